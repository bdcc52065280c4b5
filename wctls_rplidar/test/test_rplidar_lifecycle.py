# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
rplidar_node's lifecycle and its motor stop on every exit, against the emulator on a real pty.

What the device was told is read from the emulator itself (its ``requests`` log of the
requests it heard, and ``clock``, idle once it no longer streams), never from the node.
"""

import os
import pathlib
import signal
import subprocess
import sys
import time

from conftest import keep_all_sent, spin_until
import pytest

rclpy = pytest.importorskip('rclpy')

from lifecycle_msgs.msg import State, Transition  # noqa: E402, I100
from lifecycle_msgs.srv import ChangeState  # noqa: E402
from rclpy.lifecycle import TransitionCallbackReturn  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rplidar_testing import start_emulator  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402
from wctls_rplidar.driver import DriverState  # noqa: E402
from wctls_rplidar.rplidar_node import RplidarNode  # noqa: E402

# One of the suite's slowest modules (make test-fast leaves it out), and one that runs
# nodes, emulators or signals against deadlines (make test runs it in its realtime group).
pytestmark = [pytest.mark.slow, pytest.mark.realtime]

PACKAGE_DIR = pathlib.Path(__file__).resolve().parents[1]
NODE_EXECUTABLE = (PACKAGE_DIR.parents[0] / 'install' / 'wctls_rplidar' / 'lib'
                   / 'wctls_rplidar' / 'rplidar_node')
# Requests that start the motor or the scan, and those that stop them.
STARTS = ('SCAN', 'FORCE_SCAN', 'EXPRESS_SCAN')
STOPS = ('STOP', 'MOTOR_SPEED=0')


@pytest.fixture
def device(tmp_path):
    """Yield an emulator of the test's own: its request log is the test's evidence."""
    with start_emulator(tmp_path, '--seed', '7') as process:
        yield process


def heard(device) -> list:
    """Return the requests the emulated device heard since the last call, in order."""
    reply = device.command('requests')
    assert reply.startswith('requests '), reply
    words = reply.split()[1:]
    return [] if words == ['none'] else words


def motor_speeds(requests) -> list:
    """Return the MOTOR_SPEED values among requests, rpm."""
    return [int(r.split('=')[1]) for r in requests if r.startswith('MOTOR_SPEED=')]


def stopped_last(requests) -> bool:
    """Tell whether the last scan or motor start heard was followed by STOP and motor speed 0."""
    starts = [i for i, r in enumerate(requests) if r.split('=')[0] in STARTS
              or (r.startswith('MOTOR_SPEED=') and r != 'MOTOR_SPEED=0')]
    after = requests[starts[-1] + 1:] if starts else requests
    return 'STOP' in after and 'MOTOR_SPEED=0' in after


def motor_stopped(device, timeout_s=2.0) -> bool:
    """Wait until the device has heard STOP and motor speed 0 after its last start."""
    requests = []
    return wait_for(lambda: requests.extend(heard(device)) or stopped_last(requests), timeout_s)


def streaming(device) -> bool:
    """Tell whether the emulated device is streaming scan data."""
    return device.command('clock') != 'clock idle'


def wait_for(predicate, timeout_s):
    """Poll ``predicate`` every 20 ms until it is true or the timeout passes; return it."""
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.02)
    return predicate()


def make_node(context, **parameters):
    """Create rplidar_node with parameter overrides."""
    return RplidarNode(context=context, use_global_arguments=False, parameter_overrides=[
        Parameter(name, value=value) for name, value in parameters.items()])


def scan_counter(context, executor):
    """Add a node counting the scans published; return the list they are appended to."""
    scans = []
    listener = rclpy.create_node('listener', context=context)
    listener.create_subscription(LaserScan, 'scan', scans.append, keep_all_sent())
    executor.add_node(listener)
    return scans


def state_id(node) -> int:
    """Return the node's lifecycle state id."""
    return node._state_machine.current_state[0]


def test_the_transitions_open_scan_stop_and_close_the_device(executor, ros_context, device):
    node = make_node(ros_context, serial_port=device.link, autostart=False)
    executor.add_node(node)
    scans = scan_counter(ros_context, executor)
    spin_until(executor, lambda: False, 0.3)
    assert state_id(node) == State.PRIMARY_STATE_UNCONFIGURED and node.driver is None
    assert heard(device) == [] and not scans

    # configure: the port is opened and the info and health read; the motor stays idle.
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert state_id(node) == State.PRIMARY_STATE_INACTIVE
    requests = heard(device)
    assert {'GET_INFO', 'GET_HEALTH'} <= set(requests) and motor_speeds(requests) == [0]
    assert not any(r.split('=')[0] in STARTS for r in requests)
    spin_until(executor, lambda: False, 0.3)
    assert not scans and not streaming(device)

    # activate: motor and scan on, scans published.
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    assert spin_until(executor, lambda: len(scans) >= 2, 5.0)
    requests = heard(device)
    assert 'EXPRESS_SCAN=0x0100000000' in requests and motor_speeds(requests) == [600]

    # deactivate: scan and motor stopped, nothing published.
    assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    assert wait_for(lambda: not streaming(device), 2.0)
    spin_until(executor, lambda: False, 0.3)
    count = len(scans)
    spin_until(executor, lambda: False, 0.5)
    assert len(scans) == count
    assert motor_stopped(device)

    # cleanup closes the port; configure and activate again scan again.
    assert node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
    assert node.driver is None and state_id(node) == State.PRIMARY_STATE_UNCONFIGURED
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    assert spin_until(executor, lambda: len(scans) >= count + 2, 5.0)

    # shutdown from active stops the motor.
    heard(device)
    assert node.trigger_shutdown() == TransitionCallbackReturn.SUCCESS
    assert state_id(node) == State.PRIMARY_STATE_FINALIZED and node.driver is None
    assert stopped_last(heard(device)) and not streaming(device)


