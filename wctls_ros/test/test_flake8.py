# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Lint the Python of every package as ament_flake8 does in a ROS build farm."""

import pathlib

import pytest

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
# The four packages sit side by side in the source tree.
LINTED = [str(REPOSITORY / path) for path in
          ('wctls_ros', 'wctls_rplidar', 'wctls_lab', 'wctls_msgs', 'conftest.py')]
# One of the suite's slowest modules: make test-fast leaves it out (make lint runs it).
pytestmark = pytest.mark.slow


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    main_with_errors = pytest.importorskip('ament_flake8.main').main_with_errors
    rc, errors = main_with_errors(argv=LINTED)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
