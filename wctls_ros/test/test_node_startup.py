# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Nodes refuse bad ROS arguments with one fatal line and exit 1; Ctrl-C ends them cleanly."""

import os
import signal
import subprocess
import time

import pytest

pytest.importorskip('rclpy')

from test_feature_node import installed_executable  # noqa: E402


@pytest.mark.parametrize('arguments,reason', [
    (['--params-file', '/nonexistent/feature_node.yaml'],
     "Couldn't parse params file: '--params-file /nonexistent/feature_node.yaml'"),
    (['--params-file', 'BROKEN'], "Couldn't parse params file"),
    # rcl opened a FIFO and waited for a writer forever.
    (['--params-file', 'FIFO'], 'fifo.yaml is not a regular file'),
    (['-r', '__node:=bad-name'], "Couldn't parse remap rule: '-r __node:=bad-name'"),
    (['--no-such-option'], "unknown ROS arguments ['--no-such-option']"),
])
@pytest.mark.parametrize('node', ['feature_node', 'bag_replay'])
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


@pytest.mark.parametrize('node', ['feature_node', 'rplidar_node'])
def test_a_second_ctrl_c_during_the_clean_up_ends_the_node_cleanly(node):
    # ros2 launch forwards the terminal's Ctrl-C once more: before the fix, a second SIGINT a
    # few ms after the first gave a KeyboardInterrupt traceback or status -2 in 10 of 24 runs
    # of feature_node (delays 0-50 ms).
    for delay_s in (0.0, 0.002, 0.005, 0.01, 0.05):
        process = subprocess.Popen([str(installed_executable(node))], stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True)
        time.sleep(1.5)                             # up and spinning
        process.send_signal(signal.SIGINT)
        time.sleep(delay_s)
        process.send_signal(signal.SIGINT)
        _, errors = process.communicate(timeout=30)
        assert (process.returncode, 'Traceback' in errors) == (0, False), (delay_s, errors)
