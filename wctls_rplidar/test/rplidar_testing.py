# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Helpers shared by the RPLIDAR tests: the emulator and its scene's true ranges."""

import contextlib
import math
import re
import threading
import time

from emulator_process import EmulatorProcess
import numpy as np
from wctls_rplidar.emulator.cli import ROOM_RANGE_SIGMA_M
from wctls_rplidar.emulator.device import EMULATED_MODELS, Faults, MODES, S1Device
from wctls_rplidar.emulator.raycast import cast_rays
from wctls_rplidar.emulator.room import RoomScene, SENSOR_POSE, walls_in_sensor_frame
from wctls_rplidar.emulator.server import Emulator, PtyPort
from wctls_rplidar.protocol import encode_express_scan
from wctls_rplidar.transport import LinkError

# The emulator's default scene: the built-in room seen from mid-room.
WALLS = walls_in_sensor_frame()
# A second view of the room: off-centre, turned.
ANOTHER_POSE = (1.0, 0.8, 0.5)
# The emulator turns 995/64 degrees per DenseBoost capsule of 40 samples of 108 us: 926.2
# samples, 100.03 ms, a turn.
EMULATOR_TURN_SAMPLES = 360.0 * 64 / 995 * 40
EMULATOR_TURN_S = EMULATOR_TURN_SAMPLES * 108e-6


def true_ranges(bearings_rad):
    """
    Return the noiseless ranges of the emulator's scene along laser-frame bearings.

    :param bearings_rad: bearings, rad, counter-clockwise (REP-103)
    :return: ranges, m
    """
    return cast_rays(WALLS, np.zeros(2), np.asarray(bearings_rad, dtype=float))


