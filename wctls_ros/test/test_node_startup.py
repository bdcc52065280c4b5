# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Nodes refuse bad ROS arguments at start-up with one fatal line and exit status 1."""

import subprocess

import pytest

pytest.importorskip('rclpy')

from test_feature_node import installed_executable  # noqa: E402


@pytest.mark.parametrize('arguments,reason', [
    (['--params-file', '/nonexistent/feature_node.yaml'],
     "Couldn't parse params file: '--params-file /nonexistent/feature_node.yaml'"),
    (['--params-file', 'BROKEN'], "Couldn't parse params file"),
    (['-r', '__node:=bad-name'], "Couldn't parse remap rule: '-r __node:=bad-name'"),
    (['--no-such-option'], "unknown ROS arguments ['--no-such-option']"),
])
@pytest.mark.parametrize('node', ['feature_node', 'bag_replay'])
def test_bad_ros_arguments_give_one_fatal_line_and_exit_1(node, arguments, reason, tmp_path):
    broken = tmp_path / 'broken.yaml'
    broken.write_text('feature_node:\n  ros__parameters: [\n')
    arguments = [str(broken) if a == 'BROKEN' else a for a in arguments]
    result = subprocess.run([str(installed_executable(node)), '--ros-args'] + arguments,
                            capture_output=True, text=True, timeout=30)
    lines = (result.stdout + result.stderr).splitlines()
    assert result.returncode == 1 and len(lines) == 1, lines
    assert '[FATAL]' in lines[0] and f'[{node}]: cannot start: ' in lines[0]
    assert reason in lines[0] and ', at /' not in lines[0]
