# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The stock-install run's own checks: noble's libraries, no optional package, and what then runs.

Collected only by `make test`'s stock-install run (the venv of requirements/stock.txt, named by
WCTLS_VENV): the name keeps the main run from collecting it, where numba and rosbags exist.
"""

import importlib
import importlib.util
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from test_feature_node import installed_executable
from wctls_ros.core import extract_features, start, status

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]


def stock_pins() -> dict:
    return dict(line.split('==') for line in
                (REPOSITORY / 'requirements' / 'stock.txt').read_text().splitlines()
                if '==' in line and not line.startswith('#'))


@pytest.mark.parametrize('module', ['numba', 'rosbags', 'matplotlib', 'tqdm'])
def test_no_optional_package_is_installed(module):
    assert importlib.util.find_spec(module) is None


@pytest.mark.parametrize('module, requirement', [('numpy', 'numpy'), ('yaml', 'PyYAML'),
                                                 ('serial', 'pyserial')])
def test_a_node_s_libraries_are_at_noble_s_versions(module, requirement):
    assert importlib.import_module(module).__version__ == stock_pins()[requirement]


def test_the_numpy_core_serves_and_says_why():
    chosen = start()
    beams = 360
    bearing = -math.pi + 2 * math.pi / beams * np.arange(beams)
    ranges = 2.0 / np.maximum(np.abs(np.cos(bearing)), np.abs(np.sin(bearing)))
    assert len(extract_features(ranges, -math.pi, 2 * math.pi / beams).corners) == 4
    assert status().name == 'numpy' and chosen.reason == 'numba is not installed'


def test_feature_node_needs_nothing_optional():
    code = ('import sys; import wctls_ros.feature_node, wctls_rplidar.rplidar_node, '
            'wctls_rplidar.emulator.cli; '
            "print(sorted(m for m in ('rosbags', 'matplotlib', 'tqdm', 'numba') "
            'if m in sys.modules))')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.strip() == '[]'


@pytest.mark.parametrize('tool, arguments', [
    ('process_bag', ['{data}/urg04lx_office', '-d', '{out}']),
    ('score', ['{data}/sick_lms1xx_static']),
    ('evaluate', ['{data}/sick_lms1xx_static', '--out', '{out}/evaluation']),
    ('calibrate', ['{data}/sick_lms1xx_static']), ('simulate', ['environment_a', '{out}/sim']),
    ('bag_replay', ['--ros-args', '-p', 'bag:={data}/urg04lx_office']),
    ('demo', ['--seconds', '2', '--out', '{out}/demo'])])
def test_a_bag_tool_without_rosbags_says_how_to_install_it_in_one_line(tool, arguments,
                                                                       tmp_path):
    command = [str(installed_executable(tool))] + [
        argument.format(data=REPOSITORY / 'data', out=tmp_path) for argument in arguments]
    result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert result.stderr.strip() == (
        f'{tool}: error: rosbags is not installed: it gives reading and writing bags '
        '(process_bag, bag_replay, simulate, score, evaluate, calibrate, demo) and '
        "feature_node's faster message path (pip install rosbags)")
    assert not list(tmp_path.iterdir())             # nothing written
