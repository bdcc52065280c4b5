# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Every RPLIDAR model the emulator speaks, driven end to end: rates, modes and motors."""

import math
import os
import signal
import subprocess
import threading
import time

import numpy as np
import pytest
from rplidar_testing import emulated_device, LogLines, serving, true_ranges, wait_for
from wctls_rplidar.driver import DriverConfig, DriverState, RplidarDriver
from wctls_rplidar.emulator.device import EMULATED_MODELS, Faults
from wctls_rplidar.parameters import PARAMETERS
from wctls_rplidar.protocol import (encode_motor_speed, encode_request, HealthStatus,
                                    MotorControl, StandardNodeDecoder)
from wctls_rplidar.transport import LinkError, SerialLink

# Runs nodes, emulators or signals against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime

# How each model's motor is driven, as SLAMTEC's SDK finds out.
MOTORS = {'a1': MotorControl.DTR, 'a2': MotorControl.PWM, 'a3': MotorControl.PWM,
          'c1': MotorControl.DTR, 's1': MotorControl.RPM, 's2': MotorControl.RPM,
          's3': MotorControl.RPM}


class Turns:
    """Collect the driver's turns (on its reader thread)."""

    def __init__(self):
        self.turns = []
        self._lock = threading.Lock()

    def __call__(self, turn, mode):
        with self._lock:
            self.turns.append((turn, mode))

    def count(self):
        """Return the number of turns received."""
        with self._lock:
            return len(self.turns)


def start_driver(link_or_port, **config):
    """Start a driver on a pty path or an in-process link; return it, its turns and its log."""
    turns, log = Turns(), LogLines()
    if isinstance(link_or_port, str):
        driver = RplidarDriver(DriverConfig(serial_port=link_or_port, **config), turns, log)
    else:
        driver = RplidarDriver(DriverConfig(**config), turns, log, link_or_port.connect)
    driver.start()
    return driver, turns, log


@pytest.mark.parametrize('name', list(EMULATED_MODELS))
def test_every_model_scans_end_to_end_at_its_own_rate_found_by_probing(name):
    # Neither the driver nor the node is told the rate: both default to probing.
    baudrate = next(p.default for p in PARAMETERS if p.name == 'serial_baudrate')
    assert baudrate == DriverConfig().serial_baudrate == 0
    model = EMULATED_MODELS[name]
    with serving(name, baudrate=model.baudrate) as path:
        driver, turns, log = start_driver(path)
        try:
            wait_for(lambda: turns.count() >= 3, what=f'3 turns from the {name}')
            status = driver.status()
        finally:
            driver.close()
    assert status.baudrate == model.baudrate
    assert status.device.model == model.model and status.device.firmware == model.firmware
    assert status.device.model_name.startswith(name.upper())
    assert status.motor == MOTORS[name]
    typical = model.modes[model.typical_mode]
    assert status.mode.name == typical.name and status.mode.answer_type == typical.answer_type
    assert status.mode.us_per_sample == typical.us_per_sample
    for turn, mode in turns.turns[1:3]:
        # One turn at the model's speed and sample time: the A1 turns at 5.5 Hz, the others 10.
        period_s = 60.0 / (model.own_rpm if name == 'a1' else 600)
        assert len(turn.distance_mm) == pytest.approx(period_s / (typical.us_per_sample * 1e-6),
                                                      rel=0.02)
        returns = turn.distance_mm > 0
        truth_mm = 1000.0 * true_ranges(math.pi - np.radians(turn.angle_deg[returns]))
        assert returns.mean() > 0.8
        # Express and ultra capsules carry their angles to 1/8 and 1/64 degree, whole mm.
        assert np.median(np.abs(turn.distance_mm[returns] - truth_mm)) < 2.0


@pytest.mark.parametrize('name', ['a2', 'a3'])
def test_a_noisy_scene_in_ultra_capsules_keeps_its_returns(name):
    # The emulator measures an ultra capsule's sample again at the angle its distance moves it
    # to; with a fresh noise draw each time no noisy sample settled, and 97 % went out as no
    # return (the A2 demo showed 3 % of its beams).
    from wctls_rplidar.emulator.cli import ROOM_RANGE_SIGMA_M
    from wctls_rplidar.emulator.room import RoomScene, SENSOR_POSE
    from wctls_rplidar.emulator.server import Emulator, PtyPort
    profile = EMULATED_MODELS[name]
    scene = RoomScene(SENSOR_POSE, ROOM_RANGE_SIGMA_M, np.random.default_rng(0))
    emulator = Emulator(scene, Faults(), profile.firmware, 0, PtyPort(None, None),
                        modes=profile.modes, typical_mode=profile.typical_mode, model=profile)
    thread = threading.Thread(target=emulator.run)
    thread.start()
    try:
        driver, turns, _ = start_driver(emulator.pty.path)
        try:
            wait_for(lambda: turns.count() >= 3, what=f'3 turns from the {name}')
        finally:
            driver.close()
    finally:
        emulator.commands.put('quit')
        thread.join()
        emulator.close()
    for turn, mode in turns.turns[1:3]:
        assert mode.answer_type == 0x84
        returns = turn.distance_mm > 0
        assert returns.mean() > 0.9
        truth_mm = 1000.0 * true_ranges(math.pi - np.radians(turn.angle_deg[returns]))
        assert np.median(np.abs(turn.distance_mm[returns] - truth_mm)) < 40.0   # 2 cm noise


