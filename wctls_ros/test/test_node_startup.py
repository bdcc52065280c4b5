# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Nodes refuse bad ROS arguments with one fatal line and exit 1; Ctrl-C ends them cleanly."""

import importlib.util
import os
import signal
import subprocess
import sys
import threading
import time

from conftest import spin_until
import pytest

rclpy = pytest.importorskip('rclpy')

from test_feature_node import installed_executable  # noqa: E402

# One of the suite's slowest modules (make test-fast leaves it out), and one that runs
# nodes, emulators or signals against deadlines (make test runs it in its realtime group).
pytestmark = [pytest.mark.slow, pytest.mark.realtime]


@pytest.mark.parametrize('arguments,reason', [
    (['--params-file', '/nonexistent/feature_node.yaml'],
     "Couldn't parse params file: '--params-file /nonexistent/feature_node.yaml'"),
    (['--params-file', 'BROKEN'], "Couldn't parse params file"),
    # rcl opened a FIFO and waited for a writer forever.
    (['--params-file', 'FIFO'], 'fifo.yaml is not a regular file'),
    (['-r', '__node:=bad-name'], "Couldn't parse remap rule: '-r __node:=bad-name'"),
    (['--no-such-option'], "unknown ROS arguments ['--no-such-option']"),
])
@pytest.mark.parametrize('node', ['feature_node', pytest.param('bag_replay', marks=[
    pytest.mark.skipif(importlib.util.find_spec('rosbags') is None,
                       reason='bag_replay reads bags with rosbags (a stock install has none)')])])
def test_bad_ros_arguments_give_one_fatal_line_and_exit_1(node, arguments, reason, tmp_path):
    broken = tmp_path / 'broken.yaml'
    broken.write_text('feature_node:\n  ros__parameters: [\n')
    os.mkfifo(tmp_path / 'fifo.yaml')
    arguments = [{'BROKEN': str(broken), 'FIFO': str(tmp_path / 'fifo.yaml')}.get(a, a)
                 for a in arguments]
    result = subprocess.run([str(installed_executable(node)), '--ros-args'] + arguments,
                            capture_output=True, text=True, timeout=30)
    lines = (result.stdout + result.stderr).splitlines()
    assert result.returncode == 1 and len(lines) == 1, lines
    assert '[FATAL]' in lines[0] and f'[{node}]: cannot start: ' in lines[0]
    assert reason in lines[0] and ', at /' not in lines[0]


def wait_until_spinning(executor, reports, process, name, timeout_s=180.0):
    """
    Return once the node ``name`` published diagnostics: its executor spins its 1 Hz timer.

    :param executor: the test's executor, spinning a listener that puts status names in
        ``reports``
    :param reports: the names of the diagnostic statuses received so far
    :param process: the node's process; its end before the first report fails the test
    :param name: the node's name (its status names contain it)
    :param timeout_s: deadline, s: generous, as with a cold numba cache the node compiles its
        core first (10-30 s, minutes on a busy machine)
    """
    spin_until(executor, lambda: process.poll() is not None
               or any(name in report for report in reports), timeout_s)
    assert any(name in report for report in reports), (
        f'{name} published no diagnostics within {timeout_s} s (status {process.poll()})')


@pytest.mark.parametrize('node', ['feature_node', 'rplidar_node'])
def test_a_second_ctrl_c_during_the_clean_up_ends_the_node_cleanly(node, ros_context, executor):
    # ros2 launch forwards the terminal's Ctrl-C once more: before the fix, a second SIGINT a
    # few ms after the first gave a KeyboardInterrupt traceback or status -2 in 10 of 24 runs
    # of feature_node (delays 0-50 ms).
    from diagnostic_msgs.msg import DiagnosticArray
    listener = rclpy.create_node('diagnostics_listener', context=ros_context)
    executor.add_node(listener)
    reports = []
    listener.create_subscription(DiagnosticArray, '/diagnostics', lambda array: reports.extend(
        status.name for status in array.status), 10)
    for run, delay_s in enumerate((0.0, 0.002, 0.005, 0.01, 0.05)):
        # A name of its own per run: a late report of the run before cannot pass for this one.
        name = f'{node}_{run}'
        process = subprocess.Popen([str(installed_executable(node)), '--ros-args', '-r',
                                    f'__node:={name}'], stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True)
        try:
            wait_until_spinning(executor, reports, process, name)
        finally:
            process.send_signal(signal.SIGINT)
            time.sleep(delay_s)
            process.send_signal(signal.SIGINT)
            _, errors = process.communicate(timeout=30)
        assert (process.returncode, 'Traceback' in errors) == (0, False), (delay_s, errors)


