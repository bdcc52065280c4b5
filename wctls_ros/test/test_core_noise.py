# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The range noise a scan shows of itself, against the simulator's and calibrate's."""

import math

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_lab.evaluation import fit_noise, load_scans
from wctls_lab.simulation import (full_turn_bearings, load_floor_plan, NoiseModel,
                                  simulate_scan)
from wctls_ros.core import extract_features, FeatureConfig, scan_to_points
from wctls_ros.core.numba_core.noise import scan_range_sigma


def estimates(plan, noise, scans=20):
    angle_min, increment, bearings = full_turn_bearings(1080)
    floor_plan = load_floor_plan(plan)
    rng = np.random.default_rng(3)
    return np.array([scan_range_sigma(scan_to_points(
        simulate_scan(floor_plan.scene(), bearings, noise, rng), angle_min, increment))
        for _ in range(scans)])


@pytest.mark.parametrize('plan', ['environment_a', 'environment_b_cluttered'])
@pytest.mark.parametrize('sigma_m', [0.005, 0.01, 0.03])
def test_the_estimate_is_the_simulated_range_noise_despite_edges_and_clutter(plan, sigma_m):
    # Ranges only: no bearing noise, which a range estimate would count at oblique walls.
    found = estimates(plan, NoiseModel(range_sigma_m=sigma_m, bearing_sigma_rad=0.0))
    assert np.median(found) == pytest.approx(sigma_m, rel=0.05)
    assert np.std(found) < 0.1 * sigma_m                    # one scan is enough


def test_mixed_pixels_and_bins_raise_the_estimate_only_a_little():
    # The S1-like sensor: 2 cm, 1/3 deg bins, 0.4 deg footprints (mixed pixels), dropouts.
    from wctls_lab.simulation import SENSOR_MODELS
    found = estimates('environment_a_cluttered', SENSOR_MODELS['s1_like'])
    assert 0.02 < np.median(found) < 0.025


def test_too_few_neighbours_estimate_nothing():
    ranges = np.full(100, np.inf)
    ranges[::3] = 2.0                                       # no three neighbours in a row
    assert scan_range_sigma(scan_to_points(ranges, 0.0, 0.01)) == 0.0


@pytest.mark.parametrize('name', ['sick_lms111_static', 'sick_lms1xx_static'])
def test_real_sick_scans_show_what_calibrate_fits_over_many_scans(name):
    scans = load_scans(REAL_DATA / name)
    fitted = fit_noise(scans).noise.range_sigma_m                 # 7.8 and 8.8 mm
    found = [scan_range_sigma(scan_to_points(ranges, scans.angle_min, scans.angle_increment,
                                             scans.range_min, scans.range_max))
             for ranges in scans.ranges]
    assert np.median(found) == pytest.approx(fitted, rel=0.15)    # 8.5 and 9.1 mm


def test_the_pipeline_uses_the_larger_of_the_floor_and_the_estimate():
    angle_min, increment, bearings = full_turn_bearings(1080)
    noise = NoiseModel(range_sigma_m=0.03, bearing_sigma_rad=0.0)
    ranges = simulate_scan(load_floor_plan('environment_a').scene(), bearings, noise,
                           np.random.default_rng(0))
    estimate = scan_range_sigma(scan_to_points(ranges, angle_min, increment))

    def corner_sigma(config):
        corners = extract_features(ranges, angle_min, increment, config).corners
        return float(np.median(np.sqrt(corners.covariance[:, 0, 0])))

    def scan_with(sigma, from_scan):
        return FeatureConfig(range_sigma_m=sigma, range_sigma_from_scan=from_scan,
                             bearing_sigma_rad=0.0, residual_scaling=False)

    assert corner_sigma(scan_with(0.005, True)) == corner_sigma(scan_with(estimate, False))
    assert corner_sigma(scan_with(0.05, True)) == corner_sigma(scan_with(0.05, False))
    assert math.isclose(estimate, 0.03, rel_tol=0.1)
