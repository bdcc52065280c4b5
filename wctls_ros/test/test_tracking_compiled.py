# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiled tracker against the numpy one, scan by scan.

The numpy steps of :class:`~wctls_ros.frontend.tracking.Tracker` are the specification; their
compiled twin (``core/numba_core/tracking.py``), which the tracker runs whenever the compiled
core serves, must give every detection the same id, state, hits and age, and every squared
distance and fused estimate (mean and covariance of every track, after every scan) within 1e-9
relative, given the same detections and steps. On the real recordings of data/ as
``score --tracks`` runs them: the moving ones with their poses' steps, Malaga also with the
odometry's own (whose lost steps grow tracks to 1e3 m^2 before an observation shrinks them to
1e-4), still ones with their views (occlusion, misses in view); and on simulated scenes: a walk
through a cluttered room with noisy steps, a crowded scene whose clusters are ambiguous (the
joint search), and a row of corners shifted onto its neighbours with the search cut to its
first leaf. The numpy tracker's joint searches are counted, so that the cases that should
exercise them do.

Skipped only where numba is not installed (the stock-install venv); ``make test`` also runs it
at the oldest numba and numpy we support.
"""

import math

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_lab.evaluation import load_scans
from wctls_lab.evaluation.analysis import features_per_scan
from wctls_lab.evaluation.trajectory import run_odometry
from wctls_lab.simulation import load_floor_plan, NoiseModel, simulate_recording
from wctls_ros.core import extract_features, FeatureConfig, runtime
from wctls_ros.frontend import tracking
from wctls_ros.frontend.frames import rotation, step_corners, wrap_angle
from wctls_ros.frontend.poses import load_poses, poses_at
from wctls_ros.frontend.tracking import (Detections, detections_of, Motion, steps_from_poses,
                                         Tracker, TrackerConfig, View)

pytest.importorskip('numba')

RELATIVE = 1e-9
POSE_SIGMA_M, POSE_SIGMA_RAD = 0.05, math.radians(1.0)
# The moving recordings and their laser's offset on the robot (each laser_mount.yaml).
MOVING = {'tuw_gh25_moving': 0.12, 'mrpt_malaga_moving': 0.78, 'rplidar_barc_moving': -0.12}


def recorded(name, scans=None, odometry=False):
    """Return a recording's (detections, motion, view) per scan, as score --tracks has them."""
    recording = load_scans(REAL_DATA / name, limit=scans)
    config = FeatureConfig()
    if name in MOVING:
        poses = poses_at(load_poses(REAL_DATA / name / 'poses.csv'),
                         recording.stamps_ns * 1e-9, (MOVING[name], 0.0, 0.0))
        assert np.isfinite(poses).all()
        motions = steps_from_poses(poses, math.sqrt(2.0) * POSE_SIGMA_M,
                                   math.sqrt(2.0) * POSE_SIGMA_RAD)
    else:
        motions = [Motion.still()] * len(recording)
    if odometry:
        run = run_odometry(recording, config)
        motions = [Motion(step, covariance)
                   for step, covariance in zip(run.steps, run.step_covariances)]
    detections = [detections_of(features, config.max_landmark_angle_sigma_rad)
                  for features, _ in features_per_scan(recording, config)]
    views = [View(recording.angle_min, recording.angle_increment, ranges, recording.range_max)
             for ranges in recording.ranges]
    return list(zip(detections, motions, views))


def simulated_walk():
    """Return a walk through a cluttered room, its steps given 3 cm and 2 deg of sigma."""
    noise = NoiseModel(range_sigma_m=0.01, bearing_sigma_rad=math.radians(0.05))
    walk = simulate_recording(load_floor_plan('environment_a_cluttered'), noise, 120, seed=4,
                              velocity=(0.3, 0.1, 0.4), beams=1080)
    config = FeatureConfig().replace(range_sigma_m=0.01, bearing_sigma_rad=math.radians(0.05))
    motions = steps_from_poses(walk.poses, 0.03, math.radians(2.0))
    out = []
    for ranges, motion in zip(walk.ranges, motions):
        features = extract_features(ranges, walk.angle_min, walk.angle_increment, config,
                                    0.05, 40.0)
        out.append((detections_of(features, config.max_landmark_angle_sigma_rad), motion,
                    View(walk.angle_min, walk.angle_increment, ranges, 40.0)))
    return out