def _cross(a, b):
    """Return the z component of the cross product of 2-D vectors (last axis)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _critical_bearings(walls):
    """
    Return the bearings at which the range, as a function of bearing, can have a local extreme.

    Between wall ends and wall crossings the nearest wall stays the same, and the range along one
    wall falls only up to the foot of its perpendicular and rises after it. So over any bearing
    interval the range is extreme at the interval's ends, at a wall end (a corner's kink, or an
    occlusion edge, approached from either side), at a crossing or at a perpendicular's foot.

    :param walls: wall segments in the laser frame, shape (K, 4), m
    :return: bearings, rad
    """
    start, edge = walls[:, :2], walls[:, 2:] - walls[:, :2]
    foot = -np.einsum('ij,ij->i', start, edge) / np.einsum('ij,ij->i', edge, edge)
    feet = start + np.clip(foot, 0.0, 1.0)[:, None] * edge
    denominator = _cross(edge[:, None], edge[None])
    between = start[None] - start[:, None]
    with np.errstate(divide='ignore', invalid='ignore'):
        along = _cross(between, edge[None]) / denominator
        other = _cross(between, edge[:, None]) / denominator
    first, second = np.nonzero((along >= 0.0) & (along <= 1.0) & (other >= 0.0) & (other <= 1.0))
    crossings = start[first] + along[first, second, None] * edge[first]
    ends = walls.reshape(-1, 2)
    points = np.concatenate([ends, feet, crossings])
    bearings = np.arctan2(points[:, 1], points[:, 0])
    # An occlusion edge is a jump: take the range just before and just after it too.
    return np.concatenate([bearings, bearings - 1e-9, bearings + 1e-9])


_CRITICAL_BEARINGS = _critical_bearings(WALLS)
_CRITICAL_RANGES = true_ranges(_CRITICAL_BEARINGS)


def range_band(low_rad, high_rad):
    """
    Return the scene's smallest and largest range over bearing intervals, exactly.

    Sampling an interval at a few bearings is not enough: a wall corner pointing at the sensor
    is a sharp minimum of the range between two samples. The walls being straight, the extremes
    lie at the interval's ends or at one of the scene's critical bearings inside it.

    :param low_rad: interval starts, rad
    :param high_rad: interval ends (at most a turn above the starts), rad
    :return: (lowest, highest) range per interval, m
    """
    low_rad, high_rad = np.broadcast_arrays(np.asarray(low_rad, float),
                                            np.asarray(high_rad, float))
    ends = true_ranges(np.stack([low_rad, high_rad], axis=-1).ravel()).reshape(-1, 2)
    inside = (np.mod(_CRITICAL_BEARINGS - low_rad.reshape(-1, 1), 2.0 * np.pi)
              <= (high_rad - low_rad).reshape(-1, 1))
    lowest = np.where(inside, _CRITICAL_RANGES, np.inf).min(axis=1)
    highest = np.where(inside, _CRITICAL_RANGES, -np.inf).max(axis=1)
    return (np.minimum(ends.min(axis=1), lowest).reshape(low_rad.shape),
            np.maximum(ends.max(axis=1), highest).reshape(low_rad.shape))


def compensated_beam_bands(multiple=3):
    """
    Return the scene's range band of each beam of a compensated scan of ``360 * multiple`` beams.

    With k = ``multiple`` bins per degree (3 in DenseBoost: 1080 beams), beam i is bin
    b = 360 k - 1 - i, holding a sample with raw angle in [b / k, (b + 1) / k) degrees; its laser
    bearing is pi - raw, within half a bin of the beam's published angle, the bin's centre.

    :param multiple: bins per degree
    :return: (lowest, highest) range per beam, m
    """
    raw_bin = 360 * multiple - 1 - np.arange(360 * multiple)
    return range_band(math.pi - np.radians((raw_bin + 1) / multiple),
                      math.pi - np.radians(raw_bin / multiple))


def ros_minus_monotonic_s():
    """
    Return ROS (system) time minus monotonic time, from the closest pair of readings.

    :return: s
    """
    pairs = []
    for _ in range(5):
        before, now, after = time.monotonic(), time.time(), time.monotonic()
        pairs.append((after - before, now - 0.5 * (before + after)))
    return min(pairs)[1]


def first_sample_times(clock_reply, stamps, first_angles_deg):
    """
    Return when the emulator measured each scan's first sample, on the ROS clock.

    The sample is the one at the scan's first raw angle nearest in time to the scan's stamp
    (within half a turn: stamps a whole number of turns off cannot be told apart this way).

    :param clock_reply: the emulator's answer to ``clock``
    :param stamps: the scans' header stamps, s
    :param first_angles_deg: the scans' first raw angles, degrees
    :return: the true measurement times, s (the end of the sample, as the driver reckons)
    """
    start_s, sample_us, first_deg, step_deg = (
        float(x) for x in re.findall(r'[-+0-9.]+(?:e[-+]?\d+)?', clock_reply))
    sample_s = sample_us * 1e-6
    offset_s = ros_minus_monotonic_s()
    half_turn = int(180.0 / step_deg)
    times = []
    for stamp, angle in zip(stamps, first_angles_deg):
        nearest = round((stamp - offset_s - start_s) / sample_s) - 1
        candidates = nearest + np.arange(-half_turn, half_turn + 1)
        error = (first_deg + candidates * step_deg - angle + 180.0) % 360.0 - 180.0
        sample = candidates[np.argmin(np.abs(error))]
        times.append(start_s + (sample + 1) * sample_s + offset_s)
    return np.array(times)


def denseboost_stream(pose=SENSOR_POSE, seconds=3.0, noisy=False, seed=0, faults=None):
    """
    Return the bytes an emulated S1 streams in DenseBoost, without waiting for them.

    :param pose: the sensor's pose in the emulator's room (x m, y m, yaw rad)
    :param seconds: stream length, s
    :param noisy: the S1's datasheet range noise, else exact ranges
    :param seed: random seed
    :param faults: the emulator's fault injection (default: none)
    :return: the capsules' bytes (after the scan descriptor)
    """
    return emulated_stream(MODES, 1, pose, seconds, noisy, seed, faults)


def emulated_stream(modes, mode_id, pose=SENSOR_POSE, seconds=3.0, noisy=False, seed=0,
                    faults=None):
    """
    Return the bytes an emulated device with ``modes`` streams in one, without waiting for them.

    :param modes: the device's scan modes (e.g. the emulator's ``A_SERIES_MODES``)
    :param mode_id: the mode streamed
    :return: the frames' bytes (after the scan descriptor); see :func:`denseboost_stream`
    """
    rng = np.random.default_rng(seed)
    scene = RoomScene(pose, ROOM_RANGE_SIGMA_M if noisy else 0.0, rng)
    device = S1Device(scene, faults or Faults(), (1, 28), rng, modes)
    device.receive(encode_express_scan(mode_id), 0.0)
    # The device keeps at most 0.5 s of frames due: ask in steps.
    return b''.join(device.stream(t) for t in np.arange(0.1, seconds + 0.05, 0.1))


@contextlib.contextmanager
def serving(model, typical_mode=None, firmware=None, baudrate=None, faults=None):
    """
    Serve a noiseless emulated device of ``model`` on a pseudo-terminal, in a thread.

    :param model: the emulator's model name (e.g. ``'a2'``: its model byte, scan modes, motor)
        or a :class:`~wctls_rplidar.emulator.device.DeviceModel`
    :param typical_mode: the id of its typical mode (the one the driver starts; default: the
        model's)
    :param firmware: (major, minor) (default: the model's)
    :param baudrate: the only rate it hears its client at (default: any)
    :param faults: its fault settings (default: none)
    :return: a context manager yielding the terminal's path
    """
    profile = EMULATED_MODELS[model] if isinstance(model, str) else model
    scene = RoomScene()
    emulator = Emulator(scene, faults or Faults(), firmware or profile.firmware, 0,
                        PtyPort(None, baudrate), modes=profile.modes,
                        typical_mode=profile.typical_mode if typical_mode is None
                        else typical_mode, model=profile)
    thread = threading.Thread(target=emulator.run)
    thread.start()
    try:
        yield emulator.pty.path
    finally:
        emulator.commands.put('quit')
        thread.join()
        emulator.close()


def start_emulator(directory, *options):
    """
    Start a noiseless emulator whose terminal is linked at ``directory/ttyS1``.

    :param directory: a pathlib.Path for the link
    :param options: more emulator options
    :return: the running :class:`EmulatorProcess` (a context manager)
    """
    # Ready in 6 s beside two CPU hogs on a 2-core machine, once not within 20 s.
    return EmulatorProcess(['--noiseless', '--link', str(directory / 'ttyS1'), *options],
                           startup_timeout_s=60.0)


def sdk_framed_capsules(data: bytes, size: int):
    """
    Frame capsules of ``size`` bytes as SLAMTEC's SDK does, one byte at a time.

    What the SDK ports of the capsule tests share: a byte out of sync, or a capsule whose
    checksum fails, makes the SDK drop the capsule it holds (yielded as None).

    :param data: the stream
    :param size: bytes per capsule (84 for dense and express, 132 for ultra)
    :return: an iterator of capsules (bytes) and None where the SDK resets
    """
    buffer = []
    for byte in data:
        if (len(buffer) == 0 and byte >> 4 != 0xA) or (len(buffer) == 1 and byte >> 4 != 0x5):
            buffer = []
            yield None
            continue
        buffer.append(byte)
        if len(buffer) < size:
            continue
        capsule, buffer = bytes(buffer), []
        checksum = 0
        for value in capsule[2:]:
            checksum ^= value
        yield capsule if checksum == (capsule[0] & 0xF) | ((capsule[1] << 4) & 0xFF) else None


class DeviceLink:
    """
    The driver's link to an emulated device in this process, its DTR line included.

    A pseudo-terminal carries no modem lines, so the DTR motor control of an A1 is seen here:
    the driver's writes, reads and DTR changes reach the device as a serial line would carry
    them. :meth:`unplug` makes every later use fail as a pulled USB adapter does;
    :meth:`break_connection` only the open connection's, as a link that broke while the device
    stayed powered (the next :meth:`connect` reaches it again). :attr:`on_write` and
    :attr:`on_close`, when set, are called with each write's bytes and on each close (on the
    driver's thread), to act at an exact point of a session; :attr:`read_error`, when set, is
    raised once by the next read (a bug in the session).

    :param device: the emulated device
    :param baudrate: the line's rate, bits per second (for the driver's byte time)
    """

    def __init__(self, device: S1Device, baudrate: int):
        self.device = device
        self.name = f'in-process device @ {baudrate} baud'
        self.byte_time_s = 10.0 / baudrate
        self.opened = 0
        self.on_write = None
        self.on_close = None
        self.read_error = None
        self._answers = b''
        self._gone = False
        self._broken = False

    def connect(self, config):
        """
        Serve as the driver's link factory: the same device every session.

        :param config: the driver's configuration (unused)
        :return: this link
        """
        self.opened += 1
        self._broken = False
        return self

    def unplug(self):
        """Pull the device: every later write, read or DTR change fails."""
        self._gone = True

    def break_connection(self):
        """Break the open connection; the device stays powered and a new connection reaches it."""
        self._broken = True

    def _check(self):
        if self._gone:
            raise LinkError(f'{self.name}: device unplugged')
        if self._broken:
            raise LinkError(f'{self.name}: the connection broke')

    def write(self, data: bytes):
        """Deliver bytes to the device; keep its answers for :meth:`read`."""
        self._check()
        if self.on_write is not None:
            self.on_write(data)
        self._answers += self.device.receive(data, time.monotonic())

    def set_dtr(self, asserted: bool) -> bool:
        """Set or clear the device's DTR input; return True (the line exists)."""
        self._check()
        self.device.set_dtr(asserted, time.monotonic())
        return True

    def read(self, timeout_s: float) -> bytes:
        """Return the answers and stream bytes due, waiting up to ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        if self.read_error is not None:
            error, self.read_error = self.read_error, None
            raise error
        while True:
            self._check()
            now = time.monotonic()
            data, self._answers = self._answers + self.device.stream(now), b''
            if data or now >= deadline:
                return data
            time.sleep(min(max(self.device.next_frame_in(now), 0.001), deadline - now, 0.02))

    def close(self):
        """Call :attr:`on_close`, if set; nothing to release."""
        if self.on_close is not None:
            self.on_close()


class LogLines:
    """An rclpy-style logger keeping its lines (``info``, ``warning``, ``error``)."""

    def __init__(self):
        self.lines = []

    def _keep(self, level: str, message: str, **_):
        self.lines.append(f'{level}: {message}')

    def info(self, message: str, **kwargs):
        """Keep an info line."""
        self._keep('info', message)

    def warning(self, message: str, **kwargs):
        """Keep a warning line."""
        self._keep('warning', message)

    def error(self, message: str, **kwargs):
        """Keep an error line."""
        self._keep('error', message)


def emulated_device(model, firmware=None, seed=0, faults=None):
    """
    Return a noiseless emulated device of ``model`` and a :class:`DeviceLink` to it.

    :param model: the emulator's model name or a ``DeviceModel``
    :param firmware: (major, minor) (default: the model's)
    :param seed: random seed
    :param faults: its fault settings (default: none)
    :return: ``(device, link)``
    """
    profile = EMULATED_MODELS[model] if isinstance(model, str) else model
    rng = np.random.default_rng(seed)
    scene = RoomScene(rng=rng)
    device = S1Device(scene, faults or Faults(), firmware or profile.firmware, rng, profile.modes,
                      profile.typical_mode, profile)
    return device, DeviceLink(device, profile.baudrate)


def wait_for(predicate, timeout_s=20.0, what='the condition'):
    """
    Wait until ``predicate()`` is true.

    :param predicate: the condition
    :param timeout_s: deadline, s
    :param what: what is waited for, for the failure message
    :return: the predicate's last value
    """
    deadline = time.monotonic() + timeout_s
    while not (value := predicate()):
        assert time.monotonic() < deadline, f'no {what} within {timeout_s} s'
        time.sleep(0.01)
    return value
