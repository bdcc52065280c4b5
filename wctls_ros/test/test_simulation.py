# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The scan simulator: exact ray casting, the bundled plans and the noise model."""

import math

import numpy as np
import pytest
from wctls_ros.simulation import (cast_rays, floor_plan_from_dict, full_turn_bearings,
                                  load_floor_plan, NOISELESS, NoiseModel, simulate_ranges,
                                  simulate_recording, visible_corners)

SQUARE = {'name': 'square', 'polylines': [
    {'closed': True, 'points': [[-1.0, -2.0], [3.0, -2.0], [3.0, 2.0], [-1.0, 2.0]]}]}


def test_ray_casting_matches_the_analytic_distance_to_the_walls_of_a_box():
    walls, _ = floor_plan_from_dict(SQUARE).in_sensor_frame((0.0, 0.0, 0.0))
    bearings = np.linspace(-math.pi, math.pi, 721)
    ranges = cast_rays(walls, np.zeros(2), bearings)
    c, s = np.cos(bearings), np.sin(bearings)
    with np.errstate(divide='ignore'):
        expected = np.min(np.where(np.array([c, -c, s, -s]) > 1e-12,
                                   np.array([3.0, 1.0, 2.0, 2.0])[:, None]
                                   / np.abs(np.array([c, c, s, s])), np.inf), axis=0)
    np.testing.assert_allclose(ranges, expected, rtol=1e-12)


def test_a_ray_that_hits_nothing_is_infinite():
    wall = np.array([[1.0, -1.0, 1.0, 1.0]])
    assert cast_rays(wall, np.zeros(2), np.array([math.pi]))[0] == math.inf


def test_sensor_pose_moves_and_turns_the_scene():
    plan = floor_plan_from_dict(SQUARE)
    _, corners = plan.in_sensor_frame((3.0, 2.0, math.pi / 2))
    # The plan corner (-1, -2) is 4 m behind-left and 4 m below: in a sensor facing +y it lies
    # at x = -4 (behind), y = +4 (left).
    assert [-4.0, 4.0] in np.round(corners, 12).tolist()


@pytest.mark.parametrize('name', ['environment_a', 'environment_b'])
def test_bundled_plans_surround_the_sensor(name):
    plan = load_floor_plan(name)
    walls, corners = plan.in_sensor_frame()
    _, _, bearings = full_turn_bearings()
    ranges = simulate_ranges(walls, bearings, NOISELESS, np.random.default_rng(0))
    assert np.isfinite(ranges).all()
    assert len(corners) >= 12


def test_noise_has_the_documented_spread():
    wall = np.array([[2.0, -50.0, 2.0, 50.0]])
    bearings = np.zeros(20000)
    noise = NoiseModel(range_sigma_m=0.01, bearing_sigma_rad=0.0, range_sigma_per_m=0.005)
    ranges = simulate_ranges(wall, bearings, noise, np.random.default_rng(1))
    assert ranges.mean() == pytest.approx(2.0, abs=3e-4)
    assert ranges.std() == pytest.approx(math.hypot(0.01, 0.01), rel=0.03)


def test_dropouts_and_range_limits_give_infinity():
    wall = np.array([[2.0, -50.0, 2.0, 50.0]])
    noise = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0, dropout_probability=0.25)
    ranges = simulate_ranges(wall, np.zeros(4000), noise, np.random.default_rng(2))
    assert np.isinf(ranges).mean() == pytest.approx(0.25, abs=0.03)
    far = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0, max_range_m=1.5)
    assert np.isinf(simulate_ranges(wall, np.zeros(3), far, np.random.default_rng(3))).all()


def test_missing_plan_is_a_clear_error():
    with pytest.raises(FileNotFoundError, match='environment_a'):
        load_floor_plan('no_such_plan')


@pytest.mark.parametrize('name, visible', [('environment_a', 17), ('environment_b', 13)])
def test_bundled_plans_show_many_corners_with_both_walls(name, visible):
    walls, corners = load_floor_plan(name).in_sensor_frame()
    seen = visible_corners(walls, corners, full_turn_bearings()[2])
    assert seen.sum() == visible


def test_a_corner_behind_an_obstacle_or_with_one_wall_hidden_is_not_visible():
    walls, corners = floor_plan_from_dict(SQUARE).in_sensor_frame((0.0, 0.0, 0.0))
    bearings = full_turn_bearings()[2]
    assert visible_corners(walls, corners, bearings).all()
    blocker = np.array([[2.0, 1.2, 2.0, 2.5]])               # hides the corner (3, 2)
    hidden = visible_corners(np.vstack([walls, blocker]), corners, bearings)
    assert not hidden[np.all(np.isclose(corners, [3.0, 2.0]), axis=1)].any()
    assert hidden.sum() == 3


def test_a_recording_moves_the_sensor_at_10_hz():
    plan = floor_plan_from_dict(SQUARE)
    recording = simulate_recording(plan, NOISELESS, 5, pose=(0.0, 0.0, 0.0),
                                   velocity=(1.0, 0.0, 0.0))
    np.testing.assert_allclose(recording.poses[:, 0], [0.0, 0.1, 0.2, 0.3, 0.4])
    forward = np.argmin(np.abs(-math.pi + recording.angle_increment * np.arange(1080)))
    np.testing.assert_allclose(recording.ranges[:, forward], 3.0 - recording.poses[:, 0],
                               atol=1e-4)    # the beam nearest 0 deg is 0.17 deg off
