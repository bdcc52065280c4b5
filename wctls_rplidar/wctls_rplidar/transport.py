# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Byte links to an RPLIDAR: a serial port (pyserial) or a TCP socket.

The serial port is opened with ``dsrdtr=False, rtscts=False``; pyserial sets DTR on opening,
which keeps the motor of an A1 (or of an A2/A3 without its accessory board) still until the
driver clears it (:meth:`SerialLink.set_dtr`). A pseudo-terminal has no modem lines: there
setting DTR reports False. Every failure is raised as :class:`LinkError` with a message that says
what to check.
"""

import errno
import socket
import time

import serial

# Bits per byte on an 8N1 serial line (start bit, 8 data bits, stop bit).
_BITS_PER_BYTE = 10


class LinkError(OSError):
    """The link could not be opened, or broke (unplugged device, closed socket)."""


def _explain_serial_error(port: str, error: serial.SerialException) -> str:
    """Turn a pyserial failure into a message that says what to check."""
    code = getattr(error, 'errno', None)
    if code == errno.ENOENT:
        hint = ('no such device: is the RPLIDAR plugged in and powered? Check serial_port '
                '(ls -l /dev/ttyUSB* /dev/rplidar)')
    elif code == errno.EACCES:
        hint = ('permission denied: add the user to the dialout group (sudo usermod -aG dialout '
                '$USER, then log in again) or install the udev rule from the README')
    elif 'exclusively lock' in str(error) or code == errno.EBUSY:
        hint = 'the port is in use by another process (another driver or a serial terminal?)'
    else:
        hint = 'the device was unplugged or the port is not a serial device'
    return f'serial port {port}: {error} -- {hint}'


class SerialLink:
    """
    A serial port at the RPLIDARs' 8N1 line settings.

    :param port: device path, e.g. ``/dev/ttyUSB0``
    :param baudrate: bits per second (the model's: 115200 to 1000000)
    :raises LinkError: when the port cannot be opened
    """

    def __init__(self, port: str, baudrate: int):
        self.name = f'serial {port} @ {baudrate} baud'
        self.byte_time_s = _BITS_PER_BYTE / baudrate
        try:
            self._serial = serial.Serial(port=port, baudrate=baudrate, timeout=0.0,
                                         dsrdtr=False, rtscts=False, exclusive=True)
        except (serial.SerialException, ValueError) as error:
            raise LinkError(_explain_serial_error(port, error)) from error
        self._port = port

    def write(self, data: bytes):
        """
        Send bytes.

        :param data: bytes to send
        :raises LinkError: when the device is gone
        """
        try:
            self._serial.write(data)
        except serial.SerialException as error:
            raise LinkError(_explain_serial_error(self._port, error)) from error

    def set_dtr(self, asserted: bool) -> bool:
        """
        Set or clear the DTR line (an A1's motor runs while it is cleared).

        :param asserted: True to set DTR, False to clear it
        :return: False when the port has no modem lines (a pseudo-terminal), else True
        :raises LinkError: when the device is gone
        """
        try:
            self._serial.dtr = asserted
        except (serial.SerialException, OSError) as error:
            if getattr(error, 'errno', None) in (errno.EINVAL, errno.ENOTTY):
                return False
            raise LinkError(_explain_serial_error(self._port, error)) from error
        return True

    def read(self, timeout_s: float) -> bytes:
        """
        Wait for bytes and return all that have arrived.

        :param timeout_s: longest wait, s
        :return: the bytes (empty after a timeout)
        :raises LinkError: when the device is gone
        """
        try:
            if self._serial.timeout != timeout_s:
                # pyserial reconfigures the port on every timeout change: only when needed.
                self._serial.timeout = timeout_s
            data = self._serial.read(1)
            waiting = self._serial.in_waiting
            return data + self._serial.read(waiting) if data and waiting else data
        except (serial.SerialException, OSError) as error:
            raise LinkError(_explain_serial_error(self._port, error)) from error

    def close(self):
        """Close the port (a port whose device is gone closes without an error)."""
        try:
            self._serial.close()
        except (serial.SerialException, OSError):
            pass


class TcpLink:
    """
    A TCP connection to a networked RPLIDAR (or to the emulator).

    :param host: address
    :param port: TCP port (20108 for SLAMTEC's TCP variant)
    :param connect_timeout_s: how long to try to connect, s
    :raises LinkError: when the connection fails
    """

    def __init__(self, host: str, port: int, connect_timeout_s: float = 2.0):
        self.name = f'tcp {host}:{port}'
        self.byte_time_s = 0.0
        try:
            self._socket = socket.create_connection((host, port), timeout=connect_timeout_s)
        except OSError as error:
            raise LinkError(f'{self.name}: {error} -- check tcp_ip / tcp_port and that the '
                            'device is powered and reachable') from error
        self._socket.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def write(self, data: bytes):
        """
        Send bytes.

        :param data: bytes to send
        :raises LinkError: when the connection is gone
        """
        try:
            self._socket.sendall(data)
        except OSError as error:
            raise LinkError(f'{self.name}: {error}') from error

    def read(self, timeout_s: float) -> bytes:
        """
        Wait for bytes and return what arrived.

        :param timeout_s: longest wait, s
        :return: the bytes (empty after a timeout)
        :raises LinkError: when the peer closed the connection or it broke
        """
        try:
            self._socket.settimeout(timeout_s)
            data = self._socket.recv(65536)
        except socket.timeout:
            return b''
        except OSError as error:
            raise LinkError(f'{self.name}: {error}') from error
        if not data:
            raise LinkError(f'{self.name}: the peer closed the connection')
        return data

    def set_dtr(self, asserted: bool) -> bool:
        """
        Report that a TCP link has no DTR line.

        :param asserted: ignored
        :return: False
        """
        return False

    def close(self):
        """Close the connection."""
        self._socket.close()


def drain(link, quiet_s: float, limit_s: float) -> int:
    """
    Read and discard until the link has been quiet for ``quiet_s`` (at most ``limit_s``).

    :param link: a :class:`SerialLink` or :class:`TcpLink`
    :param quiet_s: silence that ends the drain, s
    :param limit_s: longest drain, s
    :return: number of bytes discarded
    """
    deadline = time.monotonic() + limit_s
    discarded = 0
    while time.monotonic() < deadline:
        data = link.read(quiet_s)
        if not data:
            break
        discarded += len(data)
    return discarded
