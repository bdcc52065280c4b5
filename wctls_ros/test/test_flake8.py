# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Lint the Python of both packages as ament_flake8 does in a ROS build farm."""

import pathlib

import pytest

PACKAGE_DIR = pathlib.Path(__file__).resolve().parents[1]
# The interface package's tests sit beside this package in the source tree.
LINTED = [str(PACKAGE_DIR)] + [str(p) for p in [PACKAGE_DIR.parent / 'wctls_msgs'] if p.is_dir()]
# One of the suite's slowest modules: make test-fast leaves it out (make lint runs it).
pytestmark = pytest.mark.slow


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    main_with_errors = pytest.importorskip('ament_flake8.main').main_with_errors
    rc, errors = main_with_errors(argv=LINTED)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
