# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``s1_emulator``: an RPLIDAR S1 speaking the real byte protocol on a pseudo-terminal and TCP.

It answers like a real S1 (model 0x61, firmware 1.28, hardware 18; modes 0 Standard, 244 us,
answer 0x81 and 1 DenseBoost, 108 us, answer 0x85, typical 1; no answer to RESET, then about
1.5 s of silence; requests other than STOP, RESET and MOTOR_SPEED are ignored while streaming)
and streams scans of a floor plan from :mod:`wctls_ros.simulation` in real time: every frame is
written when its last byte would arrive over a 256000-baud line after its samples were measured.

A sample at raw (clockwise) angle theta is the range along the laser-frame bearing pi - theta,
so a driver publishing sllidar_ros2's angle = pi - theta sees the plan in REP-103 orientation.
Dense capsule distances are whole millimetres and standard node distances quarter millimetres.

Faults for testing recovery: ``--corrupt-rate`` / ``--drop-rate`` (per streamed byte),
``--silent-after``/``--silent-for``, ``--health warning|error``. Lines on standard input
control it live: ``unplug``, ``replug``, ``silent SECONDS``, ``health ok|warning|error [RESETS]``,
``corrupt RATE``, ``drop RATE``, ``quit``; each is acknowledged on standard output.
"""

import argparse
from dataclasses import dataclass
import math
import os
import pty
import queue
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import tty
from typing import Optional

import numpy as np

from .protocol import (AnswerType, CAPSULE_SIZE, Command, CONF_COMMANDS_FIRMWARE, ConfType,
                       decode_conf_request, DeviceHealth, DeviceInfo, encode_answer,
                       encode_conf_value, encode_dense_capsules, encode_standard_nodes,
                       FULL_TURN_Q6, HealthStatus, MODE_CONF_TYPES, NODE_SIZE, ProtocolError,
                       RequestParser, ResponseDescriptor, SampleRate, SAMPLES_PER_CAPSULE,
                       ScanMode, SendMode)
from ..simulation import FloorPlan, load_floor_plan, NOISELESS, NoiseModel, simulate_scan

MODES = (ScanMode(0, 'Standard', 244.0, 40.0, AnswerType.MEASUREMENT),
         ScanMode(1, 'DenseBoost', 108.0, 40.0, AnswerType.DENSE_CAPSULE))
TYPICAL_MODE = 1
MODEL_S1M1 = 0x61
HARDWARE = 18
SERIAL_NUMBER = b'WCTLS-S1-EMULATR'
DEFAULT_RPM = 600
SERIAL_BAUD = 256000
RESET_SILENCE_S = 1.5
HEALTH_ERROR_CODE = 0x0001
MAX_NODE_DISTANCE_Q2 = 0xFFFF
_CATCH_UP_LIMIT_S = 0.5
_POLL_S = 0.001


@dataclass
class Faults:
    """
    Fault injection settings (mutable: stdin commands change them).

    :ivar corrupt_rate: probability that a streamed byte is replaced by another value
    :ivar drop_rate: probability that a streamed byte is left out
    :ivar silent_from_s: monotonic time from which the device neither answers nor streams
    :ivar silent_until_s: monotonic time at which it speaks again
    :ivar health: :class:`HealthStatus` reported by GET_HEALTH
    :ivar resets_to_clear: RESETs still needed before an error health clears
    """

    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    silent_from_s: float = 0.0
    silent_until_s: float = 0.0
    health: int = HealthStatus.OK
    resets_to_clear: int = 1

    def silent(self, now_s: float) -> bool:
        """
        Tell whether the device is silent.

        :param now_s: monotonic time, s
        :return: True while neither answering nor streaming
        """
        return self.silent_from_s <= now_s < self.silent_until_s


class Scene:
    """
    Ranges of a floor plan seen from a pose, with the simulator's sensor model.

    Walkers in the plan move in real time from the moment the scene is made.

    :param plan: the floor plan
    :param pose: sensor pose in the plan (x m, y m, yaw rad); None: the plan's own
    :param noise: the sensor model
    :param rng: random generator
    """

    def __init__(self, plan: FloorPlan, pose, noise: NoiseModel, rng: np.random.Generator):
        self._plan = plan
        self._pose = pose
        self._noise = noise
        self._rng = rng
        self._start_s = time.monotonic()
        # Without walkers the scene never changes: build it once.
        self._still = None if plan.walkers else plan.scene(pose)

    def distances_mm(self, raw_angle_deg: np.ndarray) -> np.ndarray:
        """
        Return the measured distance at each raw clockwise angle.

        :param raw_angle_deg: device angles, degrees clockwise from the front
        :return: distances, mm (float); 0 where nothing returns
        """
        bearings = math.pi - np.radians(raw_angle_deg)
        scene = (self._plan.scene(self._pose, time.monotonic() - self._start_s)
                 if self._still is None else self._still)
        ranges = simulate_scan(scene, bearings, self._noise, self._rng)
        return np.where(np.isfinite(ranges), ranges * 1000.0, 0.0)


class S1Device:
    """
    One emulated S1 behind one link: answers requests and produces the scan stream.

    :param scene: what the device sees
    :param faults: shared fault settings
    :param firmware: (major, minor)
    :param rng: random generator (rotation phase, faults)
    """

    def __init__(self, scene: Scene, faults: Faults, firmware: tuple, rng: np.random.Generator):
        self._scene = scene
        self._faults = faults
        self._firmware = firmware
        self._rng = rng
        self._parser = RequestParser()
        self._rpm = DEFAULT_RPM
        self._mode: Optional[ScanMode] = None
        self._booting_until_s = 0.0
        self._phase_q6 = int(rng.integers(FULL_TURN_Q6))

    def receive(self, data: bytes, now_s: float) -> bytes:
        """
        Take received bytes; return the answers to the requests they complete.

        :param data: bytes from the host
        :param now_s: monotonic time, s
        :return: answer bytes (may be empty)
        """
        answers = b''
        for request in self._parser.feed(data):
            if now_s < self._booting_until_s or self._faults.silent(now_s):
                continue
            answers += self._answer(request.command, request.payload, now_s)
        return answers

    def _answer(self, command: int, payload: bytes, now_s: float) -> bytes:
        """Return the answer to one request (and change state)."""
        if command == Command.STOP:
            self._stop()
        elif command == Command.RESET:
            self._stop()
            self._booting_until_s = now_s + RESET_SILENCE_S
            self._faults.resets_to_clear -= 1
            if self._faults.resets_to_clear <= 0 and self._faults.health == HealthStatus.ERROR:
                self._faults.health = HealthStatus.OK
        elif command == Command.MOTOR_SPEED and len(payload) == 2:
            self._rpm = int.from_bytes(payload, 'little')
            if self._rpm == 0:
                self._stop()
        elif self._mode is not None:
            return b''      # busy streaming: only STOP, RESET and MOTOR_SPEED are heard
        elif command in (Command.SCAN, Command.FORCE_SCAN):
            return self._start(MODES[0], now_s)
        elif command == Command.EXPRESS_SCAN and payload and payload[0] < len(MODES):
            return self._start(MODES[payload[0]], now_s)
        elif command == Command.GET_INFO:
            return encode_answer(AnswerType.DEVICE_INFO, DeviceInfo(
                MODEL_S1M1, self._firmware[1], self._firmware[0], HARDWARE,
                SERIAL_NUMBER).encode())
        elif command == Command.GET_HEALTH:
            code = 0 if self._faults.health == HealthStatus.OK else HEALTH_ERROR_CODE
            return encode_answer(AnswerType.DEVICE_HEALTH,
                                 DeviceHealth(self._faults.health, code).encode())
        elif command == Command.GET_SAMPLERATE:
            return encode_answer(AnswerType.SAMPLE_RATE, SampleRate(
                int(MODES[0].us_per_sample), int(MODES[1].us_per_sample)).encode())
        elif command == Command.GET_LIDAR_CONF and self._firmware >= CONF_COMMANDS_FIRMWARE:
            return self._conf_answer(payload)
        return b''

    def _conf_answer(self, payload: bytes) -> bytes:
        """Answer GET_LIDAR_CONF (unknown entries: the type echo alone)."""
        try:
            conf_type, mode_id = decode_conf_request(payload)
        except ProtocolError:
            return b''
        if conf_type in MODE_CONF_TYPES:
            if mode_id is None or mode_id >= len(MODES):
                return encode_answer(AnswerType.LIDAR_CONF, encode_conf_value(conf_type, None))
            mode = MODES[mode_id]
            value = {ConfType.US_PER_SAMPLE: mode.us_per_sample,
                     ConfType.MAX_DISTANCE: mode.max_distance_m,
                     ConfType.ANSWER_TYPE: mode.answer_type,
                     ConfType.MODE_NAME: mode.name}[conf_type]
        else:
            value = {ConfType.MODE_COUNT: len(MODES), ConfType.TYPICAL_MODE: TYPICAL_MODE,
                     ConfType.DESIRED_ROTATION: (DEFAULT_RPM, 0)}.get(conf_type)
        return encode_answer(AnswerType.LIDAR_CONF, encode_conf_value(conf_type, value))

    def _start(self, mode: ScanMode, now_s: float) -> bytes:
        """Start streaming a mode; return its descriptor."""
        self._mode = mode
        self._start_s = now_s
        self._sent = 0
        samples_per_frame = (SAMPLES_PER_CAPSULE if mode.answer_type == AnswerType.DENSE_CAPSULE
                             else 1)
        self._frame_size = CAPSULE_SIZE if samples_per_frame > 1 else NODE_SIZE
        self._frame_s = samples_per_frame * mode.us_per_sample * 1e-6
        rpm = self._rpm or DEFAULT_RPM
        # Whole 1/64 degrees per frame keep every sample on one exact, uniform angle grid.
        self._step_q6 = round(rpm / 60.0 * FULL_TURN_Q6 * self._frame_s)
        self._previous_angle_q6 = None
        return ResponseDescriptor(self._frame_size, SendMode.MULTIPLE, mode.answer_type).encode()

    def _stop(self):
        if self._mode is not None:
            self._phase_q6 = int((self._phase_q6 + self._sent * self._step_q6) % FULL_TURN_Q6)
        self._mode = None

    def next_frame_in(self, now_s: float) -> float:
        """
        Return how long until the next frame is due.

        :param now_s: monotonic time, s
        :return: seconds (inf when not streaming)
        """
        if self._mode is None:
            return math.inf
        return max(self._due_s(self._sent) - now_s, 0.0)

    def _due_s(self, frame: int) -> float:
        """When frame ``frame``'s last byte arrives at the host."""
        return (self._start_s + (frame + 1) * self._frame_s
                + self._frame_size * 10.0 / SERIAL_BAUD)

    def stream(self, now_s: float) -> bytes:
        """
        Return the stream bytes due by ``now_s`` (with faults applied).

        :param now_s: monotonic time, s
        :return: bytes to send
        """
        if self._mode is None:
            return b''
        due = int((now_s - self._due_s(0)) // self._frame_s) + 1
        first = max(self._sent, due - int(_CATCH_UP_LIMIT_S / self._frame_s))
        if due <= first:
            return b''
        frames = np.arange(first, due)
        self._sent = due
        if self._faults.silent(now_s):
            return b''
        start_q6 = (self._phase_q6 + frames * self._step_q6) % FULL_TURN_Q6
        if self._mode.answer_type == AnswerType.DENSE_CAPSULE:
            data = self._capsules(frames, start_q6)
        else:
            data = self._nodes(start_q6)
        return self._inject_faults(data)

    def _capsules(self, frames: np.ndarray, start_q6: np.ndarray) -> bytes:
        """Encode dense capsules: sample k of capsule i at start_i + k * step / 40."""
        offsets = np.arange(SAMPLES_PER_CAPSULE) / SAMPLES_PER_CAPSULE
        angles = (start_q6[:, None] + self._step_q6 * offsets) / 64.0 % 360.0
        distances = np.rint(self._scene.distances_mm(angles.reshape(-1)))
        distances[distances > 0xFFFF] = 0
        return encode_dense_capsules(start_q6, distances.reshape(angles.shape),
                                     frames == 0)

    def _nodes(self, angle_q6: np.ndarray) -> bytes:
        """Encode standard nodes, S set on the first node of each turn."""
        previous = np.concatenate([[angle_q6[0] if self._previous_angle_q6 is None
                                    else self._previous_angle_q6], angle_q6[:-1]])
        self._previous_angle_q6 = angle_q6[-1]
        distance_q2 = np.rint(self._scene.distances_mm(angle_q6 / 64.0) * 4.0)
        distance_q2[distance_q2 > MAX_NODE_DISTANCE_Q2] = 0
        quality = np.where(distance_q2 > 0, 47, 0)
        return encode_standard_nodes(angle_q6, distance_q2, quality, angle_q6 < previous)

    def _inject_faults(self, data: bytes) -> bytes:
        """Corrupt and drop streamed bytes at the configured rates."""
        if not (self._faults.corrupt_rate or self._faults.drop_rate):
            return data
        raw = np.frombuffer(data, np.uint8).copy()
        corrupt = self._rng.random(raw.size) < self._faults.corrupt_rate
        raw[corrupt] ^= self._rng.integers(1, 256, int(corrupt.sum()), dtype=np.uint8)
        return raw[self._rng.random(raw.size) >= self._faults.drop_rate].tobytes()


class PtyPort:
    """
    The emulator's end of a pseudo-terminal, optionally reachable through a symlink.

    The emulator keeps the terminal's other end open too, so a client closing it is not an
    error, and sets it raw like a serial line. ``unplug`` closes both ends (the client's reads
    fail, as when a USB adapter is pulled); ``plug`` opens a new terminal behind the same link.

    :param link: symlink path to (re)point at the terminal, or None
    """

    def __init__(self, link: Optional[str]):
        self._link = link
        self.fd = None
        self.plug()

    def plug(self) -> str:
        """
        Open a new pseudo-terminal (and point the link at it).

        :return: the terminal's device path
        """
        self.fd, self._client_fd = pty.openpty()
        tty.setraw(self._client_fd)
        os.set_blocking(self.fd, False)
        self.path = os.ttyname(self._client_fd)
        if self._link:
            temporary = f'{self._link}.{os.getpid()}'
            os.symlink(self.path, temporary)
            os.replace(temporary, self._link)
        return self.path

    def unplug(self):
        """Close the terminal and remove the link."""
        if self.fd is None:
            return
        if self._link and os.path.islink(self._link):
            os.unlink(self._link)
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
    Serves S1 devices on a pseudo-terminal and, optionally, on TCP loopback.

    :param scene: what the devices see
    :param faults: shared fault settings
    :param firmware: (major, minor)
    :param seed: random seed
    :param link: symlink path for the pseudo-terminal
    :param tcp_address: (host, port) to listen on, or None
    """

    def __init__(self, scene: Scene, faults: Faults, firmware: tuple, seed: int,
                 link: Optional[str], tcp_address: Optional[tuple]):
        self._scene = scene
        self._faults = faults
        self._firmware = firmware
        self._rng = np.random.default_rng(seed)
        self.pty = PtyPort(link)
        self._pty_device = self._new_device()
        self._listener = None
        self._clients = {}
        if tcp_address is not None:
            self._listener = socket.create_server(tcp_address)
            self.tcp_address = self._listener.getsockname()[:2]
        self.commands = queue.Queue()

    def _new_device(self) -> S1Device:
        return S1Device(self._scene, self._faults, self._firmware, self._rng)

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
                self.pty.write(self._pty_device.stream(now))
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
            verb, args = words[0], words[1:]
            try:
                reply = self._command(verb, args)
            except (ValueError, IndexError, KeyError) as error:
                reply = f'error: {verb} {" ".join(args)}: {error}'
            if reply is None:
                return False
            print(reply, flush=True)

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
                self._pty_device = self._new_device()
            return f'replugged {self.pty.path}'
        if verb == 'silent':
            self._faults.silent_from_s = time.monotonic()
            self._faults.silent_until_s = self._faults.silent_from_s + float(args[0])
            return f'silent for {float(args[0]):g} s'
        if verb == 'health':
            self._faults.health = HealthStatus[args[0].upper()]
            self._faults.resets_to_clear = int(args[1]) if len(args) > 1 else 1
            return f'health {args[0]}'
        if verb in ('corrupt', 'drop'):
            setattr(self._faults, f'{verb}_rate', float(args[0]))
            return f'{verb} rate {float(args[0]):g}'
        raise ValueError('unknown command (unplug, replug, silent S, health STATUS [RESETS], '
                         'corrupt RATE, drop RATE, quit)')

    def close(self):
        """Close everything (and remove the link)."""
        self.pty.unplug()
        for client in list(self._clients):
            self._drop_client(client)
        if self._listener is not None:
            self._listener.close()


class EmulatorProcess:
    """
    ``s1_emulator`` in a child process, controlled through its standard input (tests, benchmarks).

    :param args: command line arguments, e.g. ``['--noiseless', '--tcp-port', '0']``
    :param startup_timeout_s: longest wait for the emulator to be ready, s
    :ivar pty: the pseudo-terminal's device path
    :ivar link: the symlink to it (None without ``--link``)
    :ivar tcp_port: the TCP port served (None without ``--tcp-port``)
    :raises RuntimeError: when it does not become ready
    """

    def __init__(self, args: list = (), startup_timeout_s: float = 20.0):
        self._process = subprocess.Popen(
            [sys.executable, '-m', 'wctls_ros.rplidar.emulator', *args], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, text=True, bufsize=1)
        self._lines = queue.Queue()
        threading.Thread(target=self._forward_lines, daemon=True).start()
        self.link = self.tcp_port = None
        while True:
            line = self._next_line(startup_timeout_s)
            key, _, value = line.partition(' ')
            if key == 'pty':
                self.pty = value
            elif key == 'link':
                self.link = value
            elif key == 'tcp':
                self.tcp_port = int(value.rsplit(':', 1)[1])
            elif key == 'ready:':
                break

    def _forward_lines(self):
        for line in self._process.stdout:
            self._lines.put(line.strip())
        self._lines.put(None)

    def _next_line(self, timeout_s: float) -> str:
        try:
            line = self._lines.get(timeout=timeout_s)
        except queue.Empty:
            line = None
        if line is None:
            self.close()
            raise RuntimeError('s1_emulator did not answer (see its standard error)')
        return line

    def command(self, line: str, timeout_s: float = 5.0) -> str:
        """
        Send a control command and return its acknowledgement.

        :param line: e.g. ``'unplug'``, ``'health error 2'``
        :param timeout_s: longest wait for the acknowledgement, s
        :return: the acknowledgement line
        :raises RuntimeError: when the emulator does not answer
        """
        self._process.stdin.write(line + '\n')
        self._process.stdin.flush()
        return self._next_line(timeout_s)

    def close(self):
        """Stop the emulator (quit, then kill if needed)."""
        if self._process.poll() is None:
            try:
                self._process.stdin.write('quit\n')
                self._process.stdin.flush()
                self._process.wait(5.0)
            except (OSError, subprocess.TimeoutExpired):
                self._process.kill()
                self._process.wait()
        self._process.stdin.close()
        self._process.stdout.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()


def _read_stdin_commands(commands: queue.Queue):
    """Forward standard input lines to the command queue (until EOF)."""
    for line in sys.stdin:
        commands.put(line)


def _parse_args(argv):
    parser = argparse.ArgumentParser(
        prog='s1_emulator',
        description='An RPLIDAR S1 speaking the real byte protocol on a pseudo-terminal (and '
                    'TCP), streaming a simulated floor plan in real time.',
        epilog='Lines on standard input control it while it runs: unplug, replug, silent SECONDS, '
               'health ok|warning|error [RESETS], corrupt RATE, drop RATE, quit.')
    parser.add_argument('--link', help='symlink to point at the pseudo-terminal, e.g. /tmp/ttyS1')
    parser.add_argument('--tcp-port', type=int,
                        help='also serve on this TCP port (0 = any free port; S1 TCP: 20108)')
    parser.add_argument('--tcp-host', default='127.0.0.1',
                        help='address to listen on (default: %(default)s)')
    parser.add_argument('--floor-plan', default='environment_a',
                        help='bundled plan name (environment_a, environment_b, their '
                             '_cluttered variants) or a YAML path (default: %(default)s)')
    parser.add_argument('--pose', type=float, nargs=3, metavar=('X', 'Y', 'YAW_DEG'),
                        help="sensor pose in the plan, m and degrees (default: the plan's own)")
    parser.add_argument('--range-sigma', type=float, default=NoiseModel.range_sigma_m,
                        help='range noise std, m (default: %(default)s)')
    parser.add_argument('--bearing-sigma-deg', type=float,
                        default=math.degrees(NoiseModel.bearing_sigma_rad),
                        help='bearing noise std, degrees (default: %(default).3f)')
    parser.add_argument('--noiseless', action='store_true', help='exact ranges (no noise)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default: 0)')
    parser.add_argument('--firmware', default='1.28',
                        help='firmware version MAJOR.MINOR (default: %(default)s; before 1.24 '
                             'there is no GET_LIDAR_CONF)')
    parser.add_argument('--corrupt-rate', type=float, default=0.0,
                        help='probability that a streamed byte is corrupted')
    parser.add_argument('--drop-rate', type=float, default=0.0,
                        help='probability that a streamed byte is dropped')
    parser.add_argument('--silent-after', type=float, help='go silent after this many seconds')
    parser.add_argument('--silent-for', type=float, default=3.0,
                        help='silence duration, s (default: %(default)s)')
    parser.add_argument('--health', choices=['ok', 'warning', 'error'], default='ok',
                        help='health status to report (default: %(default)s)')
    parser.add_argument('--health-error-resets', type=int, default=1,
                        help='RESETs that clear a health error (default: %(default)s)')
    return parser.parse_args(argv)


def main(argv=None):
    """Run the emulator until interrupted (or ``quit`` on standard input)."""
    args = _parse_args(argv)
    major, minor = (int(part) for part in args.firmware.split('.'))
    plan = load_floor_plan(args.floor_plan)
    pose = None if args.pose is None else (args.pose[0], args.pose[1], math.radians(args.pose[2]))
    noise = NOISELESS if args.noiseless else NoiseModel(
        range_sigma_m=args.range_sigma, bearing_sigma_rad=math.radians(args.bearing_sigma_deg))
    faults = Faults(corrupt_rate=args.corrupt_rate, drop_rate=args.drop_rate,
                    health=HealthStatus[args.health.upper()],
                    resets_to_clear=args.health_error_resets)
    if args.silent_after is not None:
        faults.silent_from_s = time.monotonic() + args.silent_after
        faults.silent_until_s = faults.silent_from_s + args.silent_for
    scene = Scene(plan, pose, noise, np.random.default_rng(args.seed))
    tcp = None if args.tcp_port is None else (args.tcp_host, args.tcp_port)
    emulator = Emulator(scene, faults, (major, minor), args.seed, args.link, tcp)
    signal.signal(signal.SIGTERM, lambda *_: emulator.commands.put('quit'))
    print(f'pty {emulator.pty.path}', flush=True)
    if args.link:
        print(f'link {args.link}', flush=True)
    if tcp is not None:
        print(f'tcp {emulator.tcp_address[0]}:{emulator.tcp_address[1]}', flush=True)
    print(f'ready: RPLIDAR S1 emulator, floor plan {plan.name}', flush=True)
    threading.Thread(target=_read_stdin_commands, args=(emulator.commands,), daemon=True).start()
    try:
        emulator.run()
    except KeyboardInterrupt:
        pass
    finally:
        emulator.close()


if __name__ == '__main__':
    main()