def test_deactivate_stops_the_motor(executor, ros_context, device):
    node = make_node(ros_context, serial_port=device.link)
    executor.add_node(node)
    assert wait_for(lambda: streaming(device), 5.0)
    heard(device)
    assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    assert wait_for(lambda: not streaming(device), 2.0)
    assert motor_stopped(device)


def change_state(executor, context, *transition_ids) -> list:
    """
    Send change_state requests at once from another node, as a lifecycle manager does.

    :param transition_ids: the transitions asked for, by id
    :return: each answer's ``success``
    """
    manager = rclpy.create_node('lifecycle_manager', context=context)
    client = manager.create_client(ChangeState, '/rplidar_node/change_state')
    executor.add_node(manager)
    try:
        assert spin_until(executor, client.service_is_ready, 20.0)
        futures = [client.call_async(ChangeState.Request(transition=Transition(id=i)))
                   for i in transition_ids]
        # The node's executor raised the failing transition's error: it ended here.
        assert spin_until(executor, lambda: all(f.done() for f in futures), 60.0)
    finally:
        executor.remove_node(manager)
        manager.destroy_node()
    return [future.result().success for future in futures]


def test_a_transition_the_state_does_not_have_is_refused_and_the_node_lives_on(
        executor, ros_context, device, capfd):
    node = make_node(ros_context, serial_port=device.link, autostart=False)
    executor.add_node(node)
    scans = scan_counter(ros_context, executor)
    assert change_state(executor, ros_context, Transition.TRANSITION_CLEANUP,
                        Transition.TRANSITION_ACTIVATE) == [False, False]
    assert state_id(node) == State.PRIMARY_STATE_UNCONFIGURED
    assert change_state(executor, ros_context, Transition.TRANSITION_CONFIGURE,
                        Transition.TRANSITION_ACTIVATE) == [True, True]
    assert spin_until(executor, lambda: len(scans) >= 1, 10.0)
    assert change_state(executor, ros_context, Transition.TRANSITION_CONFIGURE,
                        Transition.TRANSITION_CLEANUP) == [False, False]
    assert state_id(node) == State.PRIMARY_STATE_ACTIVE
    count = len(scans)
    assert spin_until(executor, lambda: len(scans) >= count + 2, 10.0)
    refusals = [line for line in capfd.readouterr().err.splitlines() if 'refused' in line]
    assert len(refusals) == 4, refusals
    assert 'transition 2 is not possible from the unconfigured state' in refusals[0]
    assert '(possible: deactivate, shutdown)' in refusals[2]
    # A manager asking for the shutdown of another state: this state's is the one meant.
    heard(device)
    assert change_state(executor, ros_context,
                        Transition.TRANSITION_UNCONFIGURED_SHUTDOWN) == [True]
    assert state_id(node) == State.PRIMARY_STATE_FINALIZED and node.driver is None
    assert stopped_last(heard(device)) and not streaming(device)


def test_two_managers_configuring_at_once_get_one_success_and_one_refusal(
        executor, ros_context, device):
    node = make_node(ros_context, serial_port=device.link, autostart=False)
    executor.add_node(node)
    answers = change_state(executor, ros_context, Transition.TRANSITION_CONFIGURE,
                           Transition.TRANSITION_CONFIGURE)
    assert answers == [True, False]
    assert state_id(node) == State.PRIMARY_STATE_INACTIVE and node.driver is not None
    answers = change_state(executor, ros_context, Transition.TRANSITION_ACTIVATE,
                           Transition.TRANSITION_ACTIVATE, Transition.TRANSITION_DEACTIVATE)
    assert answers == [True, False, True]
    assert state_id(node) == State.PRIMARY_STATE_INACTIVE


def test_configure_without_a_device_fails_naming_the_cause(ros_context, tmp_path, capfd):
    node = make_node(ros_context, serial_port=str(tmp_path / 'absent'), autostart=False,
                     configure_timeout=0.5)
    started = time.monotonic()
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert time.monotonic() - started < 2.0
    assert state_id(node) == State.PRIMARY_STATE_UNCONFIGURED and node.driver is None
    lines = [line for line in capfd.readouterr().err.splitlines() if 'configure failed' in line]
    assert len(lines) == 1 and 'no such device' in lines[0]
    node.destroy_node()