@pytest.mark.parametrize('name, accessory_board, frequency_hz, rpm', [
    ('a1', True, 10.0, 330),          # the DTR line only switches: its own 5.5 Hz
    ('a2', True, 8.0, 480),           # PWM 528 of the 660 that make 600 rpm
    ('a2', False, 8.0, 600),          # no board: the DTR line, its own 10 Hz
    ('a3', True, 12.0, 720),
    ('c1', True, 8.0, 600),           # the C1 runs its own 10 Hz
    ('s1', True, 8.0, 480),
    ('s3', True, 12.0, 720),
])
def test_the_motor_runs_the_models_way_and_close_stops_it(name, accessory_board, frequency_hz,
                                                          rpm):
    model = EMULATED_MODELS[name]
    if not accessory_board:
        model = model.without_accessory_board()
    device, link = emulated_device(model)
    driver, turns, log = start_driver(link, scan_frequency_hz=frequency_hz)
    try:
        wait_for(lambda: turns.count() >= 2, what=f'2 turns from the {name}')
        assert device.motor_rpm == rpm and device.scanning
        assert driver.status().motor == (model.motor or MotorControl.DTR)
    finally:
        driver.close()
    assert device.motor_rpm == 0 and not device.scanning
    dtr_lines = [line for line in log.lines if 'DTR line' in line]
    if driver.status().motor == MotorControl.DTR:
        assert len(dtr_lines) == 1 and 'scan_frequency (' in dtr_lines[0], log.lines
    else:
        assert not dtr_lines


def test_an_s_series_motor_keeps_turning_after_stop_until_its_speed_is_zero():
    device, link = emulated_device('s1')
    link.write(encode_motor_speed(600) + encode_request(0x20))
    wait_for(lambda: link.read(0.05), what='standard nodes')
    link.write(encode_request(0x25))
    assert device.motor_rpm == 600 and not device.scanning
    link.write(encode_motor_speed(0))
    assert device.motor_rpm == 0


def test_a_pwm_model_streams_nothing_until_its_motor_runs():
    device, link = emulated_device('a2')
    link.write(encode_request(0x20))
    assert link.read(0.3)[:7] == bytes.fromhex('A5 5A 05 00 00 40 81') and device.motor_rpm == 0
    assert link.read(0.2) == b''


def test_close_after_the_port_is_lost_returns_at_once_and_says_so():
    device, link = emulated_device('s1')
    driver, turns, log = start_driver(link)
    wait_for(lambda: turns.count() >= 1, what='a turn')
    link.unplug()
    started = time.monotonic()
    driver.close()
    assert time.monotonic() - started < 2.0
    assert driver.status().state == DriverState.CLOSED
    driver.close()                                   # a second close is harmless
    assert any('could not be told to stop' in line for line in log.lines) or \
        any('unplugged' in line for line in log.lines), log.lines


def test_close_from_a_signal_handler_stops_the_motor():
    device, link = emulated_device('a2')
    driver, turns, _ = start_driver(link)
    wait_for(lambda: turns.count() >= 1, what='a turn')
    closed = []
    previous = signal.signal(signal.SIGALRM, lambda *_: closed.append(driver.close()))
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        deadline = time.monotonic() + 10.0
        while not closed and time.monotonic() < deadline:
            driver.status()                          # the main thread busy with the driver
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
    assert closed and device.motor_rpm == 0 and not device.scanning


@pytest.mark.parametrize('name', ['a1', 'a2'])
def test_old_firmware_scans_the_standard_mode_from_get_samplerate(name):
    device, link = emulated_device(name, firmware=(1, 20))
    driver, turns, _ = start_driver(link)
    try:
        wait_for(lambda: turns.count() >= 1, what='a turn')
        mode = driver.status().mode
    finally:
        driver.close()
    assert (mode.name, mode.us_per_sample, mode.answer_type) == ('Standard', 500.0, 0x81)
    # It has no GET_LIDAR_CONF: the request goes unanswered.
    assert link.write(bytes.fromhex('A5 84 04 70 00 00 00 55')) is None and link.read(0.2) == b''


def test_a_new_design_with_a_low_firmware_number_has_its_scan_modes():
    # The S3's firmware 1.02 answers GET_LIDAR_CONF: SLAMTEC's SDK asks every C- and
    # S-series device whatever its firmware.
    device, link = emulated_device('s3')
    driver, turns, _ = start_driver(link)
    try:
        wait_for(lambda: turns.count() >= 1, what='a turn')
    finally:
        driver.close()
    assert driver.status().mode.name == 'DenseBoost'


