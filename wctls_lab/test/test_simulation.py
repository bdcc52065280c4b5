# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The scan simulator: exact ray casting, the bundled plans and the sensor model.

Each feature of the realistic scenes is measured against independent geometry: mixed pixels,
dropouts, dark pieces, bowed and rough walls, bearing quantisation, cylinders, walkers, corner
kinds and occlusion by clutter.
"""

import math

import numpy as np
import pytest
from wctls_lab.simulation import (BUNDLED_PLANS, cast_rays, floor_plan_from_dict,
                                  full_turn_bearings, load_floor_plan, NOISELESS, NoiseModel,
                                  ray_hits, Scene, SENSOR_MODELS, simulate_ranges,
                                  simulate_recording, simulate_scan, visible_corners)

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


@pytest.mark.parametrize('shadow_centre_m, visible', [(1.835, False), (1.635, True)])
def test_a_wall_seen_near_its_corner_only_beyond_a_shadow_does_not_make_the_corner_visible(
        shadow_centre_m, visible):
    # A leg 1.5 m out shadows about 0.17 m of the wall x = 3 below the corner (3, 2). Returns
    # beyond the shadow are another piece of the wall: the corner counts as visible only when the
    # piece next to it is long enough (0.08 m left of it: not; 0.28 m: yes).
    walls, corners = floor_plan_from_dict(SQUARE).in_sensor_frame((0.0, 0.0, 0.0))
    bearings = full_turn_bearings()[2]
    leg = np.array([[1.5, 1.5 * shadow_centre_m / 3.0, 0.036]])
    ranges = ray_hits(walls, leg, np.zeros(2), bearings).range_m
    shadowed = np.flatnonzero((ranges < 2.0) & (bearings > 0.0) & (bearings < 1.0))
    y_on_wall = 3.0 * np.tan(bearings[[shadowed[0] - 1, shadowed[-1] + 1]])
    assert 0.15 < np.ptp(y_on_wall) < 0.2                    # the shadow the comment describes
    corner = np.all(np.isclose(corners, [3.0, 2.0]), axis=1)
    seen = visible_corners(walls, corners, bearings, circles_m=leg)
    assert seen[corner].item() is visible and seen[~corner].all()


def test_a_recording_moves_the_sensor_at_10_hz():
    plan = floor_plan_from_dict(SQUARE)
    recording = simulate_recording(plan, NOISELESS, 5, pose=(0.0, 0.0, 0.0),
                                   velocity=(1.0, 0.0, 0.0))
    np.testing.assert_allclose(recording.poses[:, 0], [0.0, 0.1, 0.2, 0.3, 0.4])
    forward = np.argmin(np.abs(-math.pi + recording.angle_increment * np.arange(1080)))
    np.testing.assert_allclose(recording.ranges[:, forward], 3.0 - recording.poses[:, 0],
                               atol=1e-4)    # the beam nearest 0 deg is 0.17 deg off


def _old_simulate_ranges(walls_m, bearings_rad, noise, rng):
    """Simulate as before mixed pixels, surfaces and clutter existed (kept as the oracle)."""
    bearings = np.asarray(bearings_rad, dtype=float)
    true_bearings = bearings + rng.normal(0.0, noise.bearing_sigma_rad, bearings.shape)
    ranges = cast_rays(walls_m, np.zeros(2), true_bearings)
    hit = np.isfinite(ranges)
    sigma = np.hypot(noise.range_sigma_m, noise.range_sigma_per_m * np.where(hit, ranges, 0.0))
    offset = rng.normal(0.0, noise.common_range_sigma_m)
    with np.errstate(invalid='ignore'):
        ranges = ranges + rng.normal(0.0, 1.0, bearings.shape) * sigma + offset
    dropped = rng.random(bearings.shape) < noise.dropout_probability
    out_of_range = ~((ranges >= noise.min_range_m) & (ranges <= noise.max_range_m))
    ranges[dropped | out_of_range] = np.inf
    return ranges


@pytest.mark.parametrize('name', ['environment_a', 'environment_b'])
def test_existing_plans_and_models_give_the_same_scans_as_before(name):
    plan = load_floor_plan(name)
    walls, _ = plan.in_sensor_frame()
    bearings = full_turn_bearings()[2]
    noise = NoiseModel(range_sigma_m=0.012, bearing_sigma_rad=math.radians(0.2),
                       common_range_sigma_m=0.003, dropout_probability=0.02,
                       range_sigma_per_m=0.003, max_range_m=5.0)
    for model in (NoiseModel(), noise):
        recording = simulate_recording(plan, model, 3, seed=7)
        rng = np.random.default_rng(7)
        expected = [_old_simulate_ranges(walls, bearings, model, rng) for _ in range(3)]
        np.testing.assert_array_equal(recording.ranges, expected)


def _edge_scene():
    """Return a far wall at x = 3 and a near wall at x = 1 for y < 0: an edge at bearing 0."""
    return Scene.of_walls(np.array([[3.0, -5.0, 3.0, 5.0], [1.0, -2.0, 1.0, 0.0]]))


def test_a_mixed_pixel_lies_between_the_two_surfaces_and_only_at_the_edge():
    divergence = math.radians(0.4)
    bearings = np.radians(np.linspace(-3.0, 3.0, 601))
    noise = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0, beam_divergence_rad=divergence)
    ranges = simulate_scan(_edge_scene(), bearings, noise, np.random.default_rng(0))
    near, far = 1.0 / np.cos(bearings), 3.0 / np.cos(bearings)
    mixed = (np.abs(ranges - near) > 1e-9) & (np.abs(ranges - far) > 1e-9)
    assert mixed.sum() >= 3                             # 0.4 deg footprint, 0.01 deg spacing
    # Footprint half-widths of other surfaces stay at least 0.1 % of the range away.
    assert np.all(ranges[mixed] > near[mixed] * 1.001)
    assert np.all(ranges[mixed] < far[mixed] * 0.999)
    assert np.all(np.abs(bearings[mixed]) <= divergence / 2)
    # Sweeping from the near surface to the far one, the mixed range grows (in steps of the
    # footprint fraction; within a step the surfaces' 1/cos changes it by under 1e-5 m).
    assert np.all(np.diff(ranges[mixed]) > -1e-5) and np.ptp(ranges[mixed]) > 1.0
    ideal = simulate_scan(_edge_scene(), bearings, NOISELESS, np.random.default_rng(0))
    np.testing.assert_allclose(ideal, np.where(bearings <= 0.0, near, far), rtol=1e-12)


def test_sensor_dropouts_follow_their_rate():
    wall = np.array([[2.0, -50.0, 2.0, 50.0]])
    count, rate = 20000, 0.05
    noise = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0, dropout_probability=rate)
    lost = np.isinf(simulate_ranges(wall, np.zeros(count), noise, np.random.default_rng(4)))
    spread = math.sqrt(count * rate * (1 - rate))
    assert abs(lost.sum() - count * rate) < 4.5 * spread


def _wall_plan(surface, **extra):
    """Return a long wall at y = 2 beside a sensor at the origin facing +x, with a surface."""
    return floor_plan_from_dict(dict({
        'name': 'wall', 'sensor': {'x': 0.0, 'y': 0.0, 'yaw_deg': 0.0},
        'polylines': [{'points': [[-20.0, 2.0], [20.0, 2.0]]}],
        'surfaces': [surface]}, **extra))


def test_a_dark_piece_never_returns_and_a_grey_one_drops_at_its_rate():
    plan = _wall_plan({'from': [-1.0, 2.0], 'to': [1.0, 2.0], 'dark': True})
    bearings = np.radians(np.linspace(30.0, 150.0, 2001))
    on_piece = np.abs(2.0 / np.tan(bearings)) < 1.0 - 1e-6
    for no_return, value in (('inf', math.inf), ('zero', 0.0), ('max', 40.0)):
        noise = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0, no_return=no_return)
        ranges = simulate_scan(plan.scene(), bearings, noise, np.random.default_rng(1))
        assert np.all(ranges[on_piece] == value)
        np.testing.assert_allclose(ranges[~on_piece & (np.abs(2.0 / np.tan(bearings)) > 1.0)],
                                   2.0 / np.sin(bearings[~on_piece & (np.abs(
                                       2.0 / np.tan(bearings)) > 1.0)]), rtol=1e-12)
    grey = _wall_plan({'from': [-10.0, 2.0], 'to': [10.0, 2.0], 'dropout': 0.3})
    count = 20000
    noise = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0, dropout_probability=0.1)
    ranges = simulate_scan(grey.scene(), np.full(count, math.pi / 2), noise,
                           np.random.default_rng(2))
    rate = 1.0 - 0.9 * 0.7                    # either the sensor or the surface drops the beam
    assert abs(np.isinf(ranges).sum() - count * rate) < 4.5 * math.sqrt(count * rate * (1 - rate))


def test_a_bowed_wall_moves_its_returns_by_the_sagitta_the_same_in_every_scan():
    bow = 0.005                     # towards +y (left of from -> to): away from the sensor
    plan = _wall_plan({'from': [-1.0, 2.0], 'to': [1.0, 2.0], 'bow_m': bow})
    recording = simulate_recording(plan, NOISELESS, 3, beams=2161)
    bearings = recording.angle_min + recording.angle_increment * np.arange(2161)
    seen = np.isfinite(recording.ranges[0])
    points = recording.ranges[0, seen, None] * np.column_stack([np.cos(bearings[seen]),
                                                                np.sin(bearings[seen])])
    on_piece = (np.abs(points[:, 0]) < 1.0) & (points[:, 1] > 0.0)
    x = points[on_piece, 0]
    s = (x + 1.0) / 2.0
    # The surface is y = 2 + 4 bow s (1 - s): returns lie on it to first order (1e-5 m).
    np.testing.assert_allclose(points[on_piece, 1], 2.0 + 4.0 * bow * s * (1.0 - s), atol=2e-5)
    middle = np.argmin(np.abs(bearings - math.pi / 2))
    assert recording.ranges[0, middle] == pytest.approx(2.0 + bow, abs=2e-5)
    np.testing.assert_array_equal(recording.ranges[0], recording.ranges[2])


def test_a_rough_wall_has_its_stated_rms_fixed_across_scans():
    rms = 0.002
    plan = _wall_plan({'from': [-1.5, 2.0], 'to': [1.5, 2.0], 'roughness_m': rms,
                       'roughness_length_m': 0.05, 'seed': 3})
    noise = NoiseModel(range_sigma_m=0.004, bearing_sigma_rad=0.0)
    recording = simulate_recording(plan, noise, 60, seed=5, beams=4321)
    bearings = recording.angle_min + recording.angle_increment * np.arange(4321)
    piece = (np.abs(np.cos(bearings)) < 0.57) & (bearings > 0.0)     # |x| < 1.4 at y = 2
    # The mean over the scans removes the noise, not the roughness: it is part of the wall.
    mean = recording.ranges[:, piece].mean(axis=0)
    departure = (mean - 2.0 / np.sin(bearings[piece])) * np.sin(bearings[piece])
    assert np.sqrt(np.mean(departure ** 2)) == pytest.approx(rms, rel=0.15)
    assert np.abs(departure).max() < 5 * rms
    first, second = recording.ranges[:30, piece].mean(0), recording.ranges[30:, piece].mean(0)
    assert np.corrcoef(first, second)[0, 1] > 0.9       # the same profile in both halves


def test_quantised_bearings_lie_within_half_a_bin():
    quantum = math.radians(1.0 / 3.0)
    wall = np.array([[-20.0, 1.0, 20.0, 1.0]])
    bearings = np.radians(np.linspace(40.0, 140.0, 3001))
    noise = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0, bearing_quantum_rad=quantum)
    ranges = simulate_ranges(wall, bearings, noise, np.random.default_rng(6))
    # The return's true bearing from the wall's geometry: r sin(theta) = 1, on the same side.
    true = np.where(bearings < math.pi / 2, np.arcsin(1.0 / ranges),
                    math.pi - np.arcsin(1.0 / ranges))
    offset = true - bearings
    assert np.abs(offset).max() <= quantum / 2 + 1e-9
    assert np.abs(offset).max() > 0.45 * quantum                # the whole bin is used
    assert np.std(offset) == pytest.approx(quantum / math.sqrt(12.0), rel=0.1)


def test_cylinder_hits_match_the_analytic_circle_intersection():
    rng = np.random.default_rng(8)
    circles = np.array([[2.0, 0.5, 0.3], [-1.0, -1.5, 0.05], [0.1, 0.0, 0.2]])  # last: around
    bearings = rng.uniform(-math.pi, math.pi, 4000)
    hits = ray_hits(np.zeros((0, 4)), circles, np.zeros(2), bearings)
    expected = np.full(bearings.shape, np.inf)
    for x, y, radius in circles:
        for k, theta in enumerate(bearings):
            # |t u - c|^2 = r^2: t^2 - 2 (u.c) t + |c|^2 - r^2 = 0, smallest positive root.
            roots = np.roots([1.0, -2.0 * (math.cos(theta) * x + math.sin(theta) * y),
                              x * x + y * y - radius * radius])
            roots = roots[np.isreal(roots) & (roots.real > 0.0)].real
            if roots.size:
                expected[k] = min(expected[k], roots.min())
    np.testing.assert_allclose(hits.range_m, expected, rtol=1e-9)
    # The sensor stands inside the third circle: every ray hits something.
    assert np.isfinite(hits.range_m).all() and set(np.unique(hits.surface)) <= {0, 1, 2}


WALKER_ROOM = {
    'name': 'walker', 'sensor': {'x': 2.0, 'y': 1.5, 'yaw_deg': 0.0},
    'polylines': [{'closed': True, 'points': [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]}],
    'walkers': [{'path': [[0.8, 0.6], [3.4, 0.6]], 'speed_m_s': 1.0}]}


def test_the_walkers_returns_move_between_scans_while_the_walls_stay():
    plan = floor_plan_from_dict(WALKER_ROOM)
    recording = simulate_recording(plan, NOISELESS, 4)
    bearings = recording.angle_min + recording.angle_increment * np.arange(1080)
    walls, _ = plan.in_sensor_frame()
    on_walls = cast_rays(walls, np.zeros(2), bearings)
    for t in range(4):
        legs = plan.walkers[0].legs_m(0.1 * t)
        legs[:, :2] = plan.to_sensor_frame(legs[:, :2])
        points = recording.ranges[t, :, None] * np.column_stack([np.cos(bearings),
                                                                 np.sin(bearings)])
        off_walls = np.abs(recording.ranges[t] - on_walls) > 1e-9
        distance = np.hypot(*(points[:, None, :] - legs[None, :, :2]).transpose(2, 0, 1))
        # Every return off the walls lies on a leg's circle, and both legs are seen.
        assert np.all(np.min(np.abs(distance[off_walls] - legs[:, 2]), axis=1) < 1e-9)
        assert off_walls.sum() >= 10
    moved = np.abs(recording.ranges[1] - recording.ranges[0]) > 1e-9
    assert moved.sum() >= 5
    steps = [plan.walkers[0].legs_m(0.1 * t) for t in range(3)]
    assert np.all(np.hypot(*(steps[1][:, :2] - steps[0][:, :2]).T) > 0.01)


def test_corner_kinds_on_a_known_plan():
    plan = floor_plan_from_dict({
        'name': 'kinds', 'sensor': {'x': 2.0, 'y': 2.5},
        'polylines': [{'closed': True, 'points': [[0, 0], [4, 0], [4, 3], [1.5, 3], [1.5, 3.6],
                                                  [0, 3.6]]}],
        'boxes': [{'center': [2.0, 0.25], 'size': [1.0, 0.5]},      # a cabinet on the wall
                  {'center': [3.0, 2.0], 'size': [0.4, 0.4]}]})      # a free-standing box
    kinds = dict(zip(map(tuple, np.round(plan.corners_m, 6).tolist()), plan.corner_kinds))
    assert kinds == {
        (0.0, 0.0): 'inside', (4.0, 0.0): 'inside', (4.0, 3.0): 'inside',
        (1.5, 3.0): 'outside', (1.5, 3.6): 'inside', (0.0, 3.6): 'inside',
        (1.5, 0.0): 'inside', (2.5, 0.0): 'inside', (2.5, 0.5): 'outside',
        (1.5, 0.5): 'outside', (2.8, 1.8): 'outside', (3.2, 1.8): 'outside',
        (3.2, 2.2): 'outside', (2.8, 2.2): 'outside'}


SQUARE_ROOM = {'name': 'square', 'sensor': {'x': 2.0, 'y': 2.0},
               'polylines': [{'closed': True, 'points': [[0, 0], [4, 0], [4, 4], [0, 4]]}]}


def test_clutter_and_a_walker_hide_the_corners_behind_them():
    bearings = full_turn_bearings()[2]
    open_room = floor_plan_from_dict(SQUARE_ROOM)
    assert open_room.scene().visible(open_room.in_sensor_frame()[1], bearings).all()
    leg = dict(SQUARE_ROOM, clutter=[{'cylinder': [3.5, 3.5], 'radius_m': 0.03}])
    plan = floor_plan_from_dict(leg)
    seen = plan.scene().visible(plan.in_sensor_frame()[1], bearings)
    assert seen.tolist() == [True, True, False, True]          # (4, 4) is behind the leg
    # A walker crossing the diagonal to (0, 0), both legs on it at t = 0, then walking off.
    walker = dict(SQUARE_ROOM, walkers=[{'path': [[0.5, 1.5], [1.5, 0.5]], 'speed_m_s': 0.5,
                                         'start_m': math.sqrt(0.5), 'hip_width_m': 0.0,
                                         'step_m': 0.1}])
    plan = floor_plan_from_dict(walker)
    recording = simulate_recording(plan, NOISELESS, 12)
    assert recording.visible[0].tolist() == [False, True, True, True]
    assert recording.visible[:, 1:].all() and recording.visible[-1, 0]


def _length_on(walls, wall):
    """Return the length of the walls that lie on one wall, as a fraction of it."""
    start, edge = wall[:2], wall[2:] - wall[:2]
    ends = walls.reshape(-1, 2, 2) - start
    cross = ends[..., 0] * edge[1] - ends[..., 1] * edge[0]
    along = ends[np.all(np.abs(cross) < 1e-9 * np.hypot(*edge), axis=1)] @ edge / (edge @ edge)
    inside = np.all((along > -1e-9) & (along < 1.0 + 1e-9), axis=1)
    return float(np.sum(np.abs(along[inside, 1] - along[inside, 0])))


@pytest.mark.parametrize('name', ['environment_a', 'environment_b'])
def test_cluttered_variants_are_the_same_rooms_with_more_in_them(name):
    base, cluttered = load_floor_plan(name), load_floor_plan(f'{name}_cluttered')
    # Corners where a wall meets a bowed or rough one in its middle sit on its surface.
    np.testing.assert_allclose(cluttered.corners_m, base.corners_m, atol=0.006)
    assert cluttered.corner_kinds == base.corner_kinds and len(cluttered.walkers) == 1
    assert len(cluttered.cylinders_m) >= 4 and (cluttered.surfaces.dropout == 1.0).any()
    assert cluttered.surfaces.shaped and cluttered.sensor_pose == base.sensor_pose
    # Every base wall is still there, split into collinear pieces where surfaces are given:
    # the length of the pieces on it is the same in both plans.
    for wall in base.walls_m:
        assert _length_on(cluttered.walls_m, wall) == pytest.approx(_length_on(base.walls_m,
                                                                               wall))
    assert set(BUNDLED_PLANS) >= {f'{name}_cluttered'}


def test_a_corner_in_the_middle_of_a_bowed_wall_lies_on_its_surface():
    # A 4 m wall along y = 0 bowed by 1 cm towards +y (its left normal, from x = 0 to 4), and a
    # cabinet against it from x = 1 to 1.4: its corners on the wall sit on the bowed surface,
    # 4 s (1 - s) 1 cm off the straight line at s = 1/4 and 0.35 along.
    plan = floor_plan_from_dict({
        'name': 'bowed', 'polylines': [{'closed': False, 'points': [[0.0, 0.0], [4.0, 0.0]]}],
        'boxes': [{'center': [1.2, 0.5], 'size': [0.4, 1.0]}],
        'surfaces': [{'from': [0.0, 0.0], 'to': [4.0, 0.0], 'bow_m': 0.01}]})
    on_wall = plan.corners_m[np.abs(plan.corners_m[:, 1]) < 0.02]
    np.testing.assert_allclose(on_wall[np.argsort(on_wall[:, 0])],
                               [[1.0, 0.0075], [1.4, 0.0091]], atol=1e-9)


def test_the_s1_like_model_makes_veils_dropouts_and_binned_bearings():
    plan = load_floor_plan('environment_a')
    clean = simulate_recording(plan, NOISELESS, 1)
    s1 = simulate_recording(plan, SENSOR_MODELS['s1_like'], 20, seed=2)
    lost = np.isinf(s1.ranges).mean()
    assert 0.005 < lost < 0.02
    spread = np.nanstd(np.where(np.isfinite(s1.ranges), s1.ranges - clean.ranges, np.nan))
    assert spread > 0.02                         # 2 cm noise plus veils at every edge


@pytest.mark.parametrize('spec, message', [
    ({'polylines': [{'points': [[0, 0], [1, 0]]}], 'colour': 'red'}, 'unknown keys'),
    ({'polylines': [{'points': [[0, 0], [1, 0]]}],
      'clutter': [{'cylinder': [0.5, 0.5], 'radius_m': -1}]}, 'radius_m'),
    ({'polylines': [{'points': [[0, 0], [1, 0]]}],
      'surfaces': [{'from': [0, 1], 'to': [1, 1], 'bow_m': 0.01}]}, 'do not both lie'),
    ({'polylines': [{'points': [[0, 0], [1, 0]]}],
      'surfaces': [{'from': [0, 0], 'to': [0.5, 0]}, {'from': [0.2, 0], 'to': [0.4, 0]}]},
     'overlaps surfaces'),
    ({'polylines': [{'points': [[0, 0], [1, 0]]}] * 1001}, 'more than 1000 shapes'),
    ({'polylines': [{'points': [[0, 0], [1e9, 0]]}]}, 'outside'),
    ({'polylines': [{'points': [[0, 0], [1, 0]]}],
      'walkers': [{'path': [[0, 0], [0, 0]]}]}, 'at least 1 cm'),
    ({'base': 'no_such_plan'}, 'no floor plan'),
])
def test_malformed_plans_are_refused_with_the_reason(spec, message):
    with pytest.raises((ValueError, FileNotFoundError), match=message):
        floor_plan_from_dict(dict({'name': 'bad'}, **spec))


def test_a_plan_cannot_make_the_loader_allocate_without_bound(tmp_path):
    points = [[float(k), 0.0] for k in range(10001)]
    with pytest.raises(ValueError, match='2 to 10000'):
        floor_plan_from_dict({'name': 'huge', 'polylines': [{'points': points}]})
    path = tmp_path / 'big.yaml'
    path.write_text('name: big\n' + '#' * 1_000_001)
    with pytest.raises(ValueError, match='larger than'):
        load_floor_plan(path)
