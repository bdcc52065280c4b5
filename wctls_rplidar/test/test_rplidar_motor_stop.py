# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The motor stops on every exit of the driver, in every state, for every model the emulator speaks.

Each case acts at an exact point of a session through the in-process link's hooks (no sleeps):
the driver is closed while it backs off after a failed session (a garbage stream, silence, a
link that broke with the device still powered, a bug in the session), during its first
handshake with a device an earlier process left turning, and after it gave up. The emulated
motor turns only as the model's own control says (an S-series one until MOTOR_SPEED 0, an A2/A3
board's until SET_MOTOR_PWM 0, an A1's while DTR is cleared, a C1's while it scans), so the
device's speed after close is the truth.
"""

import math

import pytest
from rplidar_testing import emulated_device, LogLines, wait_for
from wctls_rplidar.driver import DriverConfig, DriverState, RplidarDriver
from wctls_rplidar.emulator.device import EMULATED_MODELS, Faults
from wctls_rplidar.protocol import (Command, ConfType, encode_motor_pwm, encode_motor_speed,
                                    encode_request)

# Runs drivers against emulated devices with deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime

MODELS = list(EMULATED_MODELS)
# An answer type no RPLIDAR streams or answers with.
UNKNOWN_ANSWER_TYPE = 0x99
# Short, so that a fault ends the session soon.
DATA_TIMEOUT_S = 0.3


def garbage(device, link, faults):
    """Corrupt every streamed byte: no valid frame, the session ends after data_timeout."""
    faults.corrupt_rate = 1.0


def silence(device, link, faults):
    """Silence the device (it speaks again as the driver closes)."""
    faults.silent_from_s, faults.silent_until_s = 0.0, math.inf


def broken_link(device, link, faults):
    """Break the link, the device still powered."""
    link.break_connection()


def session_bug(device, link, faults):
    """Raise an unexpected exception in the session."""
    link.read_error = RuntimeError('a bug in the session')


FAULTS = {'garbage': garbage, 'silence': silence, 'broken link': broken_link,
          'exception': session_bug}


def scanning_driver(name):
    """Return an emulated ``name``, its link, its faults and a driver scanning it (1 turn)."""
    faults = Faults()
    device, link = emulated_device(name, faults=faults)
    turns = []
    # Garbage in standard nodes still decodes as nodes now and then: the C1 runs DenseBoost.
    config = DriverConfig(data_timeout_s=DATA_TIMEOUT_S,
                          scan_mode='DenseBoost' if name == 'c1' else '')
    driver = RplidarDriver(config, lambda turn, mode: turns.append(turn), LogLines(),
                           link.connect)
    driver.start()
    wait_for(lambda: turns, what=f'a turn from the {name}')
    assert device.motor_rpm > 0 and device.scanning
    return device, link, faults, driver


def leave_running(device, link):
    """Start the motor and a scan as an earlier process that was killed would have left them."""
    link.write(encode_motor_speed(600) + encode_motor_pwm(660))
    link.set_dtr(False)
    link.write(encode_request(Command.SCAN))
    wait_for(lambda: link.read(0.05), what='the stream of a device left running')
    assert device.motor_rpm > 0 and device.scanning


@pytest.mark.parametrize('fault', list(FAULTS))
@pytest.mark.parametrize('name', MODELS)
def test_close_while_backing_off_after_a_failed_session_stops_the_motor(name, fault):
    device, link, faults, driver = scanning_driver(name)

    def close_as_the_session_ends():
        # The failed session's link is closed, the back-off comes next: close now.
        link.on_close = None
        faults.silent_until_s = 0.0
        driver.close()

    link.on_close = close_as_the_session_ends
    FAULTS[fault](device, link, faults)
    try:
        wait_for(lambda: link.on_close is None, what=f'the session to fail on {fault}')
    finally:
        driver.close()
    assert driver.status().reconnects >= 1
    assert device.motor_rpm == 0 and not device.scanning


@pytest.mark.parametrize('name', MODELS)
def test_close_during_the_first_handshake_stops_a_motor_left_running(name):
    # A device answering with another answer type: GET_INFO is never answered as expected.
    device, link = emulated_device(name, faults=Faults(answer_type=UNKNOWN_ANSWER_TYPE))
    leave_running(device, link)
    driver = RplidarDriver(DriverConfig(), lambda turn, mode: None, LogLines(), link.connect)

    def close_at_get_info(data):
        if data == encode_request(Command.GET_INFO):
            link.on_write = None
            driver.close()

    link.on_write = close_at_get_info
    driver.start()
    try:
        wait_for(lambda: link.on_write is None, what='GET_INFO')
    finally:
        driver.close()
    assert driver.status().device is None
    assert device.motor_rpm == 0 and not device.scanning


@pytest.mark.parametrize('name', MODELS)
def test_a_driver_that_gives_up_stops_the_motor_and_close_keeps_it_stopped(name):
    # Every scan mode streams an answer type the driver does not decode: it gives up.
    faults = Faults(conf_answers={ConfType.ANSWER_TYPE: UNKNOWN_ANSWER_TYPE})
    device, link = emulated_device(name, faults=faults)
    leave_running(device, link)
    log = LogLines()
    driver = RplidarDriver(DriverConfig(), lambda turn, mode: None, log, link.connect)
    driver.start()
    try:
        wait_for(lambda: driver.status().state == DriverState.FAILED, what='the driver to give up')
        wait_for(lambda: device.motor_rpm == 0, timeout_s=5.0, what='the motor to stop')
        assert not device.scanning
    finally:
        driver.close()
    assert device.motor_rpm == 0 and not device.scanning
    assert any('does not decode' in line for line in log.lines), log.lines


def test_close_of_a_driver_that_never_reached_the_port_says_so_in_one_line(tmp_path):
    log = LogLines()
    driver = RplidarDriver(DriverConfig(serial_port=str(tmp_path / 'missing')),
                           lambda turn, mode: None, log)
    driver.start()
    wait_for(lambda: driver.status().message != 'starting', what='a failed open')
    driver.close()
    stops = [line for line in log.lines if 'could not be told to stop' in line]
    assert len(stops) == 1 and 'no such device' in stops[0], log.lines
