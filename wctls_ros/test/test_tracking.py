# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The landmark tracker against independent truth: Monte Carlo, a simulated walk, hand labels.

- The moves of corners and lines by a step have the Jacobians finite differences give.
- Monte Carlo over random steps drawn from their stated covariance: the innovations of the
  re-observed corners are chi2 with 2 dof (mean 2), and every id persists; given a quarter of
  the step's covariance the mean is clearly above 2 (a test that can fail).
- A row of corners and a step whose error moves each onto its neighbour's prediction: joint
  compatibility keeps every id, the nearest-first pairing (the search cut to its first leaf)
  shifts them. Each 2.2 sigma off, six corners pass jointly only with the shared step's cross
  terms.
- On a simulated walk through a room every true corner keeps one id, and the fused estimates'
  NEES against the truth is about 2; without the persistent share of the observation
  covariance it is about 4 (the extractor's small bias does not average out).
- A false corner that moves or flickers is never confirmed; a corner hidden behind a nearer
  return is not missed, one in view and not seen is lost.
- On the labelled still recording sick_lms111_static every confirmed corner is a labelled one.
- The judge of ``score --tracks`` takes a line through the world's origin, written once with
  r >= 0 and once with its normal turned round, as one line: no id switch, and a second track
  on it is a duplicate; a jump of 1 m is a switch.
"""

import math

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_lab.evaluation import load_scans
from wctls_lab.evaluation.score import match_detections
from wctls_lab.evaluation.tracks import run_tracker, track_figures, TrackRun
from wctls_lab.evaluation.truth import load_truth
from wctls_lab.simulation import floor_plan_from_dict, NoiseModel, simulate_recording
from wctls_ros.core import extract_features, FeatureConfig
from wctls_ros.frontend.frames import step_corners, step_lines, world_landmarks
from wctls_ros.frontend.tracking import (
    chi2_quantile_even, CONFIRMED, Detections, detections_of, Identified, LOST, Motion,
    steps_from_poses, TENTATIVE, TrackedScan, Tracker, TrackerConfig, View)

ROOM = {'name': 'room', 'polylines': [
    {'closed': True, 'points': [[0.0, 0.0], [4.5, 0.0], [4.5, 2.5], [1.5, 2.5], [1.5, 1.6],
                                [0.0, 1.6]]}],
    'boxes': [{'center': [3.6, 1.9], 'size': [0.8, 0.6], 'yaw_deg': 30.0}],
    'sensor': {'x': 2.5, 'y': 1.0, 'yaw_deg': 10.0}}
RANGE_SIGMA_M = 0.01
BEARING_SIGMA_RAD = math.radians(0.05)
CORNER_SIGMA_M = 0.01


def corners_seen(world: np.ndarray, pose: np.ndarray, rng, sigma_m=CORNER_SIGMA_M):
    """Return Detections of world corners (x, y, yaw) seen from a pose, with noise."""
    xy, by_corner, _ = step_corners(world, pose)
    cov = np.tile(np.diag([sigma_m ** 2, sigma_m ** 2, 0.01 ** 2]), (len(world), 1, 1))
    noisy = xy + rng.normal(size=xy.shape) * [sigma_m, sigma_m, 0.01]
    return Detections(noisy, cov, np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))


def test_chi2_quantiles_of_even_dof_match_the_tables():
    assert chi2_quantile_even(0.99, 2) == pytest.approx(9.2103, abs=1e-3)
    assert chi2_quantile_even(0.99, 4) == pytest.approx(13.2767, abs=1e-3)
    assert chi2_quantile_even(0.95, 6) == pytest.approx(12.5916, abs=1e-3)
    with pytest.raises(ValueError):
        chi2_quantile_even(0.99, 3)


@pytest.mark.parametrize('mover', ['corners', 'lines'])
def test_the_moves_by_a_step_have_the_jacobians_of_finite_differences(mover):
    rng = np.random.default_rng(3)
    step = np.array([0.3, -0.2, 0.4])
    if mover == 'corners':
        value, move = rng.uniform(-3, 3, (5, 3)), step_corners
    else:       # the last line passes between the poses: its normal turns round
        value, move = np.array([[0.3, 2.0], [2.0, 1.0], [-1.0, 3.0], [0.0, 0.2]]), step_lines
    _, by_value, by_step = move(value, step)
    h = 1e-6
    for column in range(value.shape[1]):
        delta = np.zeros_like(value)
        delta[:, column] = h
        numeric = (move(value + delta, step)[0] - move(value - delta, step)[0]) / (2 * h)
        np.testing.assert_allclose(by_value[:, :, column], numeric, atol=1e-6)
    for column in range(3):
        delta = np.zeros(3)
        delta[column] = h
        numeric = (move(value, step + delta)[0] - move(value, step - delta)[0]) / (2 * h)
        np.testing.assert_allclose(by_step[:, :, column], numeric, atol=1e-6)


def monte_carlo_innovations(stated_scale: float, trials: int = 300):
    """Return the squared distances of re-observed corners and whether every id persisted."""
    rng = np.random.default_rng(5)
    world = np.column_stack([rng.uniform(-4, 4, (6, 2)), rng.uniform(-3, 3, 6)])
    nominal = np.array([0.2, 0.05, 0.1])
    step_cov = np.diag([0.03 ** 2, 0.03 ** 2, 0.02 ** 2])
    squared, persisted = [], 0
    for _ in range(trials):
        tracker = Tracker()
        first = tracker.update(corners_seen(world, np.zeros(3), rng), Motion.still())
        true_step = rng.multivariate_normal(nominal, step_cov)
        second = tracker.update(corners_seen(world, true_step, rng),
                                Motion(nominal, stated_scale * step_cov))
        squared.append(second.corners.squared_distance)
        persisted += int(np.array_equal(first.corners.ids, second.corners.ids))
    return np.concatenate(squared), persisted / trials


def test_innovations_under_monte_carlo_steps_are_chi2_and_ids_persist():
    squared, persisted = monte_carlo_innovations(1.0)
    assert np.isfinite(squared).mean() > 0.98
    finite = squared[np.isfinite(squared)]
    # chi2 with 2 dof, truncated at the 99 % gate: mean 1.91. Corners of one trial share its
    # step, so the 1800 values are worth ~300 trials: +-0.3 is about 3 standard errors.
    assert 1.6 <= finite.mean() <= 2.2, finite.mean()
    assert 0.92 <= np.mean(finite <= 5.991) <= 0.98
    assert persisted >= 0.95


def test_a_step_covariance_stated_too_small_shows_in_the_innovations():
    squared, _ = monte_carlo_innovations(0.25)
    finite = squared[np.isfinite(squared)]
    assert finite.mean() > 2.6 or np.isnan(squared).mean() > 0.1


def row_of_corners(max_hypotheses: int, spacing_m: float = 0.3, shift_m: float = 0.3):
    """Track a row of corners spacing_m apart through a step shift_m longer than stated."""
    world = np.column_stack([spacing_m * (np.arange(6) - 2.5), np.full(6, 2.0), np.zeros(6)])
    step_cov = np.diag([0.2 ** 2, 0.002 ** 2, 1e-8])
    rng = np.random.default_rng(2)
    tracker = Tracker(TrackerConfig(max_hypotheses=max_hypotheses))
    first = tracker.update(corners_seen(world, np.zeros(3), rng, 0.002), Motion.still())
    second = tracker.update(corners_seen(world, np.array([shift_m, 0.0, 0.0]), rng, 0.002),
                            Motion(np.zeros(3), step_cov))
    return first.corners.ids, second.corners.ids


def test_joint_compatibility_keeps_the_ids_nearest_first_shifts():
    first, second = row_of_corners(200)
    np.testing.assert_array_equal(first, second)
    first, second = row_of_corners(1)     # cut to the nearest-first pairing
    assert np.sum(first == second) <= 1


def test_the_shared_step_lets_a_common_shift_pass_jointly():
    # Each corner is 2.24 sigma off along the row (d2 5, plus about 1 across it, of the gate's
    # 9.21), its neighbour's prediction 2.76 sigma (d2 7.6; an ambiguous cluster): the six are
    # jointly compatible as one shared step error (d2 about 5 + 6 of chi2(12) 26.2), not as
    # six independent errors (d2 about 36).
    first, second = row_of_corners(200, spacing_m=1.0, shift_m=0.2 * math.sqrt(5.0))
    np.testing.assert_array_equal(first, second)


@pytest.fixture(scope='module')
def walk():
    plan = floor_plan_from_dict(ROOM)
    noise = NoiseModel(range_sigma_m=RANGE_SIGMA_M, bearing_sigma_rad=BEARING_SIGMA_RAD)
    recording = simulate_recording(plan, noise, 80, seed=11, pose=(2.0, 0.8, 0.2),
                                   velocity=(0.2, 0.1, 0.3), beams=1080)
    config = FeatureConfig().replace(range_sigma_m=RANGE_SIGMA_M,
                                     bearing_sigma_rad=BEARING_SIGMA_RAD)
    features = [extract_features(ranges, recording.angle_min, recording.angle_increment, config,
                                 0.05, 40.0) for ranges in recording.ranges]
    detections = [detections_of(f, config.max_landmark_angle_sigma_rad) for f in features]
    return plan, recording, detections


def track_walk(walk, tracker_config: TrackerConfig):
    """Return (true corner -> confirmed ids, id -> true corners, NEES of fused corners)."""
    plan, recording, detections = walk
    tracker = Tracker(tracker_config)
    ids_of_corner, corners_of_id, nees = {}, {}, []
    motions = steps_from_poses(recording.poses, 0.0, 0.0)        # the true steps
    for t, found in enumerate(detections):
        view = View(recording.angle_min, recording.angle_increment, recording.ranges[t], 40.0)
        tracked = tracker.update(found, motions[t], view)
        truth = plan.to_sensor_frame(plan.corners_m, recording.poses[t])
        match = match_detections(found.corner_pose[:, :2], found.corner_cov[:, :2, :2], truth)
        for n in np.flatnonzero((match >= 0) & (tracked.corners.states == CONFIRMED)):
            ids_of_corner.setdefault(int(match[n]), set()).add(int(tracked.corners.ids[n]))
            corners_of_id.setdefault(int(tracked.corners.ids[n]), set()).add(int(match[n]))
        for landmark in tracker.landmarks('corner'):
            if landmark.state == CONFIRMED:
                error = truth - landmark.mean[:2]
                nearest = error[np.argmin(np.hypot(*error.T))]
                nees.append(nearest @ np.linalg.solve(landmark.covariance[:2, :2], nearest))
    return ids_of_corner, corners_of_id, np.array(nees)


def test_every_true_corner_keeps_one_id_on_a_simulated_walk(walk):
    ids_of_corner, corners_of_id, nees = track_walk(walk, TrackerConfig())
    assert len(ids_of_corner) >= 6, ids_of_corner
    assert all(len(ids) == 1 for ids in ids_of_corner.values()), ids_of_corner
    assert all(len(corners) == 1 for corners in corners_of_id.values()), corners_of_id
    # The same tracks over many scans: correlated samples, hence the wide band around 2.
    assert len(nees) >= 200
    assert 1.3 <= nees.mean() <= 2.7, nees.mean()


def test_without_the_persistent_share_the_fused_corners_are_overconfident(walk):
    _, _, nees = track_walk(walk, TrackerConfig(persistent_share=0.0))
    assert nees.mean() > 3.0, nees.mean()


def test_a_moving_or_flickering_false_corner_is_never_confirmed():
    rng = np.random.default_rng(8)
    world = np.column_stack([rng.uniform(-3, 3, (4, 2)), np.zeros(4)])
    tracker = Tracker()
    confirmed_false, confirmed_true = 0, set()
    for t in range(30):
        walker = np.array([[-2.0 + 0.05 * t, 1.0, 0.0]])         # 0.5 m/s at 10 Hz
        flicker = np.array([[1.5, -1.5, 0.0]]) if t % 3 else np.zeros((0, 3))
        everything = np.concatenate([world, walker, flicker])
        tracked = tracker.update(corners_seen(everything, np.zeros(3), rng), Motion.still())
        confirmed = tracked.corners.states == CONFIRMED
        confirmed_false += int(confirmed[len(world):].sum())
        confirmed_true |= set(tracked.corners.ids[:len(world)][confirmed[:len(world)]])
    assert confirmed_false == 0
    assert len(confirmed_true) == len(world)


def test_a_hidden_corner_is_not_missed_one_in_view_is_lost():
    rng = np.random.default_rng(4)
    world = np.array([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    bearings = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    # Something 1 m away hides the corner ahead (bearing 0); the other one is in clear view.
    ranges = np.where(np.abs(bearings) < 0.1, 1.0, 5.0)
    view = View(-math.pi, 2 * math.pi / 720, ranges, 10.0)
    tracker = Tracker()
    for _ in range(4):
        tracker.update(corners_seen(world, np.zeros(3), rng), Motion.still(), view)
    for _ in range(5):
        tracker.update(Detections.empty(), Motion.still(), view)
    states = {tuple(np.round(landmark.mean[:2])): landmark.state
              for landmark in tracker.landmarks('corner')}
    assert states == {(2.0, 0.0): CONFIRMED, (0.0, 2.0): LOST}


def test_bad_input_is_refused_with_the_reason():
    with pytest.raises(ValueError, match='non-finite corner_pose'):
        Detections(np.full((1, 3), np.nan), np.eye(3)[None], np.zeros((0, 2)),
                   np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))
    with pytest.raises(ValueError, match='positive semi-definite'):
        Motion(np.zeros(3), -np.eye(3))
    with pytest.raises(ValueError, match='confirm_hits'):
        TrackerConfig(confirm_hits=0)
    assert TENTATIVE != CONFIRMED


def test_confirmed_corners_of_a_labelled_still_recording_are_all_labelled():
    scans = load_scans(REAL_DATA / 'sick_lms111_static')
    truth = load_truth(REAL_DATA.parent / 'data' / 'labels' / 'sick_lms111_static.yaml')
    figures = track_figures(run_tracker(scans, FeatureConfig()), 'corner', truth)
    assert figures.precision == 1.0
    assert figures.recall == 1.0
    assert figures.id_switches == 0 and figures.duplicates == 0


# A wall 1 cm from the world's origin (normal -88.2 deg), seen from (0, 0) and from (0, 0.2) m:
# from there a range 15 mm short puts it 5 mm beyond the origin, where the world frame, which
# writes every line with r >= 0, turns its normal round (alpha 1.60 rad).
WALL_ANGLE_RAD = -1.54
SEEN_FROM = {'origin': np.zeros(3), 'north': np.array([0.0, 0.2, 0.0])}


def wall_run(sightings):
    """Return a TrackRun of one wall per scan: (track id, pose name, sensor-frame r m)."""
    normal = np.array([math.cos(WALL_ANGLE_RAD), math.sin(WALL_ANGLE_RAD)])
    along = np.array([-normal[1], normal[0]])
    detections, tracked = [], []
    for track, _, radius in sightings:
        ends = np.array([[radius * normal - along, radius * normal + along]])
        detections.append(Detections(np.zeros((0, 3)), np.zeros((0, 3, 3)),
                                     np.array([[WALL_ANGLE_RAD, radius]]),
                                     np.diag([1e-4, 1e-4])[None], ends))
        lines = Identified(np.array([track]), np.array([CONFIRMED]), np.array([3]),
                           np.array([3]), np.array([np.nan]))
        empty = Identified(*(np.zeros(0, dtype=int),) * 4, np.zeros(0))
        tracked.append(TrackedScan(empty, lines))
    poses = np.array([SEEN_FROM[name] for _, name, _ in sightings])
    return TrackRun(detections, tracked, poses, 0.0)


def test_the_judge_takes_a_line_through_the_world_origin_as_one_line():
    near_side = 0.01 + 0.2 * math.sin(-WALL_ANGLE_RAD) - 0.015      # the range 15 mm short
    world_line = world_landmarks(np.zeros((0, 2)), np.zeros((0, 2, 2)),
                                 np.array([[WALL_ANGLE_RAD, near_side]]), np.eye(2)[None],
                                 SEEN_FROM['north'], np.zeros((3, 3)))[2]
    assert world_line[0, 0] == pytest.approx(WALL_ANGLE_RAD + math.pi)      # turned round
    assert world_line[0, 1] == pytest.approx(0.005, abs=1e-4)
    one_track = wall_run([(1, 'origin', 0.01), (1, 'north', near_side),
                          (1, 'north', near_side + 1.0)])
    assert track_figures(one_track, 'line').id_switches == 1          # the 1 m jump only
    two_tracks = wall_run([(1, 'origin', 0.01), (1, 'north', near_side),
                           (2, 'north', near_side), (2, 'origin', 0.01)])
    figures = track_figures(two_tracks, 'line')
    assert figures.id_switches == 0
    assert figures.duplicates == 1