def test_a_missing_port_says_no_such_device(tmp_path):
    driver, _, log = start_driver(str(tmp_path / 'ttyUSB9'))
    try:
        message = wait_for(lambda: driver.status().message if 'no such device'
                           in driver.status().message else '', what='an error')
    finally:
        driver.close()
    assert '\n' not in message and 'plugged in' in message


def test_no_answer_at_any_rate_says_so_in_one_line():
    with serving('s1', baudrate=57600) as path:
        driver, _, _ = start_driver(path)
        try:
            message = wait_for(lambda: driver.status().message if 'at any rate'
                               in driver.status().message else '', what='an error')
        finally:
            driver.close()
    assert '\n' not in message and 'not powered' in message, message


def test_a_device_answering_with_another_answer_type_is_named_not_the_port():
    # Every answer's descriptor says 0x99: the device answers, but not as this driver expects.
    with serving('s1', faults=Faults(answer_type=0x99)) as path:
        driver, turns, log = start_driver(path)
        try:
            message = wait_for(lambda: 'GET_INFO' in driver.status().message
                               and driver.status().message, what='a failed GET_INFO')
        finally:
            driver.close()
    assert 'answered with answer type 0x99 instead of 0x04' in message, message
    assert 'serial_baudrate' not in message and not turns.turns
    assert any('answer type 0x99' in line for line in log.lines), log.lines


def test_a_lasting_health_error_names_its_code_in_one_line():
    _, link = emulated_device('s1', faults=Faults(health=HealthStatus.ERROR, resets_to_clear=99))
    driver, _, log = start_driver(link, health_reset_attempts=0)
    try:
        wait_for(lambda: driver.status().state == DriverState.FAILED, what='giving up')
    finally:
        driver.close()
    message = [line for line in log.lines if line.startswith('error:')][-1]
    assert 'health error (code 0x0001)' in message and '\n' not in message, message
    assert 'power-cycle the device' in message


def test_a_port_without_permission_names_the_dialout_group():
    if os.geteuid() != 0:
        pytest.skip('needs root to open a port as another user')
    with serving('s1') as path:
        os.chmod(path, 0o600)
        reader, writer = os.pipe()
        child = os.fork()
        if child == 0:                               # as nobody, with the modules loaded
            try:
                os.setuid(65534)
                SerialLink(path, 256000)
                message = 'opened'
            except LinkError as error:
                message = str(error)
            os.write(writer, message.encode())
            os._exit(0)
        os.close(writer)
        os.waitpid(child, 0)
        with os.fdopen(reader) as pipe:
            message = pipe.read()
    assert 'permission denied' in message and 'dialout group' in message, message
    assert '\n' not in message


def test_a_pty_has_no_dtr_line_and_the_a1_runs_as_it_is():
    with serving('a1') as path:
        driver, turns, log = start_driver(path)
        try:
            wait_for(lambda: turns.count() >= 1, what='a turn')
        finally:
            driver.close()
    assert any('has no DTR line' in line for line in log.lines), log.lines


@pytest.mark.parametrize('program, options, heard', [
    ('rplidar_emulator', ['--model', 'c1'], {460800}),
    ('rplidar_emulator', [], {256000}),
    ('rplidar_emulator', ['--baudrate', '0'], {115200, 256000, 460800}),
])
def test_the_emulator_answers_only_at_the_models_rate(program, options, heard):
    from test_feature_node import installed_executable
    import serial
    process = subprocess.Popen([str(installed_executable(program)), '--noiseless', *options],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        pty_path = process.stdout.readline().split()[1]
        ready = process.stdout.readline()
        assert ready.startswith('ready: RPLIDAR'), ready
        for rate in (115200, 256000, 460800):
            with serial.Serial(pty_path, rate, timeout=0.5, dsrdtr=False, rtscts=False) as port:
                port.write(bytes.fromhex('A5 50'))
                answer = port.read(27)
            answered = answer[:7] == bytes.fromhex('A5 5A 14 00 00 00 04')
            assert answered == (rate in heard), (rate, answer)
    finally:
        process.stdin.write('quit\n')
        process.stdin.close()
        process.wait(10)
        process.stdout.close()


def test_standard_nodes_of_the_fast_models_fit_their_line():
    # The S3's 16 kHz Standard mode at 1 Mbaud: 5-byte nodes leave room on the line.
    device, link = emulated_device('s3')
    link.write(encode_motor_speed(600) + encode_request(0x20))
    data = b''
    started = time.monotonic()
    while time.monotonic() - started < 0.5:
        data += link.read(0.05)
    samples = StandardNodeDecoder().feed(data[7:])
    rate_hz = len(samples) / (time.monotonic() - started)
    assert rate_hz == pytest.approx(16000, rel=0.15)
    assert 5 * 10 * 16000 < EMULATED_MODELS['s3'].baudrate