def crowded_scene():
    """Return 60 landmarks crowded round a sensor whose steps are stated 15 cm and 4 deg."""
    rng = np.random.default_rng(7)
    corner = np.column_stack([rng.uniform(-2.4, 2.4, (30, 2)), rng.uniform(-3, 3, 30)])
    line = np.column_stack([np.linspace(-math.pi, math.pi, 30, endpoint=False),
                            rng.uniform(0.5, 8.0, 30)])
    step = np.array([0.05, 0.0, math.radians(1.0)])
    step_cov = np.diag([0.15 ** 2, 0.15 ** 2, math.radians(4.0) ** 2])
    pose, out = np.zeros(3), []
    for t in range(120):
        if t:
            pose = pose + np.concatenate([rotation(pose[2]) @ step[:2], step[2:]])
        xy, _, _ = step_corners(corner, pose)
        noisy = xy + rng.normal(size=xy.shape) * [0.01, 0.01, 0.02]
        corner_cov = np.tile(np.diag([0.01 ** 2, 0.01 ** 2, 0.02 ** 2]), (len(xy), 1, 1))
        # Lines in the sensor frame; those the sensor has crossed have their normal turned.
        angle = line[:, 0] - pose[2]
        radius = line[:, 1] - pose[0] * np.cos(line[:, 0]) - pose[1] * np.sin(line[:, 0])
        angle = wrap_angle(np.where(radius < 0.0, angle + math.pi, angle))
        sensed = np.column_stack([angle, np.abs(radius)]) + rng.normal(size=(30, 2)) * [
            0.005, 0.01]
        normal = np.column_stack([np.cos(sensed[:, 0]), np.sin(sensed[:, 0])])
        along = np.column_stack([-normal[:, 1], normal[:, 0]])
        foot = normal * sensed[:, 1:2]
        out.append((Detections(noisy, corner_cov, sensed,
                               np.tile(np.diag([0.005 ** 2, 0.01 ** 2]), (30, 1, 1)),
                               np.stack([foot - along, foot + along], axis=1)),
                    Motion(step, step_cov) if t else Motion.still(), None))
    return out


def shifted_row():
    """Return a row of corners 0.3 m apart and a step 0.3 m longer than its stated mean."""
    world = np.column_stack([0.3 * (np.arange(6) - 2.5), np.full(6, 2.0), np.zeros(6)])
    rng = np.random.default_rng(2)
    out = []
    for t, shift in enumerate((0.0, 0.3, 0.3, 0.0)):
        xy, _, _ = step_corners(world, np.array([shift, 0.0, 0.0]))
        noisy = xy + rng.normal(size=xy.shape) * [0.002, 0.002, 0.01]
        cov = np.tile(np.diag([0.002 ** 2, 0.002 ** 2, 0.01 ** 2]), (6, 1, 1))
        out.append((Detections(noisy, cov, np.zeros((0, 2)), np.zeros((0, 2, 2)),
                               np.zeros((0, 2, 2))),
                    Motion(np.zeros(3), np.diag([0.2 ** 2, 0.002 ** 2, 1e-8])) if t
                    else Motion.still(), None))
    return out


# name: (its scans, the tracker's rules, whether clusters of several detections must be searched)
CASES = {
    'gh25': (lambda: recorded('tuw_gh25_moving'), TrackerConfig(), True),
    'car': (lambda: recorded('rplidar_barc_moving', 200), TrackerConfig(), True),
    'malaga_odometry': (lambda: recorded('mrpt_malaga_moving', odometry=True), TrackerConfig(),
                        True),
    'urg04lx_still': (lambda: recorded('urg04lx_office'), TrackerConfig(), False),
    'lms111_still': (lambda: recorded('sick_lms111_static'), TrackerConfig(), False),
    'walk': (simulated_walk, TrackerConfig(), False),
    'walk_other_rules': (simulated_walk, TrackerConfig(
        gate_probability=0.95, confirm_hits=2, drop_tentative_misses=2, lose_misses=2,
        memory_scans=10, occlusion_margin_m=0.05, persistent_share=0.2), False),
    'crowded': (crowded_scene, TrackerConfig(), True),
    # Searches cut short at every depth: the node count and the best kept by then.
    **{f'crowded_cut_{nodes}': (crowded_scene, TrackerConfig(max_hypotheses=nodes), True)
       for nodes in (2, 3, 5, 8, 13)},
    'gh25_cut_4': (lambda: recorded('tuw_gh25_moving'), TrackerConfig(max_hypotheses=4), True),
    'row_first_leaf': (shifted_row, TrackerConfig(max_hypotheses=1), True),
}


