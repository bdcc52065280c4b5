# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The model-error term: clean walls stay calibrated, rough and bowed walls become so.

Monte Carlo against the simulator's truth: a room corner 2.2 m away seen in 300 scans; the
mean NEES of the corner's position against the true corner is 2 for a calibrated estimate.
"""

import math

import numpy as np
import pytest
from wctls_lab.simulation import floor_plan_from_dict, NoiseModel, simulate_recording
from wctls_ros.core import extract_features, FeatureConfig, nees
from wctls_ros.core.numba_core.model_error import flatness_covariance

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

NOISE = NoiseModel(range_sigma_m=0.005, bearing_sigma_rad=math.radians(0.05))
CONFIG = FeatureConfig(range_sigma_m=0.005, bearing_sigma_rad=math.radians(0.05))
CORNER = np.array([2.0, 1.0])


def corner_nees(surfaces=(), config=CONFIG, scans=600):
    """
    Return the mean NEES of the corner (2, 1) against the truth, and how often it was found.

    :param surfaces: one surface list per group of scans (a wall drawn anew), or none
    """
    groups = [list(s) for s in surfaces] or [[]]
    values, count = [], 0
    for group, surface in enumerate(groups):
        plan = {'name': 'corner', 'sensor': {'x': 0.0, 'y': 0.0, 'yaw_deg': 0.0},
                'polylines': [{'closed': False,
                               'points': [[2.0, -1.2], [2.0, 1.0], [0.2, 1.0]]}],
                'surfaces': surface}
        recording = simulate_recording(floor_plan_from_dict(plan), NOISE, scans // len(groups),
                                       seed=4 + group)
        for ranges in recording.ranges:
            count += 1
            corners = extract_features(ranges, recording.angle_min,
                                       recording.angle_increment, config).corners
            near = np.hypot(*(corners.xy_m - CORNER).T) < 0.05 if len(corners) else []
            if np.any(near):
                k = int(np.argmax(near))
                values.append(float(nees(corners.xy_m[k] - CORNER,
                                         corners.covariance[k, :2, :2])))
    return float(np.mean(values)), len(values) / count


@pytest.mark.parametrize('method', ['utls', 'wtls', 'wctls', 'ml'])
def test_clean_walls_stay_calibrated_with_the_model_error_term_on(method):
    config = CONFIG.replace(method=method)
    assert config.residual_scaling
    mean_nees, found = corner_nees(config=config)
    assert found == 1.0
    assert 1.8 <= mean_nees <= 2.2


@pytest.mark.parametrize('method', ['utls', 'wtls', 'wctls', 'ml'])
def test_rough_walls_become_calibrated_by_the_residual_factor(method):
    # Plaster rough by 1 cm (correlation length 1 cm, about the returns' spacing) against 5 mm
    # of range noise: the returns scatter five times the modelled variance about the line. A
    # profile is the same in every scan, so 12 walls, each rough in its own way.
    rough = [[{'from': [2.0, -1.2], 'to': [2.0, 1.0], 'roughness_m': 0.01,
               'roughness_length_m': 0.01, 'seed': seed}] for seed in range(12)]
    config = CONFIG.replace(method=method)
    without, _ = corner_nees(rough, config.replace(residual_scaling=False))
    with_term, found = corner_nees(rough, config)
    assert found > 0.85
    assert without > 4.0
    assert 1.7 <= with_term <= 2.5


@pytest.mark.parametrize('method', ['utls', 'wtls', 'wctls', 'ml'])
def test_a_bow_the_noise_hides_needs_the_flatness_prior(method):
    # 12 rooms whose two walls are bowed by sagittas drawn with a 6 mm std: an unweighted fit
    # passes 2/3 of it off the corner (a 4 mm std). The returns scatter no more than the
    # noise, so the residual factor cannot see it; a flatness prior of that size brings the
    # NEES from 30-40 to 1.8 (WTLS, WCTLS), 1.2 (UTLS) and 0.9 (ML): WTLS weights the near
    # middle of a wall, where a bow is deepest, and so is moved most by it.
    rng = np.random.default_rng(1)
    bowed = [[{'from': [2.0, -1.2], 'to': [2.0, 1.0], 'bow_m': float(first)},
              {'from': [2.0, 1.0], 'to': [0.2, 1.0], 'bow_m': float(second)}]
             for first, second in rng.normal(0.0, 0.006, (12, 2))]
    config = CONFIG.replace(method=method)
    without, _ = corner_nees(bowed, config)
    with_prior, found = corner_nees(bowed, config.replace(wall_flatness_sigma_m=0.004))
    assert found > 0.95
    assert without > 20.0
    assert 0.8 <= with_prior <= 2.5


def test_the_flatness_covariance_is_that_of_independent_end_offsets():
    # Monte Carlo of the line through two ends displaced across it by N(0, sigma^2) each.
    rng = np.random.default_rng(0)
    start, end, sigma = np.array([2.0, -1.0]), np.array([2.5, 1.5]), 0.01
    direction = (end - start) / np.hypot(*(end - start))
    normal = np.array([direction[1], -direction[0]])
    if normal @ start < 0:
        normal = -normal
    draws = rng.normal(0.0, sigma, (200000, 2))
    moved_start = start + draws[:, :1] * normal
    moved_end = end + draws[:, 1:] * normal
    tangent = moved_end - moved_start
    angle = np.arctan2(tangent[:, 0], -tangent[:, 1])             # the normal's angle
    angle = np.where(np.cos(angle - math.atan2(*normal[::-1])) < 0, angle + np.pi, angle)
    radius = moved_start[:, 0] * np.cos(angle) + moved_start[:, 1] * np.sin(angle)
    sample = np.cov(np.stack([np.angle(np.exp(1j * angle)), radius]))
    predicted = flatness_covariance(np.array([math.atan2(*normal[::-1])]), start[None],
                                    end[None], sigma)[0]
    np.testing.assert_allclose(sample, predicted, rtol=0.02, atol=1e-9)
