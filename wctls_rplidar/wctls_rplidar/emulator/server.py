# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Emulated S1 devices served on a pseudo-terminal and TCP, with live control commands.

One device answers on the pseudo-terminal (reachable through a symlink, like a udev name) and
one more per TCP client. Control lines (``unplug``, ``replug``, ``hangup`` (the terminal is
closed and a new one opened behind the link at once while the device, powered on its own, goes
on with what it was doing: a USB adapter that drops off the bus and comes back),
``requests`` (the requests the pty device heard since the last ``requests``, in order, each
command's name with its payload: ``MOTOR_SPEED=0``; how tests see a client stop the motor;
``requests timed``: each as ``NAME@SECONDS``, when it was read, on the machine's monotonic
clock: how tests time a client's retries), ``silent SECONDS``,
``health ok|warning|error [RESETS]``, ``corrupt RATE``, ``drop RATE``, ``cut RATE``,
``insert RATE``, ``flip RATE``, ``replay RATE``, ``swap RATE``, ``duplicate RATE`` (the stream
faults of :class:`~wctls_rplidar.emulator.device.Faults`), ``conf ENTRY=VALUE`` (a
GET_LIDAR_CONF value reported instead of the device's own), ``clock``
(the pty device's sample clock: when and at what angle each sample of its stream is measured),
``quit``) are queued on :attr:`Emulator.commands` and each is acknowledged with one line on
standard output.

A pseudo-terminal carries the line settings its client sets, the rate too: a port given a rate
serves only a client that set it; between the two ends at different rates every byte is lost
(a device does not understand a request sent at another rate, nor its client the stream). The
rate is read with the termios2 ioctl, so only on Linux; elsewhere a port given a rate refuses
to start.
"""

import array
import fcntl
import os
import pty
import queue
import select
import socket
import time
import tty
from typing import Optional

import numpy as np

from .device import Faults, MODEL_S1M1, MODES, S1Device, Scene, STREAM_FAULTS, TYPICAL_MODE
from ..protocol import Command, HealthStatus, RequestParser

_POLL_S = 0.001
# The reads of waiting requests before a command is answered, at most (4 KB each).
_WAITING_READS_MAX = 16
# Linux's TCGETS2 (asm-generic ioctls, as pyserial uses them) and the offset of c_ospeed in the
# struct termios2 it fills: four flag words, c_line, 19 control characters, then c_ispeed.
_TCGETS2 = 0x802C542A
_TERMIOS2_WORDS = 11
_OSPEED_WORD = 10


class PtyPort:
    """
    The emulator's end of a pseudo-terminal, optionally reachable through a symlink.

    The emulator keeps the terminal's other end open too, so a client closing it is not an
    error, and sets it raw like a serial line. ``unplug`` closes both ends (the client's reads
    fail, as when a USB adapter is pulled); ``plug`` opens a new terminal behind the same link.

    :param link: symlink path to (re)point at the terminal, or None
    :param baudrate: the only rate, bits per second, its client is heard at (None: any)
    """

    def __init__(self, link: Optional[str], baudrate: Optional[int] = None):
        self._link = link
        self.baudrate = baudrate
        self.fd = None
        self.plug()
        if baudrate is not None:
            self.client_baudrate()      # fails at once where the rate cannot be read

    def client_baudrate(self) -> int:
        """
        Return the rate the client set on the terminal.

        :return: bits per second
        :raises OSError: where the termios2 ioctl is missing (not Linux)
        """
        settings = array.array('I', [0] * _TERMIOS2_WORDS)
        fcntl.ioctl(self.fd, _TCGETS2, settings)
        return settings[_OSPEED_WORD]

    def hears_client(self) -> bool:
        """
        Tell whether the client's bytes arrive at the port's rate.

        :return: True without a rate of its own or when the client set it
        """
        return self.baudrate is None or self.client_baudrate() == self.baudrate

    def plug(self) -> str:
        """
        Open a new pseudo-terminal (and point the link at it).

        :return: the terminal's device path
        :raises OSError: when the link cannot be made (the terminal is closed again)
        """
        self.fd, self._client_fd = pty.openpty()
        tty.setraw(self._client_fd)
        os.set_blocking(self.fd, False)
        self.path = os.ttyname(self._client_fd)
        if self._link:
            temporary = f'{self._link}.{os.getpid()}'
            try:
                os.symlink(self.path, temporary)
                os.replace(temporary, self._link)
            except OSError:
                if os.path.islink(temporary):
                    os.unlink(temporary)
                self._close_terminal()
                raise
        return self.path

    def unplug(self):
        """Close the terminal and remove the link."""
        if self.fd is None:
            return
        if self._link and os.path.islink(self._link):
            os.unlink(self._link)
        self._close_terminal()

    def _close_terminal(self):
        os.close(self.fd)
        os.close(self._client_fd)
        self.fd = None

    def write(self, data: bytes):
        """
        Write without blocking; like a serial line, what does not fit is lost.

        :param data: bytes to send
        """
        try:
            os.write(self.fd, data)
        except BlockingIOError:
            pass


class Emulator:
    """
    Serves S1 devices on a pseudo-terminal and, optionally, on a TCP listening socket.

    :param scene: what the devices see
    :param faults: shared fault settings
    :param firmware: (major, minor)
    :param seed: random seed
    :param pty_port: the pseudo-terminal (closed by :meth:`close`)
    :param listener: a listening TCP socket, or None (closed by :meth:`close`)
    :param modes: the devices' scan modes (see :class:`~.device.S1Device`)
    :param typical_mode: the id of their typical mode
    :param model: the model byte they report
    """

    def __init__(self, scene: Scene, faults: Faults, firmware: tuple, seed: int,
                 pty_port: PtyPort, listener: Optional[socket.socket] = None,
                 modes: tuple = MODES, typical_mode: int = TYPICAL_MODE,
                 model: int = MODEL_S1M1):
        self._model = model
        self._modes = modes
        self._typical_mode = typical_mode
        self._scene = scene
        self._faults = faults
        self._firmware = firmware
        self._rng = np.random.default_rng(seed)
        self.pty = pty_port
        self._pty_device = self._new_device()
        self._listener = listener
        self._clients = {}
        self._request_parser = RequestParser()
        self._heard = []
        # A SimpleQueue: its put is reentrant, so the SIGTERM handler may put 'quit' while
        # this thread is inside get_nowait (a Queue's lock deadlocked both threads there).
        self.commands = queue.SimpleQueue()

    def _new_device(self) -> S1Device:
        return S1Device(self._scene, self._faults, self._firmware, self._rng, self._modes,
                        self._typical_mode, self._model)

    def run(self):
        """Serve until a ``quit`` command (or a signal)."""
        while self._handle_commands():
            now = time.monotonic()
            devices = [self._pty_device] + list(self._clients.values())
            timeout = min([_POLL_S * 50] + [d.next_frame_in(now) for d in devices])
            readable = [s for s in [self.pty.fd, self._listener, *self._clients] if s is not None]
            ready, _, _ = select.select(readable, [], [], max(timeout, _POLL_S))
            now = time.monotonic()
            for source in ready:
                self._receive(source, now)
            if self.pty.fd is not None:
                streamed = self._pty_device.stream(now)
                if self.pty.hears_client():
                    self.pty.write(streamed)
            for client, device in list(self._clients.items()):
                self._send(client, device.stream(now))

    def _receive(self, source, now_s: float):
        """Handle a readable pty, listener or client."""
        if source is self._listener:
            client, _ = self._listener.accept()
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client.settimeout(1.0)
            self._clients[client] = self._new_device()
            return
        if source == self.pty.fd:
            try:
                data = os.read(source, 4096)
            except (BlockingIOError, OSError):
                return
            if self.pty.hears_client():
                self._heard.extend((now_s, _request_name(request))
                                   for request in self._request_parser.feed(data))
                self.pty.write(self._pty_device.receive(data, now_s))
            return
        try:
            data = source.recv(4096)
        except OSError:
            data = b''
        if not data:
            self._drop_client(source)
            return
        self._send(source, self._clients[source].receive(data, now_s))

    def _send(self, client: socket.socket, data: bytes):
        if not data:
            return
        try:
            client.sendall(data)
        except OSError:
            self._drop_client(client)

    def _drop_client(self, client: socket.socket):
        self._clients.pop(client, None)
        client.close()

    def _handle_commands(self) -> bool:
        """Apply queued control commands; return False on ``quit``."""
        while True:
            try:
                words = self.commands.get_nowait().split()
            except queue.Empty:
                return True
            if not words:
                continue
            self._read_waiting_requests()
            verb, args = words[0], words[1:]
            try:
                reply = self._command(verb, args)
            except (ValueError, IndexError, KeyError) as error:
                reply = f'error: {verb} {" ".join(args)}: {error}'
            if reply is None:
                return False
            print(reply, flush=True)

    def _read_waiting_requests(self):
        """
        Read what the client wrote before a command came, so that the command answers after it.

        A command can come while the serving loop has not yet read a request the client wrote
        before sending the command (a STOP, say, then ``requests``): on a busy machine the
        answer missed it.
        """
        for _ in range(_WAITING_READS_MAX):     # a closed client's end stays readable (EIO)
            if self.pty.fd is None or not select.select([self.pty.fd], [], [], 0)[0]:
                return
            self._receive(self.pty.fd, time.monotonic())

    def _command(self, verb: str, args: list) -> Optional[str]:
        """Apply one command; return the acknowledgement (None on quit)."""
        if verb == 'quit':
            return None
        if verb == 'unplug':
            self.pty.unplug()
            return 'unplugged'
        if verb == 'replug':
            if self.pty.fd is None:
                self.pty.plug()
                self._request_parser = RequestParser()
                self._pty_device = self._new_device()
            return f'replugged {self.pty.path}'
        if verb == 'hangup':
            self.pty.unplug()
            self.pty.plug()
            self._request_parser = RequestParser()
            return f'hung up, device still running, new terminal {self.pty.path}'
        if verb == 'requests':
            heard, self._heard = self._heard, []
            # 'requests timed': each with when it was read (the machine's monotonic clock, s).
            timed = args == ['timed']
            return 'requests ' + (' '.join(f'{name}@{at_s:.6f}' if timed else name
                                           for at_s, name in heard) or 'none')
        if verb == 'silent':
            self._faults.silent_from_s = time.monotonic()
            self._faults.silent_until_s = self._faults.silent_from_s + float(args[0])
            return f'silent for {float(args[0]):g} s'
        if verb == 'health':
            self._faults.health = HealthStatus[args[0].upper()]
            self._faults.resets_to_clear = int(args[1]) if len(args) > 1 else 1
            return f'health {args[0]}'
        if verb in STREAM_FAULTS:
            setattr(self._faults, f'{verb}_rate', float(args[0]))
            return f'{verb} rate {float(args[0]):g}'
        if verb == 'conf':
            self._faults.replace_conf_answer(args[0])
            return f'conf {args[0]}'
        if verb == 'clock':
            clock = self._pty_device.clock()
            if clock is None:
                return 'clock idle'
            return (f'clock start {clock.start_s:.9f} s, {clock.sample_s * 1e6:.6f} us per '
                    f'sample, first at {clock.first_angle_deg:.9f} deg, '
                    f'{clock.step_deg:.9f} deg per sample')
        raise ValueError('unknown command (unplug, replug, hangup, requests [timed], silent S, '
                         'health STATUS [RESETS], '
                         f'{", ".join(f"{name} RATE" for name in STREAM_FAULTS)}, '
                         'conf ENTRY=VALUE, clock, quit)')

    def close(self):
        """Close everything (and remove the link)."""
        self.pty.unplug()
        for client in list(self._clients):
            self._drop_client(client)
        if self._listener is not None:
            self._listener.close()


def _request_name(request) -> str:
    """
    Name a request: its command's name (or byte), with its payload as a number (up to 4 bytes).

    :param request: a :class:`~wctls_rplidar.protocol.Request`
    :return: e.g. ``'STOP'``, ``'MOTOR_SPEED=600'``, ``'EXPRESS_SCAN=0x0100000000'``
    """
    try:
        name = Command(request.command).name
    except ValueError:
        name = f'0x{request.command:02X}'
    payload = request.payload
    if not payload:
        return name
    if len(payload) <= 4:
        return f'{name}={int.from_bytes(payload, "little")}'
    return f'{name}=0x{payload.hex()}'