@pytest.fixture(scope='module')
def compiled_core():
    """Make the compiled core serve (loaded, or compiled, now); return the tracker's kernels."""
    kernels = runtime.compiled_kernels('tracking', True)
    assert kernels is not None, runtime.status()
    return kernels


def assert_close(compiled, reference, floor, what):
    """Hold values to the reference within RELATIVE of its largest magnitude (at least floor)."""
    compiled, reference = np.asarray(compiled, dtype=float), np.asarray(reference, dtype=float)
    assert compiled.shape == reference.shape, what
    assert np.array_equal(np.isnan(compiled), np.isnan(reference)), what
    if reference.size:
        scale = max(float(np.nanmax(np.abs(reference), initial=0.0)), floor)
        error = np.nan_to_num(np.abs(compiled - reference))
        assert error.max() <= RELATIVE * scale, (what, error.max() / scale)


def assert_same_scan(compiled, reference, compiled_tracks, reference_tracks, where):
    """Hold one scan's output and every track after it to the numpy tracker's."""
    for kind in ('corners', 'lines'):
        ours, theirs = getattr(compiled, kind), getattr(reference, kind)
        for name in ('ids', 'states', 'hits', 'age_scans'):
            np.testing.assert_array_equal(getattr(ours, name), getattr(theirs, name),
                                          err_msg=f'{where}, {kind} {name}')
        assert_close(ours.squared_distance, theirs.squared_distance, 1.0,
                     f'{where}, {kind} squared distances')
    assert [(t.track_id, t.kind, t.state, t.hits, t.age_scans) for t in compiled_tracks] == [
        (t.track_id, t.kind, t.state, t.hits, t.age_scans) for t in reference_tracks], where
    for ours, theirs in zip(compiled_tracks, reference_tracks):
        angle = 0 if ours.kind == tracking.LINE else 2
        error = ours.mean - theirs.mean
        error[angle] = wrap_angle(error[angle])
        assert_close(theirs.mean + error, theirs.mean, math.pi, f'{where}, track {ours.track_id}')
        assert_close(ours.covariance, theirs.covariance, 0.0,
                     f'{where}, track {ours.track_id} covariance')


@pytest.mark.parametrize('case', CASES)
def test_the_compiled_tracker_gives_the_numpy_ones_ids_and_estimates(case, compiled_core,
                                                                     monkeypatch):
    scans, rules, searches_expected = CASES[case]
    searches = []
    best = tracking._JointSearch.best
    monkeypatch.setattr(tracking._JointSearch, 'best',
                        lambda self, detections: searches.append(len(detections))
                        or best(self, detections))
    compiled, reference = Tracker(rules, compiled=True), Tracker(rules, compiled=False)
    seen = 0
    for t, (detections, motion, view) in enumerate(scans()):
        ours = compiled.update(detections, motion, view)
        theirs = reference.update(detections, motion, view)
        assert_same_scan(ours, theirs, compiled.landmarks(), reference.landmarks(),
                         f'{case} scan {t}')
        seen += len(theirs.corners.ids) + len(theirs.lines.ids)
    assert seen > 0
    if searches_expected:
        assert max(searches, default=0) >= 2, searches


def test_the_tracker_runs_the_compiled_twin_while_the_compiled_core_serves(compiled_core):
    assert Tracker()._kernels() is compiled_core
    assert Tracker(compiled=True)._kernels() is compiled_core
    assert Tracker(compiled=False)._kernels() is None
