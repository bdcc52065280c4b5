# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Nothing published that says "unknown": the plausibility bounds of both pipelines.

A wall interleaved with random short returns made the default preset's per-scan noise estimate
0.4-1.5 m; walls were then fitted through the noise and corners published with position stds
of metres, which a gate built on them cannot reject.
"""

from dataclasses import replace
import math

import numpy as np
import pytest
from wctls_lab.simulation import load_floor_plan, NoiseModel, simulate_recording
from wctls_ros.core import FeatureConfig
from wctls_ros.core.numba_core.pipeline import extract_features as compiled
from wctls_ros.core.numpy_core.pipeline import extract_features as in_numpy
from wctls_ros.core.plausibility import (corner_sigma_m, kept, MAX_SIGMA_RATIO, plausible,
                                         segment_sigma_m)
from wctls_ros.core.records import CornerArrays, SegmentArrays

PIPELINES = pytest.mark.parametrize('extract', [compiled, in_numpy], ids=['compiled', 'numpy'])
# The generic preset's noise model.
GENERIC = FeatureConfig(range_sigma_m=0.002, range_sigma_from_scan=True,
                        bearing_sigma_rad=math.radians(0.1), common_range_sigma_m=0.001,
                        model_error_sigma_m=0.01, wall_flatness_sigma_m=0.005)


def _room_scan(seed=1):
    recording = simulate_recording(load_floor_plan('environment_a'),
                                   NoiseModel(range_sigma_m=0.01, bearing_sigma_rad=0.0), 1,
                                   seed=seed)
    return recording.ranges[0], recording.angle_min, recording.angle_increment


def _garbage_scan():
    """Return a room scan with every other return replaced by a random short echo."""
    ranges, angle_min, increment = _room_scan()
    garbage = ranges.copy()
    garbage[::2] = np.random.default_rng(5).uniform(0.2, 1.0, garbage[::2].size)
    return garbage, angle_min, increment


@PIPELINES
def test_a_garbage_scan_gives_nothing_and_says_why(extract):
    features = extract(*_garbage_scan(), GENERIC)
    assert features.noise_implausible
    assert features.range_sigma_m > GENERIC.max_range_sigma_m
    assert len(features.segments) == 0 and len(features.corners) == 0
    # Without the bound, what it would publish: features the noise estimate makes useless.
    unbounded = extract(*_garbage_scan(), replace(GENERIC, max_range_sigma_m=100.0))
    assert not unbounded.noise_implausible
    assert len(unbounded.segments) > 0 and np.max(segment_sigma_m(unbounded.segments)) > 1.0


@PIPELINES
def test_a_clean_scan_keeps_every_feature_and_reports_its_noise(extract):
    features = extract(*_room_scan(), GENERIC)
    assert not features.noise_implausible and features.implausible_features == 0
    assert features.range_sigma_m == pytest.approx(0.01, rel=0.15)      # the simulated 1 cm
    assert len(features.corners) >= 12


def _beyond_the_bound(features):
    """Return the features with a cornered wall's and one corner's covariance inflated 1e8x."""
    walls = features.segments
    doomed = int(features.corners.first_segment[len(features.corners) // 2])
    covariance, corner_covariance = walls.covariance.copy(), features.corners.covariance.copy()
    covariance[doomed] *= 1e8
    corner_covariance[-1, :2, :2] *= 1e8
    return replace(features, segments=replace(walls, covariance=covariance),
                   corners=replace(features.corners, covariance=corner_covariance))


def test_the_compiled_bounds_keep_what_the_numpy_ones_keep():
    pipeline = pytest.importorskip('wctls_ros.core.numba_core.pipeline')
    plausibility = pytest.importorskip('wctls_ros.core.numba_core.plausibility')
    features = in_numpy(*_room_scan(), GENERIC)
    for case in (features, _beyond_the_bound(features)):
        expected = plausible(case, GENERIC, features.range_sigma_m)
        keep_segment, keep_corner = plausibility.plausible(
            SegmentArrays(**vars(case.segments)), CornerArrays(**vars(case.corners)),
            features.range_sigma_m, pipeline._settings(GENERIC))
        if keep_segment is None:                # all pass
            assert keep_corner is None and expected.implausible_features == 0
            continue
        found = kept(case, keep_segment, keep_corner)
        assert found.implausible_features == expected.implausible_features
        for group in ('segments', 'corners'):
            for name, wanted in vars(getattr(expected, group)).items():
                assert np.array_equal(getattr(getattr(found, group), name), wanted), name
    assert expected.implausible_features >= 2


def test_a_feature_beyond_the_bound_is_dropped_and_the_corners_renumbered():
    config = GENERIC
    features = in_numpy(*_room_scan(), config)
    walls = features.segments
    used = features.corners.first_segment
    doomed = int(used[len(used) // 2])                  # a wall with a corner on it
    covariance = walls.covariance.copy()
    covariance[doomed] *= 1e8                           # a std 10^4 times as large
    inflated = replace(features, segments=replace(walls, covariance=covariance))
    kept = plausible(inflated, config, features.range_sigma_m)
    assert len(kept.segments) == len(walls) - 1
    losing = ((features.corners.first_segment == doomed)
              | (features.corners.second_segment == doomed))
    assert kept.implausible_features == 1 + np.count_nonzero(losing)
    # Each remaining corner still names its own two walls (same lines as before).
    survivors = features.corners.select(~losing)
    assert np.allclose(kept.segments.angle_rad[kept.corners.first_segment],
                       walls.angle_rad[survivors.first_segment])
    assert np.allclose(kept.segments.angle_rad[kept.corners.second_segment],
                       walls.angle_rad[survivors.second_segment])
    # A corner of its own with a huge covariance goes too, its walls stay.
    corner_covariance = features.corners.covariance.copy()
    corner_covariance[0, :2, :2] *= (2.0 * MAX_SIGMA_RATIO) ** 2 * 1e4
    one_bad_corner = replace(features, corners=replace(features.corners,
                                                       covariance=corner_covariance))
    kept = plausible(one_bad_corner, config, features.range_sigma_m)
    assert len(kept.segments) == len(walls)
    assert len(kept.corners) == len(features.corners) - 1
    assert np.all(corner_sigma_m(kept.corners) < 1.0)


def test_a_fixed_range_noise_beyond_the_bound_is_refused():
    with pytest.raises(ValueError, match='must not exceed max_range_sigma_m'):
        FeatureConfig(range_sigma_m=0.2, max_range_sigma_m=0.1)
