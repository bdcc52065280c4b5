# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``rplidar_emulator``: an RPLIDAR on a pseudo-terminal (and TCP), seeing the built-in room.

The device, its server and its faults are :mod:`.device` and :mod:`.server`; this executable
builds the scene (:mod:`.room`, or another one: :func:`main` takes the scene's options and
builder, as the lab's ``simulated_rplidar`` does with its floor plans) and injects it.

``--model a1|a2|a3|c1|s1|s2|s3`` is that model: its model byte, firmware, scan modes, serial
rate and motor control (the A1 on the DTR line, the A2 and A3 by PWM through their accessory
board, by DTR with ``--no-accessory-board``, the S-series in rpm, the C1 on its own).
It answers on the pseudo-terminal only when its client set the model's rate (the S1's 256000 by
default), as a real device hears only its own; ``--baudrate RATE`` sets another, 0 any rate.
Faults for testing recovery: ``--corrupt-rate`` / ``--drop-rate`` / ``--insert-rate`` (per
streamed byte), ``--cut-rate`` (per streamed frame: a run of bytes lost from a random one to the
frame's end), ``--flip-rate`` (per frame: one bit flipped in two of its bytes, unseen by an XOR
checksum), ``--replay-rate`` (per frame: an earlier frame sent again after it),
``--swap-rate`` / ``--duplicate-rate`` (per 64-byte USB packet: swapped with the next, sent twice),
``--silent-after``/``--silent-for``, ``--health warning|error``, ``--conf-answer ENTRY=VALUE``
(a scan mode entry reported wrongly). Lines on standard input control it live: ``unplug``,
``replug``, ``silent SECONDS``, ``health ok|warning|error [RESETS]``, ``corrupt RATE``,
``drop RATE``, ``cut RATE``, ``insert RATE``, ``flip RATE``, ``replay RATE``, ``swap RATE``,
``duplicate RATE``, ``conf ENTRY=VALUE``, ``clock`` (the true timing of the samples
streamed), ``quit``; each is acknowledged on standard output.

