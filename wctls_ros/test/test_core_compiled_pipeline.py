# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiled pipeline against the numpy one, scan by scan.

The numpy implementation (``core.numpy_core``) serves where numba is missing and is the plainer
reading of each rule: on every scan both must give the same segments and corners (identical beam
indices, counts, pairings and flags) and the same values within 1e-9 relative. Scans: simulated
furnished and cluttered rooms at 270 to 4320 beams and 0.5 mm to 5 cm of noise, partial fields of
view, hostile ones (NaN, inf, zeros, one ray, a crafted peeling wall), and every scan of every
real recording in data/; every method, and settings that switch each optional rule off or on.
"""

from dataclasses import replace
import math

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_lab.evaluation.scans import load_json_scans, load_scans
from wctls_lab.simulation import load_floor_plan, NoiseModel, simulate_recording
from wctls_lab.simulation.adversarial import peeling_wall
from wctls_ros.core import FeatureConfig, METHODS, numpy_core
# The compiled pipeline itself, whatever wctls_ros.core.runtime would choose.
from wctls_ros.core.numba_core.pipeline import extract_features

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

# Relative agreement of every value: |fast - reference| <= RELATIVE * scale, the scale being
# the largest magnitude of that quantity in the feature (a covariance's largest entry, the
# larger coordinate of a point), so that an entry near zero is not held to its own magnitude;
# for an angle (defined modulo 2 pi) at least pi.
RELATIVE = 1e-9
ANGLES = ('angle_rad', 'yaw_rad', 'opening_angle_rad')
SETTINGS = {
    'paper': {},
    'preset': {'range_sigma_m': 0.01, 'bearing_sigma_rad': math.radians(0.1),
               'range_sigma_from_scan': True},
    'every_term': {'range_sigma_m': 0.005, 'bearing_sigma_rad': math.radians(0.05),
                   'common_range_sigma_m': 0.002, 'wall_flatness_sigma_m': 0.003,
                   'iepf_noise_sigmas': 4.0},
    'rules_off': {'range_sigma_m': 0.01, 'bearing_sigma_rad': 0.0, 'residual_scaling': False,
                  'end_offset_sigmas': 0.0, 'merge_chi2': 0.0},
}


def simulated_scans():
    """Yield (name, ranges, angle_min, angle_increment) of simulated and hostile scans."""
    rng = np.random.default_rng(18)
    plans = ('environment_a', 'environment_b', 'environment_a_cluttered',
             'environment_b_cluttered')
    noises = (0.0005, 0.005, 0.01, 0.05)
    for case, (plan, beams) in enumerate(
            (plan, beams) for plan in plans for beams in (270, 1080, 4320)):
        noise = NoiseModel(range_sigma_m=noises[case % len(noises)],
                           bearing_sigma_rad=math.radians(0.05), dropout_probability=0.01)
        recording = simulate_recording(load_floor_plan(plan), noise, 6, seed=case,
                                       velocity=(0.3, -0.2, 0.4), beams=beams)
        for k, ranges in enumerate(recording.ranges):
            angle_min, increment = recording.angle_min, recording.angle_increment
            if k % 3 == 1:              # a partial field of view, from a random first beam
                first = int(rng.integers(0, beams // 2))
                ranges, angle_min = ranges[first:first + beams // 2], angle_min + first * increment
            if k % 3 == 2:              # hostile returns sprinkled in, beams reversed
                ranges = ranges[::-1].copy()
                angle_min, increment = angle_min + (beams - 1) * increment, -increment
                hit = rng.random(beams) < 0.05
                ranges[hit] = rng.choice([np.nan, np.inf, -np.inf, 0.0, 1e-9], hit.sum())
            yield f'{plan}-{beams}-{k}', ranges, angle_min, increment
    yield 'peeling-wall', *peeling_wall(4000)
    yield 'one-ray', np.full(360, 2.0), 0.3, 0.0 + 1e-12
    # lambda / step beyond the largest int64: a negative array size in the compiled breakpoints.
    yield 'one-ray-1e-20', np.full(360, 2.0), 0.3, 1e-20
    yield 'one-spot', np.concatenate([np.full(50, 1.0), np.full(310, np.nan)]), -math.pi, \
        2.0 * math.pi / 360


def real_scans():
    """Yield (name, ranges, angle_min, angle_increment, range_min, range_max) of data/."""
    recordings = [load_scans(REAL_DATA / name) for name in
                  ('sick_lms111_static', 'sick_lms1xx_static', 'urg04lx_office',
                   'sick_lms511_static', 'sick_tim781s_static', 'mrpt_malaga_moving',
                   'tuw_gh25_moving', 'rplidar_c1_single_scans', 'rplidar_barc_moving')]
    recordings.append(load_json_scans(REAL_DATA / 'lms111_building'))
    for recording in recordings:
        for k, ranges in enumerate(recording.ranges):
            yield (f'{recording.source}-{k}', ranges, recording.angle_min,
                   recording.angle_increment, recording.range_min, recording.range_max)


def assert_same(fast, reference, where):
    """Assert equal features (integers and flags exactly, values within RELATIVE), as declared."""
    assert fast.work_limited == reference.work_limited, where
    assert fast.noise_implausible == reference.noise_implausible, where
    assert fast.implausible_features == reference.implausible_features, where
    assert (math.isnan(fast.range_sigma_m) and math.isnan(reference.range_sigma_m)
            or abs(fast.range_sigma_m - reference.range_sigma_m)
            <= RELATIVE * reference.range_sigma_m), where
    for group in ('segments', 'corners'):
        ours, theirs = getattr(fast, group), getattr(reference, group)
        # Each field's dtype and row shape as its table declares, every value finite.
        assert not ours.problems() and not theirs.problems(), (where, group, ours.problems(),
                                                               theirs.problems())
        for name in theirs.__dataclass_fields__:
            a, b = getattr(ours, name), getattr(theirs, name)
            assert a.shape == b.shape, (where, group, name, a.shape, b.shape)
            if b.dtype.kind in 'biu':
                assert np.array_equal(a, b), (where, group, name)
                continue
            scale = np.abs(b.reshape(len(b), -1)).max(axis=1) if len(b) else np.zeros(0)
            if name in ANGLES:
                scale = np.maximum(scale, np.pi)
            error = np.abs(a - b).reshape(len(b), -1).max(axis=1) if len(b) else np.zeros(0)
            assert np.all(error <= RELATIVE * scale), (where, group, name,
                                                       float(np.max(error / scale)))


@pytest.mark.parametrize('settings', SETTINGS)
@pytest.mark.parametrize('method', METHODS)
def test_simulated_and_hostile_scans_give_the_reference_features(method, settings):
    config = FeatureConfig(method=method, **SETTINGS[settings])
    corners = 0
    for name, ranges, angle_min, increment in simulated_scans():
        with np.errstate(all='ignore'):
            fast = extract_features(ranges, angle_min, increment, config)
        reference = numpy_core.extract_features(ranges, angle_min, increment, config)
        assert_same(fast, reference, name)
        corners += len(reference.corners)
    assert corners > 200          # the scans are rooms with corners, not only empty results


@pytest.mark.parametrize('method', METHODS)
def test_every_real_scan_gives_the_reference_features(method):
    config = FeatureConfig(method=method, **SETTINGS['preset'])
    corners = 0
    for name, ranges, angle_min, increment, range_min, range_max in real_scans():
        fast = extract_features(ranges, angle_min, increment, config, range_min, range_max)
        reference = numpy_core.extract_features(ranges, angle_min, increment, config,
                                                range_min, range_max)
        assert_same(fast, reference, name)
        corners += len(reference.corners)
    assert corners > 1000


def test_the_comparison_sees_a_difference_of_a_billionth():
    ranges, angle_min, increment = next(iter(simulated_scans()))[1:]
    reference = numpy_core.extract_features(ranges, angle_min, increment, FeatureConfig())
    assert len(reference.corners)
    nudged = replace(reference.corners, xy_m=reference.corners.xy_m * (1.0 + 3.0 * RELATIVE))
    with pytest.raises(AssertionError):
        assert_same(replace(reference, corners=nudged), reference, 'nudged')