def test_autostart_scans_at_once_and_motor_services_need_the_active_state(
        executor, ros_context, device, capfd):
    node = make_node(ros_context, serial_port=device.link)
    executor.add_node(node)
    scans = scan_counter(ros_context, executor)
    assert state_id(node) == State.PRIMARY_STATE_ACTIVE
    assert spin_until(executor, lambda: len(scans) >= 1, 5.0)
    assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    node._start_motor(None, None)
    assert 'start_motor: ignored while the node is not active' in capfd.readouterr().err
    spin_until(executor, lambda: False, 0.5)
    assert not streaming(device)


def test_a_lost_port_that_comes_back_gets_the_stale_scan_stopped_first(
        executor, ros_context, device):
    # The adapter drops off the bus while the device, powered on its own, streams on.
    node = make_node(ros_context, serial_port=device.link)
    executor.add_node(node)
    scans = scan_counter(ros_context, executor)
    assert spin_until(executor, lambda: len(scans) >= 1, 5.0)
    heard(device)
    assert device.command('hangup').startswith('hung up')
    count = len(scans)
    assert spin_until(executor, lambda: len(scans) > count + 1, 5.0)
    # On the new terminal, the first request stops the scan the device kept streaming.
    requests = heard(device)
    assert requests[0] == 'STOP' and 'EXPRESS_SCAN=0x0100000000' in requests, requests
    assert requests.index('STOP') < requests.index('GET_INFO'), requests
    executor.remove_node(node)
    node.destroy_node()
    assert stopped_last(heard(device)) and not streaming(device)


def test_destroying_the_node_while_it_waits_to_reconnect_stops_the_motor(
        executor, ros_context, device):
    # A stream of garbage ends session after session; between them the driver backs off, for
    # up to 2 s. The motor the last session started is stopped all the same.
    node = make_node(ros_context, serial_port=device.link, data_timeout=0.3)
    executor.add_node(node)
    assert wait_for(lambda: streaming(device), 20.0)
    assert device.command('corrupt 1.0').startswith('corrupt rate')

    # Five failed sessions: the back-off after the next one is 1.6 s. A session's failure is
    # counted as it ends, just before its back-off: the close lands there, not in a handshake.
    assert wait_for(lambda: node.driver.status().reconnects >= 5, 30.0)
    failed = node.driver.status().reconnects
    assert wait_for(lambda: node.driver.status().reconnects > failed, 30.0)
    assert node.driver.status().state == DriverState.CONNECTING
    heard(device)
    executor.remove_node(node)
    node.destroy_node()
    requests = heard(device)
    assert 'MOTOR_SPEED=0' in requests and 'STOP' in requests, requests


def node_process(link, *command):
    """Start the installed rplidar_node (or ``command``) on the emulator's link."""
    arguments = list(command) or [str(NODE_EXECUTABLE)]
    return subprocess.Popen([*arguments, '--ros-args', '-p', f'serial_port:={link}'],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, 'PYTHONUNBUFFERED': '1'})


@pytest.mark.parametrize('signal_number', [signal.SIGINT, signal.SIGTERM],
                         ids=['SIGINT', 'SIGTERM'])
def test_a_signal_stops_the_motor_before_the_process_ends(device, signal_number):
    process = node_process(device.link)
    try:
        assert wait_for(lambda: streaming(device), 20.0)
        heard(device)
        time.sleep(0.3)
        process.send_signal(signal_number)
        output, _ = process.communicate(timeout=10.0)
    finally:
        process.kill()
    assert process.returncode == 0, output
    assert 'Traceback' not in output, output
    requests = heard(device)
    assert stopped_last(requests), requests
    assert not streaming(device)


# A node whose own code raises once it scans: the exception leaves the executor and main().
RAISING_NODE = """
import sys
from wctls_rplidar import rplidar_node


class FailingNode(rplidar_node.RplidarNode):

    def __init__(self):
        super().__init__()
        self.create_timer(0.1, self.fail)

    def fail(self):
        if self.driver.status().turns >= 3:
            raise RuntimeError('a bug in the node')


rplidar_node.RplidarNode = FailingNode
sys.exit(rplidar_node.main())
"""


def test_an_exception_in_the_node_stops_the_motor(device):
    process = node_process(device.link, sys.executable, '-c', RAISING_NODE)
    try:
        output, _ = process.communicate(timeout=30.0)
    finally:
        process.kill()
    assert process.returncode != 0 and 'RuntimeError: a bug in the node' in output, output
    requests = heard(device)
    assert 'EXPRESS_SCAN=0x0100000000' in requests and stopped_last(requests), requests
    assert not streaming(device)


def test_an_unknown_orientation_ends_the_node_in_one_line():
    process = subprocess.run([str(NODE_EXECUTABLE), '--ros-args', '-p', 'orientation:=ned'],
                             capture_output=True, text=True, timeout=30)
    assert process.returncode == 1
    lines = [line for line in process.stderr.splitlines() if 'orientation' in line]
    assert len(lines) == 1 and "must be one of ('sllidar', 'rep103')" in lines[0], (
        process.stderr)
    assert 'Traceback' not in process.stderr