Exit status: 0 after ``quit`` or SIGTERM, 2 on a user error (one line on standard error,
``rplidar_emulator: error: ...``), 130 on Ctrl-C.
"""

import argparse
import math
import os
import queue
import signal
import socket
import sys
import threading
import time
from typing import Callable, Tuple

import numpy as np

from .device import CONF_ENTRIES, EMULATED_MODELS, Faults, parse_conf_answer
from .room import RoomScene, SENSOR_POSE
from .server import Emulator, PtyPort
from ..protocol import HealthStatus, model_name

PROG = 'rplidar_emulator'
USER_ERROR = 2
EXIT_INTERRUPTED = 130
# The S1's range noise (its datasheet's 2 cm at 1 sigma) unless told otherwise, m.
ROOM_RANGE_SIGMA_M = 0.02


class UserError(ValueError):
    """Something the user gave that cannot be used; the message says what to change."""


class Parser(argparse.ArgumentParser):
    """An argparse parser whose usage errors are one line and status 2."""

    def error(self, message):
        """
        Report a command-line error in one line and exit with status 2.

        :param message: what is wrong
        """
        self.exit(USER_ERROR, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def bounded(kind, low, high=math.inf):
    """
    Return an argparse type: ``kind`` values within [low, high].

    :param kind: int or float
    :param low: the smallest value allowed
    :param high: the largest value allowed
    :return: the parsing function (raises argparse.ArgumentTypeError with the reason)
    """
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            what = 'an integer' if kind is int else 'a number'
            raise argparse.ArgumentTypeError(f'not {what}: {text!r}') from None
        if not low <= value <= high:
            span = f'at least {low}' if high == math.inf else f'from {low} to {high}'
            raise argparse.ArgumentTypeError(f'must be {span}, got {text}')
        return value
    return parse


def _firmware(text: str) -> tuple:
    """Parse ``MAJOR.MINOR`` into (major, minor)."""
    major, dot, minor = text.partition('.')
    if not (dot and major.isdigit() and minor.isdigit() and int(major) < 256
            and int(minor) < 256):
        raise argparse.ArgumentTypeError(f'expected MAJOR.MINOR (0-255 each), got {text!r}')
    return int(major), int(minor)


def _conf_answer(text: str) -> str:
    """Check a ``--conf-answer`` value."""
    try:
        parse_conf_answer(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return text


def room_options(p: argparse.ArgumentParser) -> None:
    """
    Add the built-in room's options to a parser.

    :param p: the parser
    """
    p.add_argument('--pose', type=float, nargs=3, metavar=('X', 'Y', 'YAW_DEG'),
                   help='sensor pose in the room (4.5 x 2.5 m, x along the long walls), m and '
                        f'degrees (default: {SENSOR_POSE[0]:g} {SENSOR_POSE[1]:g} 0, mid-room)')
    p.add_argument('--range-sigma', type=bounded(float, 0.0), default=ROOM_RANGE_SIGMA_M,
                   help='range noise std, m (default: %(default)s)')


def room_scene(args) -> Tuple[RoomScene, str]:
    """
    Build the built-in room's scene from the parsed options.

    :param args: the parsed options
    :return: the scene and its name
    """
    pose = SENSOR_POSE if args.pose is None else (args.pose[0], args.pose[1],
                                                  math.radians(args.pose[2]))
    sigma = 0.0 if args.noiseless else args.range_sigma
    return RoomScene(pose, sigma, np.random.default_rng(args.seed)), 'built-in room'


def parser(prog: str = PROG, scene_options: Callable = room_options) -> argparse.ArgumentParser:
    """
    Return the command-line parser.

    :param prog: the program's name
    :param scene_options: adds the scene's options to it (default: the built-in room's)
    :return: the parser
    """
    p = Parser(
        prog=prog,
        description='An RPLIDAR (an S1 by default) speaking the real byte protocol on a '
                    'pseudo-terminal (and TCP), streaming what it sees in real time.',
        epilog='Lines on standard input control it while it runs: unplug, replug, silent SECONDS, '
               'health ok|warning|error [RESETS], corrupt RATE, drop RATE, cut RATE, insert '
               'RATE, flip RATE, replay RATE, swap RATE, duplicate RATE, conf '
               'ENTRY=VALUE, clock, quit. Exit status: 0 after quit or SIGTERM, 2 on a user '
               'error, 130 on Ctrl-C.')
    probability = bounded(float, 0.0, 1.0)
    p.add_argument('--link', help='symlink to point at the pseudo-terminal, e.g. ttyS1 '
                                  '(default: none, only the pty path is printed)')
    p.add_argument('--model', choices=tuple(EMULATED_MODELS), default='s1',
                   help='the model it is: its model byte, firmware, scan modes, serial rate '
                        'and motor control (default: %(default)s)')
    p.add_argument('--no-accessory-board', action='store_true',
                   help='an A2 or A3 without its accessory board: the motor on the DTR line, '
                        'not PWM (default: with the board)')
    p.add_argument('--baudrate', type=bounded(int, 0),
                   help='answer on the pseudo-terminal only when its client set this rate, '
                        'bits per second, as a real device hears only its own (Linux); 0: any '
                        "rate (default: the model's: A1, A2 115200, A3, S1 256000, C1 460800, "
                        'S2, S3 1000000)')
    p.add_argument('--tcp-port', type=bounded(int, 0, 65535),
                   help='also serve on this TCP port (0 = any free port; S1 TCP: 20108) '
                        '(default: no TCP)')
    p.add_argument('--tcp-host', default='127.0.0.1',
                   help='address to listen on (default: %(default)s)')
    p.add_argument('--noiseless', action='store_true',
                   help='exact ranges, no noise (default: off)')
    p.add_argument('--seed', type=int, default=0, help='random seed (default: %(default)s)')
    p.add_argument('--firmware', type=_firmware,
                   help="firmware version MAJOR.MINOR; an A-series' before 1.24 has no "
                        "GET_LIDAR_CONF, only GET_SAMPLERATE (default: the model's: A1 1.29, "
                        'A2 1.27, A3 1.29, S1 1.28, C1, S2 and S3 1.02)')
    p.add_argument('--corrupt-rate', type=probability, default=0.0,
                   help='probability that a streamed byte is corrupted (default: '
                        '%(default)s)')
    p.add_argument('--drop-rate', type=probability, default=0.0,
                   help='probability that a streamed byte is dropped (default: %(default)s)')
    p.add_argument('--cut-rate', type=probability, default=0.0,
                   help='probability that a streamed frame (capsule or node) is cut short: a '
                        'run of its bytes, from a random one to its end, is lost (default: '
                        '%(default)s)')
    p.add_argument('--insert-rate', type=probability, default=0.0,
                   help='probability that a random byte is inserted after a streamed byte '
                        '(default: %(default)s)')
    p.add_argument('--flip-rate', type=probability, default=0.0,
                   help='probability that a streamed frame has one bit flipped in two of its '
                        'bytes, which its XOR checksum does not see (default: %(default)s)')
    p.add_argument('--replay-rate', type=probability, default=0.0,
                   help='probability that a streamed frame is followed by a copy of one of the '
                        '8 before it (default: %(default)s)')
    p.add_argument('--swap-rate', type=probability, default=0.0,
                   help='probability that a 64-byte USB packet of the stream is swapped with '
                        'the next (default: %(default)s)')
    p.add_argument('--duplicate-rate', type=probability, default=0.0,
                   help='probability that a 64-byte USB packet of the stream is delivered '
                        'twice (default: %(default)s)')
    p.add_argument('--silent-after', type=bounded(float, 0.0),
                   help='go silent after this many seconds (default: never)')
    p.add_argument('--silent-for', type=bounded(float, 0.0), default=3.0,
                   help='silence duration, s (default: %(default)s)')
    p.add_argument('--health', choices=['ok', 'warning', 'error'], default='ok',
                   help='health status to report (default: %(default)s)')
    p.add_argument('--conf-answer', type=_conf_answer, action='append', default=[],
                   metavar='ENTRY=VALUE',
                   help=f'report this GET_LIDAR_CONF value instead of the real one (for every '
                        f'scan mode: a faulty device), repeatable; ENTRY one of '
                        f'{", ".join(CONF_ENTRIES)}, VALUE a number (max_distance in m) or none '
                        f'(the entry answered with no value) (default: the real ones)')
    p.add_argument('--health-error-resets', type=bounded(int, 0), default=1,
                   help='RESETs that clear a health error (default: %(default)s)')
    scene_options(p)
    return p


def _check_link(link: str):
    """Refuse a ``--link`` path that would replace something other than an old symlink."""
    if os.path.lexists(link) and not os.path.islink(link):
        raise UserError(f'--link {link}: exists and is not a symlink; give a new path')
    if not os.path.isdir(os.path.dirname(os.path.abspath(link))):
        raise UserError(f'--link {link}: no such directory')


def _read_stdin_commands(commands: queue.SimpleQueue):
    """Forward standard input lines to the command queue (until EOF)."""
    for line in sys.stdin:
        commands.put(line)


def _start_reading_commands(commands: queue.SimpleQueue):
    """
    Start the thread that forwards standard input to the command queue.

    A KeyboardInterrupt inside ``Thread.start()`` breaks its condition's lock (RuntimeError:
    release unlocked lock: status 1 and a traceback instead of 130), so a SIGINT meanwhile is
    only noted, and raised once the thread has started. (Blocking SIGINT with pthread_sigmask
    would not do: the kernel hands it to another thread of the process that does not block it,
    and Python still runs the handler in this one.)
    """
    interrupted = []
    ctrl_c = signal.signal(signal.SIGINT, lambda *_: interrupted.append(True))
    try:
        threading.Thread(target=_read_stdin_commands, args=(commands,), daemon=True).start()
    finally:
        signal.signal(signal.SIGINT, ctrl_c)
    if interrupted:
        raise KeyboardInterrupt


def _serve(args, scene_of: Callable):
    """Start the emulator, announce it on standard output and serve until ``quit``."""
    scene, scene_name = scene_of(args)
    faults = Faults(corrupt_rate=args.corrupt_rate, drop_rate=args.drop_rate,
                    cut_rate=args.cut_rate, insert_rate=args.insert_rate,
                    flip_rate=args.flip_rate, replay_rate=args.replay_rate,
                    swap_rate=args.swap_rate, duplicate_rate=args.duplicate_rate,
                    health=HealthStatus[args.health.upper()],
                    resets_to_clear=args.health_error_resets)
    for answer in args.conf_answer:
        faults.replace_conf_answer(answer)
    if args.silent_after is not None:
        faults.silent_from_s = time.monotonic() + args.silent_after
        faults.silent_until_s = faults.silent_from_s + args.silent_for
    if args.link:
        _check_link(args.link)
    model = EMULATED_MODELS[args.model]
    if args.no_accessory_board:
        model = model.without_accessory_board()
    baudrate = model.baudrate if args.baudrate is None else args.baudrate or None
    try:
        pty_port = PtyPort(args.link, baudrate)
    except OSError as error:
        option = '--link' if baudrate is None else '--link/--baudrate'
        raise UserError(f'{option} {args.link}: {error.strerror or error}') from None
    listener = None
    if args.tcp_port is not None:
        try:
            listener = socket.create_server((args.tcp_host, args.tcp_port))
        except OSError as error:
            pty_port.unplug()
            raise UserError(f'--tcp-host/--tcp-port {args.tcp_host}:{args.tcp_port}: '
                            f'{error.strerror or error}') from None
    emulator = Emulator(scene, faults, args.firmware or model.firmware, args.seed, pty_port,
                        listener, model.modes, model.typical_mode, model)
    try:
        signal.signal(signal.SIGTERM, lambda *_: emulator.commands.put('quit'))
        # A shell starts a script's background jobs with SIGINT ignored, and Python then leaves
        # it so: the demo's SIGINT to its process group (or a test's) would not stop us. Whoever
        # sends it means it, as for the nodes (rclpy installs its own SIGINT handler).
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _start_reading_commands(emulator.commands)
        print(f'pty {emulator.pty.path}', flush=True)
        if args.link:
            print(f'link {args.link}', flush=True)
        if listener is not None:
            host, port = listener.getsockname()[:2]
            print(f'tcp {host}:{port}', flush=True)
        rate = f'{baudrate} baud' if baudrate else 'any rate'
        print(f'ready: RPLIDAR {model_name(model.model)} emulator ({rate}, motor '
              f'{model.motor.value if model.motor else "run by itself"}), seeing '
              f'{scene_name}', flush=True)
        emulator.run()
    finally:
        emulator.close()


def main(argv=None, prog: str = PROG, scene_options: Callable = room_options,
         scene_of: Callable = room_scene) -> int:
    """
    Run the emulator until ``quit`` on standard input, SIGTERM or Ctrl-C.

    :param argv: command-line arguments (default: ``sys.argv[1:]``)
    :param prog: the program's name
    :param scene_options: adds the scene's options to the parser (see :func:`room_options`)
    :param scene_of: builds (scene, its name) from the parsed options (see :func:`room_scene`);
        raises :class:`UserError` on a bad option
    :return: exit status: 0 after quit or SIGTERM, 2 on a user error, 130 on Ctrl-C
    """
    try:
        _serve(parser(prog, scene_options).parse_args(argv), scene_of)
    except UserError as error:
        print(f'{prog}: error: {error}', file=sys.stderr)
        return USER_ERROR
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    return 0


if __name__ == '__main__':
    sys.exit(main())