# A node being built when Ctrl-C comes: rclpy's handler shuts the context down at once (C code),
# so the constructor fails with an RCLError, and Python runs the package's handler a few
# bytecodes later, while run_node handles that error. A profile hook sends the SIGINT at the
# moment that handler asks rclpy.ok(), the moment it hit by chance on loaded machines (a
# KeyboardInterrupt traceback, status -2).
_CTRL_C_WHILE_A_FAILED_START_IS_HANDLED = """
import os
import signal
import sys
import threading

import rclpy
import rclpy.utilities

from wctls_ros.node_main import run_node


def sigint_when_rclpy_ok_is_asked(frame, event, argument):
    if event == 'call' and frame.f_code is rclpy.utilities.ok.__code__:
        sys.setprofile(None)
        os.kill(os.getpid(), signal.SIGINT)


def half_built_node():
    rclpy.shutdown()                     # what rclpy's SIGINT handler does first
    sys.setprofile(sigint_when_rclpy_ok_is_asked)
    return rclpy.create_node('half_built')


sys.exit(run_node('half_built', half_built_node))
"""


# A Ctrl-C once the imports are done and before the node exists, as rclpy.init starts (before
# rclpy has a handler): it gave a KeyboardInterrupt traceback and status -2 in 1 of 60 random
# Ctrl-Cs during a start.
_CTRL_C_AS_A_START_UP_STEP_BEGINS = """
import os
import signal
import sys

from wctls_ros.feature_node import main

step, where = sys.argv[1:3]


def sigint_as_the_step_begins(frame, event, argument):
    code = frame.f_code
    if event == 'call' and code.co_name == step and code.co_filename.endswith(where):
        sys.setprofile(None)
        print(f'signalled in {where}:{step}', file=sys.stderr, flush=True)
        os.kill(os.getpid(), signal.SIGINT)


sys.setprofile(sigint_as_the_step_begins)
sys.argv = sys.argv[:1]
sys.exit(main())
"""


@pytest.mark.parametrize('step, where', [('init', 'rclpy/__init__.py')])
def test_ctrl_c_as_a_start_up_step_begins_ends_the_node_quietly(step, where):
    result = subprocess.run([sys.executable, '-c', _CTRL_C_AS_A_START_UP_STEP_BEGINS, step,
                             where], capture_output=True, text=True, timeout=60)
    assert result.stderr.splitlines()[0] == f'signalled in {where}:{step}', result.stderr
    assert (result.returncode, 'Traceback' in result.stderr) == (0, False), result.stderr


def test_ctrl_c_while_a_node_being_built_fails_ends_it_quietly():
    result = subprocess.run([sys.executable, '-c', _CTRL_C_WHILE_A_FAILED_START_IS_HANDLED],
                            capture_output=True, text=True, timeout=60)
    assert (result.returncode, 'Traceback' in result.stderr) == (0, False), result.stderr


def test_a_shutdown_that_wakes_no_one_still_ends_the_spin_at_once(ros_context):
    # What rclpy's signal thread does last: shut the context down in C, calling none of the
    # Python callbacks that would wake the executor. A node without timers then slept for ever.
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from wctls_ros.node_main import SHUTDOWN_CHECK_S, spin_forever
    node = rclpy.create_node('quiet', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    endings = []

    def spin():
        try:
            endings.append(spin_forever(executor, node))
        except ExternalShutdownException:        # run_node's clean end too
            endings.append('shutdown')

    spinning = threading.Thread(target=spin, daemon=True)
    spinning.start()
    time.sleep(0.3)
    assert spinning.is_alive()
    with ros_context.handle:
        ros_context.handle.shutdown()
    shut_down = time.monotonic()
    spinning.join(timeout=5.0)
    assert not spinning.is_alive() and endings in ([0], ['shutdown'])
    # A scheduling delay on a loaded machine aside, within one bounded wait.
    assert time.monotonic() - shut_down < SHUTDOWN_CHECK_S + 1.0
    node.destroy_node()
