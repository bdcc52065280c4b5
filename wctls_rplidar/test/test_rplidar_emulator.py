# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The S1 emulator in its own process, over a real pseudo-terminal: bytes, timing, oracles."""

import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from rplidar_testing import range_band, true_ranges
import serial
from wctls_rplidar.protocol import StandardNodeDecoder

# Runs nodes, emulators or signals against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime


def stop_stream(link, timeout_s=10.0):
    """
    Send STOP and read what was still streamed until the device falls silent.

    :param link: the open terminal
    :param timeout_s: deadline for the silence (no byte for 0.2 s), s
    """
    link.write(bytes.fromhex('A5 25'))
    read_timeout_s, link.timeout = link.timeout, 0.2
    deadline = time.monotonic() + timeout_s
    try:
        while link.read(4096):
            assert time.monotonic() < deadline, f'still streaming {timeout_s} s after STOP'
    finally:
        link.timeout = read_timeout_s


@pytest.fixture
def port(emulator):
    """Open the emulator's terminal as a host would, after stopping any stream."""
    with serial.Serial(emulator.link, 256000, timeout=1.0, dsrdtr=False, rtscts=False) as link:
        stop_stream(link)
        yield link


def ask(link, request_hex, answer_size):
    """Send a request (spec hex) and read a whole answer."""
    link.write(bytes.fromhex(request_hex))
    return link.read(answer_size).hex(' ').upper()


def test_answers_are_the_bytes_of_a_real_s1(port):
    assert ask(port, 'A5 50', 27).startswith('A5 5A 14 00 00 00 04 61 1C 01 12')
    assert ask(port, 'A5 52', 10) == 'A5 5A 03 00 00 00 06 00 00 00'
    assert ask(port, 'A5 59', 11) == 'A5 5A 04 00 00 00 15 F4 00 6C 00'
    assert ask(port, 'A5 84 04 7C 00 00 00 59', 13) == 'A5 5A 06 00 00 00 20 7C 00 00 00 01 00'
    assert ask(port, 'A5 84 06 71 00 00 00 01 00 57', 15).endswith('71 00 00 00 00 6C 00 00')
    names = [ask(port, f'A5 84 06 7F 00 00 00 {m:02X} 00 {0x58 ^ m:02X}', size)[33:]
             for m, size in ((0, 20), (1, 22))]
    assert [bytes.fromhex(n).rstrip(b'\0').decode() for n in names] == ['Standard',
                                                                        'DenseBoost']


def test_requests_timed_says_when_the_device_read_each_request(emulator, port):
    emulator.command('requests')                  # forget the requests heard before
    windows_s = []
    for request_hex, answer_size in (('A5 52', 10), ('A5 50', 27)):
        sent_s = time.monotonic()
        assert len(ask(port, request_hex, answer_size).split()) == answer_size
        windows_s.append((sent_s, time.monotonic()))
    heard = [word.split('@') for word in emulator.command('requests timed').split()[1:]]
    assert [name for name, _ in heard] == ['GET_HEALTH', 'GET_INFO']
    # Read after it was sent and before its answer came back, on this machine's monotonic clock.
    assert all(sent_s <= float(at_s) <= answered_s
               for (_, at_s), (sent_s, answered_s) in zip(heard, windows_s))


def test_reset_is_silent_and_the_device_reboots(port):
    port.write(bytes.fromhex('A5 40 A5 50'))            # RESET, then GET_INFO at once
    port.timeout = 1.0
    assert port.read(1) == b''                           # no banner, no answer while booting
    # Back after its boot (1.5 s of its own clock, which a busy machine may run late): a host
    # asks again until it answers.
    deadline = time.monotonic() + 30.0
    while not (answer := ask(port, 'A5 50', 27)) and time.monotonic() < deadline:
        pass
    assert answer.startswith('A5 5A 14'), answer


def read_stream(link, seconds):
    """Return the bytes streamed during ``seconds``."""
    data = b''
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        data += link.read(max(link.in_waiting, 1))
    return data


