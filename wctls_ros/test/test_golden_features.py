# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Both pipelines give the recorded features of the test corpus (golden/, golden_features.py).

A rule change that moves a segment or a corner fails here, case by case and scan by scan; when
the move is meant, ``make golden`` re-records the files and ``git diff`` shows what moved.
"""

import json

from golden_features import cases, describe, GOLDEN
import pytest
from wctls_ros.core import numpy_core

# Printed values are rounded to 9 significant digits; the pipelines agree to about 1e-12.
RELATIVE = 1e-8
CASES = {name: case for name, *case in cases()}


def same_row(row: str, recorded: str) -> bool:
    """Return whether two printed rows agree: integers and flags exactly, numbers closely."""
    ours, theirs = row.split(), recorded.split()
    if len(ours) != len(theirs):
        return False
    for mine, golden in zip(ours, theirs):
        if mine.isdigit() or golden.isdigit():
            if mine != golden:
                return False
        elif abs(float(mine) - float(golden)) > RELATIVE * max(abs(float(golden)), 1e-6):
            return False
    return True


def extractor(implementation: str):
    """Return the extract_features of one pipeline (the compiled one skips without numba)."""
    if implementation == 'numpy':
        return numpy_core.extract_features
    return pytest.importorskip('wctls_ros.core.numba_core.pipeline').extract_features


@pytest.mark.parametrize('name', sorted(CASES))
@pytest.mark.parametrize('implementation', ['numpy', 'numba'])
def test_the_features_are_the_recorded_ones(name, implementation):
    extract = extractor(implementation)
    config, ranges, angle_min, increment, range_min, range_max = CASES[name]
    recorded = json.loads((GOLDEN / f'{name}.json').read_text())
    assert len(recorded) == len(ranges)
    for k, (scan, golden) in enumerate(zip(ranges, recorded)):
        found = describe(extract(scan, angle_min, increment, config, range_min, range_max))
        where = f'{name}, scan {k}'
        assert found['work_limited'] == golden['work_limited'], where
        for group in ('segments', 'corners'):
            assert len(found[group]) == len(golden[group]), (where, group, found[group],
                                                             golden[group])
            for row, expected in zip(found[group], golden[group]):
                assert same_row(row, expected), (where, group, row, expected)
