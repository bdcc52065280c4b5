# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
What the pipelines prepare once per configuration and beam layout, and the compiled call.

The compiled pipeline calls the version of its compiled function for its arguments' types
directly, looked up when a configuration is prepared, not through numba's dispatcher, which
types every argument of every call: so every scan's arguments must be of those types, whatever
array the caller hands in, and the version must be the one the dispatcher would have chosen.
"""

import math
from typing import NamedTuple

import numpy as np
import pytest
from wctls_ros.core import FeatureConfig
from wctls_ros.core.prepared import LatestPrepared
from wctls_ros.core.records import Settings
from wctls_ros.core.scan import scan_geometry

numba = pytest.importorskip('numba')
pipeline = pytest.importorskip('wctls_ros.core.numba_core.pipeline')

BEAMS = 720
ANGLE_MIN = -math.pi
INCREMENT = 2.0 * math.pi / BEAMS


def square_room(beams=BEAMS):
    """
    Return a full turn's ranges in a 4 m square room around the sensor, 5 mm of noise.

    float32 values, so that a float32 array of them holds the same ranges.
    """
    bearing = ANGLE_MIN + 2.0 * math.pi / beams * np.arange(beams)
    ranges = 2.0 / np.maximum(np.abs(np.cos(bearing)), np.abs(np.sin(bearing)))
    noisy = ranges + np.random.default_rng(3).normal(0.0, 0.005, beams)
    return noisy.astype(np.float32).astype(np.float64)


def ranges_of_every_kind(ranges):
    """Yield (kind, the same ranges in an array or sequence of that kind)."""
    yield 'list', ranges.tolist()
    yield 'float32', ranges.astype(np.float32)
    read_only = ranges.copy()
    read_only.flags.writeable = False
    yield 'read-only', read_only
    every_other = np.empty(2 * ranges.size)
    every_other[::2] = ranges
    yield 'strided', every_other[::2]
    yield 'reversed view', ranges[::-1].copy()[::-1]
    misaligned = np.frombuffer(bytearray(ranges.nbytes + 1), np.uint8)[1:].view(np.float64)
    misaligned[:] = ranges
    yield 'misaligned', misaligned


class Layout(NamedTuple):
    """A prepared record: nothing but what it was prepared for."""

    config: FeatureConfig
    angle_increment_rad: float
    beam_count: int


def test_a_record_is_prepared_again_only_when_the_config_object_or_the_layout_changes():
    made = []

    def prepare(*layout):
        made.append(layout)
        return Layout(*layout)

    latest = LatestPrepared(prepare)
    config, equal = FeatureConfig(), FeatureConfig()
    first = latest.get(config, 0.01, 360)
    assert latest.get(config, 0.01, 360) is first and len(made) == 1
    assert latest.get(config, 0.02, 360) is not first and len(made) == 2
    assert latest.get(config, 0.02, 720).beam_count == 720 and len(made) == 3
    assert latest.get(equal, 0.02, 720).config is equal and len(made) == 4


def test_the_ranges_are_of_one_numba_type_and_copied_only_when_they_are_not_of_it():
    ranges = square_room()
    wanted = numba.typeof(scan_geometry(ranges, ANGLE_MIN, INCREMENT)[0])
    assert scan_geometry(ranges, ANGLE_MIN, INCREMENT)[0] is ranges
    for kind, given in ranges_of_every_kind(ranges):
        found = scan_geometry(given, ANGLE_MIN, INCREMENT)[0]
        assert numba.typeof(found) == wanted, kind
        assert found is not given, kind
        np.testing.assert_array_equal(found, ranges, err_msg=kind)


def test_every_kind_of_ranges_gives_the_same_features_through_the_one_compiled_version():
    ranges = square_room()
    config = FeatureConfig(range_sigma_m=0.005, bearing_sigma_rad=0.0)
    reference = pipeline.extract_features(ranges, ANGLE_MIN, INCREMENT, config)
    assert len(reference.segments) == 4 and len(reference.corners) == 4
    versions = list(pipeline._features_of_scan.signatures)
    for kind, given in ranges_of_every_kind(ranges):
        found = pipeline.extract_features(given, ANGLE_MIN, INCREMENT, config)
        for table in ('segments', 'corners'):
            ours, theirs = getattr(found, table), getattr(reference, table)
            for name in theirs.__dataclass_fields__:
                np.testing.assert_array_equal(getattr(ours, name), getattr(theirs, name),
                                              err_msg=f'{kind}: {table}.{name}')
    assert list(pipeline._features_of_scan.signatures) == versions


def test_the_version_called_is_the_one_the_dispatcher_chooses_for_the_arguments():
    ranges, full_turn, cos, sin = scan_geometry(square_room(), ANGLE_MIN, INCREMENT)
    # Integers where the configuration has floats: records of the same types all the same.
    for config in (FeatureConfig(), FeatureConfig(iepf_noise_sigmas=3, corner_end_sigmas=4)):
        pipeline.extract_features(ranges, ANGLE_MIN, INCREMENT, config)
        prepared = pipeline._LATEST.prepared
        assert isinstance(prepared.settings, Settings)
        arguments = (ranges, cos, sin, ANGLE_MIN, prepared.angle_increment_rad, 0.0, math.inf,
                     full_turn, prepared.settings, prepared.density)
        types = tuple(numba.typeof(argument) for argument in arguments)
        assert prepared.compiled is pipeline._features_of_scan.overloads[types].entry_point
        assert len(pipeline._features_of_scan.signatures) == 1
        assert prepared.compiled(*arguments)[5] == pipeline._features_of_scan(*arguments)[5]


def test_a_stand_in_for_the_compiled_function_is_called_once_a_configuration_is_prepared(
        monkeypatch):
    ranges = square_room()
    config = FeatureConfig()
    expected = pipeline.extract_features(ranges, ANGLE_MIN, INCREMENT, config)
    calls = []
    compiled = pipeline._features_of_scan

    def stand_in(*arguments):
        calls.append(arguments)
        return compiled(*arguments)

    monkeypatch.setattr(pipeline, '_features_of_scan', stand_in)
    pipeline.extract_features(ranges, ANGLE_MIN, INCREMENT, config)
    assert calls == []                   # prepared before: the compiled version itself
    pipeline._LATEST.prepared = None
    found = pipeline.extract_features(ranges, ANGLE_MIN, INCREMENT, config)
    pipeline.extract_features(ranges, ANGLE_MIN, INCREMENT, config)
    assert len(calls) == 2
    np.testing.assert_array_equal(found.segments.line, expected.segments.line)
    pipeline._LATEST.prepared = None