def test_denseboost_streams_capsules_at_real_timing_with_s_on_the_first_only(port):
    port.write(bytes.fromhex('A5 A8 02 58 02 55 A5 82 05 01 00 00 00 00 23'))
    assert port.read(7).hex(' ').upper() == 'A5 5A 54 00 00 40 85'
    started = time.monotonic()
    data = read_stream(port, 1.0)
    elapsed = time.monotonic() - started
    stop_stream(port)
    capsules = np.frombuffer(data[:len(data) // 84 * 84], np.uint8).reshape(-1, 84)
    # 40 samples of 108 us per capsule: 231.5 capsules per second.
    assert len(capsules) / elapsed == pytest.approx(1e6 / (40 * 108), rel=0.05)
    assert ((capsules[:, 0] >> 4) == 0xA).all() and ((capsules[:, 1] >> 4) == 0x5).all()
    checksums = np.bitwise_xor.reduce(capsules[:, 2:], axis=1)
    np.testing.assert_array_equal((capsules[:, 0] & 0xF) | (capsules[:, 1] << 4), checksums)
    assert (capsules[:, 3] >> 7).tolist() == [1] + [0] * (len(capsules) - 1)
    # STOP ended the stream: the device answers a request again, and with nothing else.
    assert ask(port, 'A5 52', 10) == 'A5 5A 03 00 00 00 06 00 00 00'


def test_standard_nodes_decode_alike_with_the_rplidar_package_and_show_the_scene(port):
    rplidar = pytest.importorskip('rplidar')
    port.write(bytes.fromhex('A5 20'))
    assert port.read(7).hex(' ').upper() == 'A5 5A 05 00 00 40 81'
    data = read_stream(port, 0.5)
    port.write(bytes.fromhex('A5 25'))
    data = data[:len(data) // 5 * 5]
    ours = StandardNodeDecoder().feed(data)
    theirs = np.array([rplidar._process_scan(data[i:i + 5]) for i in range(0, len(data), 5)])
    np.testing.assert_array_equal(theirs[:, 0], ours.start)
    np.testing.assert_array_equal(theirs[:, 2], ours.angle_deg)
    np.testing.assert_array_equal(theirs[:, 3], ours.distance_mm)
    # 411.4 nodes of 244 us per 10 Hz turn, one S flag each.
    turn_starts = np.flatnonzero(ours.start)
    assert len(turn_starts) >= 3 and set(np.diff(turn_starts).tolist()) <= {411, 412}
    bearing = math.pi - np.radians(ours.angle_deg)
    np.testing.assert_allclose(ours.distance_mm / 1000.0, true_ranges(bearing), atol=1.25e-4)


def test_serves_tcp_too(emulator):
    with socket.create_connection(('127.0.0.1', emulator.tcp_port), timeout=2.0) as client:
        client.sendall(bytes.fromhex('A5 52'))
        answer = b''
        while len(answer) < 10:
            answer += client.recv(10)
    assert answer == bytes.fromhex('A5 5A 03 00 00 00 06 00 00 00')


def test_unplug_breaks_the_open_port_and_replug_brings_a_new_device(emulator):
    with serial.Serial(emulator.link, 256000, timeout=1.0, dsrdtr=False, rtscts=False) as link:
        assert emulator.command('unplug') == 'unplugged'
        assert not os.path.exists(emulator.link)
        with pytest.raises(serial.SerialException):
            link.read(1)
    assert emulator.command('replug') == f'replugged {os.path.realpath(emulator.link)}'
    with serial.Serial(emulator.link, 256000, timeout=1.0, dsrdtr=False, rtscts=False) as link:
        assert ask(link, 'A5 52', 10) == 'A5 5A 03 00 00 00 06 00 00 00'


SDK_CLIENT = """
import json, sys
import pyrplidarsdk
driver = pyrplidarsdk.RplidarDriver(port=sys.argv[1], baudrate=256000)
assert driver.connect(), 'connect failed'
info, health = driver.get_device_info(), driver.get_health()
assert driver.start_scan(), 'start_scan failed'
turns = [driver.get_scan_data() for _ in range(4)][1:]
driver.stop_scan()
driver.disconnect()
print(json.dumps({'info': [info.model, info.firmware_version, info.hardware_version],
                  'health': health.status, 'turns': [[list(t[0]), list(t[1])] for t in turns]}))
"""


def test_the_official_sdk_reads_the_emulator_end_to_end(emulator):
    pytest.importorskip('pyrplidarsdk')
    # The SDK holds the GIL while it blocks: it runs in its own process.
    result = subprocess.run([sys.executable, '-c', SDK_CLIENT, emulator.link], timeout=60,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report['info'] == [0x61, 0x011C, 18] and report['health'] == 0
    for angles, ranges in report['turns']:
        angles, ranges = np.array(angles), np.array(ranges)
        assert len(angles) in (926, 927)                 # DenseBoost, the typical mode
        # The SDK truncates each angle to 1/64 degree, then to 90/16384 degree: the true raw
        # angle lies up to their sum above the reported one.
        bearing = math.pi - angles
        low, high = range_band(bearing - math.radians(1 / 64 + 90 / 16384), bearing)
        assert ((ranges >= low - 6e-4) & (ranges <= high + 6e-4)).all()


def run_cli(*args, timeout_s=60.0):
    """Run the installed rplidar_emulator as a user would; return the finished process."""
    # A deadline for a run that must end: beside CPU hogs its start-up alone took over 20 s.
    from test_feature_node import installed_executable
    return subprocess.run([str(installed_executable('rplidar_emulator')), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout_s,
                          stdin=subprocess.DEVNULL)


def test_help_shows_every_default():
    result = run_cli('--help')
    assert result.returncode == 0 and not result.stderr
    options = result.stdout.split('options:')[1].split('Lines on standard input')[0]
    # One entry per option: its flags, then its help, possibly wrapped over several lines.
    entries = [' '.join(entry.split()) for entry in re.split(r'\n  (?=-)', options) if entry]
    # 20, and the rates of inserted bytes, bit flips, replays, packet swaps and duplicates.
    assert len(entries) == 25
    for entry in entries[1:]:                                     # all but -h/--help
        assert '(default:' in entry, entry
    text = ' '.join(result.stdout.split())
    assert '(default: 2.2 1.25 0, mid-room)' in text and "(default: the model's: A1 1.29," in text
    assert '(default: 0.02)' in result.stdout


@pytest.fixture
def port_in_use():
    """Yield a TCP port some other socket listens on."""
    with socket.create_server(('127.0.0.1', 0)) as server:
        yield server.getsockname()[1]


@pytest.mark.parametrize('make_args, says', [
    (lambda tmp, port: ['--range-sigma', '-1'], '--range-sigma'),
    (lambda tmp, port: ['--pose', '1', 'x', '0'], '--pose'),
    (lambda tmp, port: ['--link', tmp / 'no' / 'such' / 'tty'], 'no such directory'),
    (lambda tmp, port: ['--link', write(tmp / 'precious.txt', 'keep me')], 'not a symlink'),
    (lambda tmp, port: ['--tcp-port', port], '--tcp-port'),
    (lambda tmp, port: ['--tcp-port', '70000'], '--tcp-port'),
    (lambda tmp, port: ['--firmware', 'one'], '--firmware'),
    (lambda tmp, port: ['--corrupt-rate', '1.5'], '--corrupt-rate'),
    (lambda tmp, port: ['--cut-rate', '-0.1'], '--cut-rate'),
    (lambda tmp, port: ['--flip-rate', '2'], '--flip-rate'),
    (lambda tmp, port: ['--conf-answer', 'speed=3'], 'ENTRY one of mode_count'),
    (lambda tmp, port: ['--conf-answer', 'us_per_sample=1e12'], 'does not fit'),
    (lambda tmp, port: ['--health', 'bad'], '--health'),
])
def test_a_user_error_is_one_line_and_status_2_without_a_traceback(
        tmp_path, port_in_use, make_args, says):
    result = run_cli(*make_args(tmp_path, port_in_use))
    assert result.returncode == 2, result.stderr
    assert result.stdout == '' and result.stderr.count('\n') == 1, result.stderr
    assert result.stderr.startswith('rplidar_emulator: error: ') and says in result.stderr
    precious = tmp_path / 'precious.txt'
    assert not precious.exists() or precious.read_text() == 'keep me'
    assert not list(tmp_path.glob('*.[0-9]*')), 'a temporary link was left behind'


# Python runs a SIGINT's handler between two bytecodes of the main thread; inside
# Thread.start() (the emulator's standard-input reader) that broke the start's lock: status 1
# and a traceback instead of 130, once in a full test run. A profile hook sends the SIGINT
# at that moment.
_CTRL_C_WHILE_THE_READER_STARTS = """
import os
import signal
import sys
import threading

from wctls_rplidar.emulator import cli

started = []


def sigint_inside_thread_start(frame, event, argument):
    if event != 'call' or frame.f_code is not threading.Condition._acquire_restore.__code__:
        return
    caller = frame.f_back
    while caller is not None and caller.f_code is not threading.Thread.start.__code__:
        caller = caller.f_back
    if caller is not None:
        sys.setprofile(None)
        started.append(True)
        os.kill(os.getpid(), signal.SIGINT)


sys.setprofile(sigint_inside_thread_start)
status = cli.main(sys.argv[1:])
print('signalled inside Thread.start' if started else 'never signalled', flush=True)
sys.exit(status)
"""


def test_ctrl_c_while_the_command_reader_starts_exits_130(tmp_path):
    result = subprocess.run(
        [sys.executable, '-c', _CTRL_C_WHILE_THE_READER_STARTS, '--link', str(tmp_path / 'tty')],
        stdin=subprocess.PIPE, capture_output=True, text=True, timeout=60)
    assert 'signalled inside Thread.start' in result.stdout, (result.stdout, result.stderr)
    assert (result.returncode, 'Traceback' in result.stderr) == (130, False), result.stderr
    assert not (tmp_path / 'tty').is_symlink()


def write(path, text):
    """Write ``text`` to ``path``; return the path."""
    path.write_text(text)
    return path


@pytest.mark.parametrize('stop, status, sigint_ignored', [
    ('quit', 0, False), (signal.SIGTERM, 0, False), (signal.SIGINT, 130, False),
    # A shell starts a script's background jobs with SIGINT ignored (``make demo &``); the
    # demo still stops the emulator with SIGINT.
    (signal.SIGINT, 130, True)])
def test_exit_status_after_quit_sigterm_and_ctrl_c(tmp_path, stop, status, sigint_ignored):
    from test_feature_node import installed_executable
    link = tmp_path / 'ttyS1'
    command = [str(installed_executable('rplidar_emulator')), '--link', str(link)]
    if sigint_ignored:                  # an ignored signal stays ignored through exec
        command = ['sh', '-c', 'trap "" INT && exec "$0" "$@"', *command]
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        while not process.stdout.readline().startswith('ready:'):
            assert process.poll() is None, process.stderr.read()
        assert link.is_symlink()
        if stop == 'quit':
            process.stdin.write('quit\n')
            process.stdin.flush()
        else:
            process.send_signal(stop)
        returncode = process.wait(timeout=10)
        errors = process.stderr.read()
        assert returncode == status, errors
        assert 'Traceback' not in errors
        assert not link.exists() and not link.is_symlink()
    finally:
        if process.poll() is None:
            process.kill()
        process.communicate()


# SIGTERM at the moment the serving loop takes a command off its queue: a profile hook sends
# it inside the queue's get (a queue.Queue holds its lock there: its _qsize; a SimpleQueue's
# get_nowait is one C call). With a queue.Queue the handler's put waited for that lock for ever:
# an emulator outlived the demo that had started it.
_SIGTERM_WHILE_A_COMMAND_IS_TAKEN = """
import os
import signal
import sys

from wctls_rplidar.emulator.cli import main


def sigterm_inside_the_queue(frame, event, argument):
    if (event == 'call' and frame.f_code.co_name == '_qsize') or (
            event == 'c_call' and getattr(argument, '__name__', '') == 'get_nowait'):
        sys.setprofile(None)
        os.kill(os.getpid(), signal.SIGTERM)


sys.setprofile(sigterm_inside_the_queue)
sys.exit(main(['--link', sys.argv[1]]))
"""


def test_sigterm_while_a_command_is_taken_ends_the_emulator(tmp_path):
    process = subprocess.Popen([sys.executable, '-c', _SIGTERM_WHILE_A_COMMAND_IS_TAKEN,
                                str(tmp_path / 'ttyS1')], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        returncode = process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        pytest.fail('the emulator hung after SIGTERM')
    finally:
        _, errors = process.communicate()
    assert (returncode, errors) == (0, '')
