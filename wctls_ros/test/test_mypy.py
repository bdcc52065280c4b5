# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Type-check the core, the message codec and the parameter schema with mypy."""

import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / 'wctls_ros'
CHECKED = ['core', 'conversions.py', 'frontend', 'odometry_messages.py', 'params.py',
           'plain_yaml.py']


@pytest.mark.linter
def test_mypy():
    api = pytest.importorskip('mypy.api')
    report, errors, status = api.run(
        ['--ignore-missing-imports', '--follow-imports=silent', '--no-error-summary',
         '--cache-dir=/dev/null'] + [str(PACKAGE / path) for path in CHECKED])
    assert status == 0, report + errors
