# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Type-check the core, the message codec, the parameter schemas and the emulator's room."""

import pathlib

import pytest

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
CHECKED = [f'wctls_ros/wctls_ros/{path}'
           for path in ('core', 'conversions.py', 'frontend', 'odometry_messages.py', 'params.py',
                        'plain_yaml.py')] + [
    'wctls_rplidar/wctls_rplidar/parameters.py', 'wctls_rplidar/wctls_rplidar/emulator/room.py']


@pytest.mark.linter
def test_mypy():
    api = pytest.importorskip('mypy.api')
    report, errors, status = api.run(
        ['--ignore-missing-imports', '--follow-imports=silent', '--no-error-summary',
         '--cache-dir=/dev/null'] + [str(REPOSITORY / path) for path in CHECKED])
    assert status == 0, report + errors
