# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiled odometry against the numpy one: its chi-squares, its fits, and its trajectories.

The numpy steps of :mod:`wctls_ros.frontend.odometry` are the specification; their compiled
twin (``core/numba_core/odometry.py``: the hypothesis search, its scoring and refinements, and
the fit), which the odometry runs whenever the compiled core serves, must give:

- the hypotheses as numpy does (the same number, in its order, within 1e-12 m and rad), the
  search's chi-squares of every corner and line pair under every hypothesis inside the gate
  where numpy's are (segments that do not overlap outside) and there within 1e-12 relative,
  and the hypotheses' scores exactly, on the first 40 steps of every shipped moving recording;
- a fit of a well-posed association within 1e-9 (its sums are taken in another order);
- on the first 200 scans of the shipped moving recordings, matched against a keyframe, scan to
  scan and with a wheel odometry as the prior, the same statuses, counts of corners and lines,
  prior sources and rejections on every scan, and the poses and steps within 1e-5 m and rad,
  their covariances within 1e-4 of their largest element. A fit of a single line pair is a
  singular system whose outcome is rounding noise, which the compiled fit rounds otherwise:
  measured on the whole recordings, 4.8e-6 m on the RPLIDAR car, 1e-9 m on Malaga and 1e-14 m
  on gh25 (docs/odometry.md#time-per-scan).

Skipped only where numba is not installed (the stock-install venv).
"""

import math
import pathlib

import numpy as np
import pytest
from wctls_lab.evaluation.poses import load_poses, poses_at
from wctls_lab.evaluation.scans import load_scans
from wctls_lab.evaluation.score_cli import node_config
from wctls_lab.evaluation.trajectory import landmarks_from_features
from wctls_ros.core import extract_features, runtime
from wctls_ros.frontend import odometry
from wctls_ros.frontend.odometry import compose, inverse, Odometry, OdometryConfig
from wctls_ros.frontend.wheel import laser_prior, WheelModel
from wctls_ros.plain_yaml import load_without_aliases

pytest.importorskip('numba')

DATA = pathlib.Path(__file__).resolve().parents[2] / 'data'
# The shipped moving recordings and their sensor presets (as benchmark/bench_odometry.py).
MOVING = {'rplidar_barc_moving': 'rplidar_a2', 'mrpt_malaga_moving': None,
          'tuw_gh25_moving': None}
SCANS = 200
POSE_TOLERANCE = 1e-5           # m and rad
COVARIANCE_TOLERANCE = 1e-4     # of the largest element


def recording(name, scans=SCANS):
    """Return a moving recording's first scans: (stamps s, landmarks, wheel priors)."""
    folder = DATA / name
    recorded = load_scans(folder, limit=scans)
    config = node_config(None, MOVING[name])
    stamps, landmarks = [], []
    for ranges, stamp_ns in zip(recorded.ranges[:scans], recorded.stamps_ns[:scans]):
        features = extract_features(ranges, recorded.angle_min, recorded.angle_increment,
                                    config, recorded.range_min, recorded.range_max)
        landmarks.append(landmarks_from_features(features, config.max_landmark_angle_sigma_rad))
        stamps.append(stamp_ns * 1e-9)
    # A wheel odometry: the reference robot's step with the model's covariance, on the laser.
    mount = load_without_aliases((folder / 'laser_mount.yaml').read_text())
    mount = np.array([mount['x_m'], mount['y_m'], mount['yaw_rad']])
    robot = poses_at(load_poses(folder / 'poses.csv'), np.array(stamps))
    wheel = [None]
    for before, after in zip(robot[:-1], robot[1:]):
        known = np.isfinite(before).all() and np.isfinite(after).all()
        step = compose(inverse(before), after) if known else None
        wheel.append(laser_prior(step, WheelModel().covariance(step), mount) if known else None)
    return stamps, landmarks, wheel


@pytest.fixture(scope='module')
def compiled_core():
    """Make the compiled core serve (loaded, or compiled, now); return the odometry's kernels."""
    kernels = runtime.compiled_kernels('odometry', True)
    assert kernels is not None
    return kernels


@pytest.fixture(scope='module')
def recordings(compiled_core):
    """Return every moving recording's first scans (:func:`recording`)."""
    return {name: recording(name) for name in MOVING}


def assert_chi2_close(compiled, reference, what):
    """Hold chi-squares to numpy's: inside the gate where it is, and there within 1e-12."""
    assert compiled.shape == reference.shape, what
    inside = reference <= odometry.CHI2_2DOF_99
    assert np.array_equal(compiled <= odometry.CHI2_2DOF_99, inside), what
    assert np.allclose(compiled[inside], reference[inside], rtol=1e-12, atol=0.0), what


def test_the_compiled_search_chi2_are_the_numpy_ones(compiled_core, recordings):
    compared = inside = outside_by_overlap = hypotheses = 0
    for name, (_, landmarks, _) in recordings.items():
        for previous, current in zip(landmarks[:40], landmarks[1:41]):
            steps = odometry._hypotheses(previous, current, OdometryConfig(), np.zeros((1, 3)))
            best = odometry._best_known(previous), odometry._best_known(current)
            ours = compiled_core.hypotheses(*odometry._arrays(best[0])[:4],
                                            *odometry._arrays(best[1])[:4])
            theirs = np.concatenate([odometry.corner_hypotheses(*best),
                                     odometry.line_hypotheses(*best),
                                     odometry.corner_line_hypotheses(*best)])
            assert ours.shape == theirs.shape, name
            assert np.allclose(ours, theirs, rtol=0.0, atol=1e-12), name
            hypotheses += len(theirs)
            corners, lines = odometry._search_chi2(previous, current, steps)
            prev, cur = odometry._arrays(previous), odometry._arrays(current)
            if corners is not None:
                twin = compiled_core._corner_chi2(prev[0], prev[1], cur[0], cur[1], steps,
                                                  odometry.SEARCH_SLACK_M ** 2, False)
                assert_chi2_close(twin, corners, (name, 'corners'))
                compared += corners.size
            if lines is not None:
                twin = compiled_core._line_chi2(
                    prev[2], prev[3], prev[4], cur[2], cur[3], cur[4], steps,
                    odometry.SEARCH_SLACK_RAD ** 2, odometry.SEARCH_SLACK_M ** 2, False)
                assert_chi2_close(twin, lines, (name, 'lines'))
                compared += lines.size
                inside += int((lines <= odometry.CHI2_2DOF_99).sum())
                # numpy's inf is a pair inside the gate that the overlap refused.
                outside_by_overlap += int(np.isinf(lines).sum())
            scores = odometry.score_hypotheses((corners, lines), len(steps))
            # The scores from each current landmark's least chi2, as the compiled search takes
            # them.
            twin_scores = np.zeros(len(steps))
            compiled_core._scores(compiled_core._corner_chi2(
                prev[0], prev[1], cur[0], cur[1], steps, odometry.SEARCH_SLACK_M ** 2, True),
                twin_scores)
            compiled_core._scores(compiled_core._line_chi2(
                prev[2], prev[3], prev[4], cur[2], cur[3], cur[4], steps,
                odometry.SEARCH_SLACK_RAD ** 2, odometry.SEARCH_SLACK_M ** 2, True), twin_scores)
            assert np.array_equal(twin_scores, scores), name
    assert compared > 1e5 and inside > 1000 and outside_by_overlap > 0 and hypotheses > 1e4, (
        compared, inside, outside_by_overlap, hypotheses)


def test_a_compiled_fit_of_a_well_posed_association_is_the_numpy_one(compiled_core,
                                                                     recordings):
    fits = 0
    _, landmarks, _ = recordings['mrpt_malaga_moving']
    for previous, current in zip(landmarks[:30], landmarks[1:31]):
        estimate = odometry.estimate_step(previous, current, np.zeros(3), np.eye(3),
                                          compiled=False)
        corners, lines = estimate.pairs
        if estimate.status != 'tracking':
            continue
        prior = (estimate.step + 0.01, np.diag([0.01, 0.01, 0.001]))
        for with_prior in (None, prior):
            ours = odometry._fit(compiled_core, previous, current, estimate.step + 0.02,
                                 corners, lines, with_prior)
            theirs = odometry.fit(previous, current, estimate.step + 0.02, corners, lines,
                                  with_prior)
            assert np.allclose(ours[0], theirs[0], rtol=0.0, atol=1e-9)
            assert np.allclose(ours[1], theirs[1], rtol=1e-9, atol=0.0)
            assert math.isclose(ours[2], theirs[2], rel_tol=1e-9, abs_tol=1e-12)
            fits += 1
    assert fits >= 20


@pytest.mark.parametrize('name', MOVING)
@pytest.mark.parametrize('reference', ['keyframe', 'scan to scan', 'wheel'])
def test_the_compiled_odometry_gives_the_numpy_ones_trajectory(name, reference, recordings):
    stamps, landmarks, wheel = recordings[name]
    config = (OdometryConfig(keyframe_m=0.0, keyframe_rad=0.0) if reference == 'scan to scan'
              else OdometryConfig())
    priors = wheel if reference == 'wheel' else [None] * len(stamps)
    ours, theirs = Odometry(config, compiled=True), Odometry(config, compiled=False)
    matched = 0
    for k, (stamp, scan, prior) in enumerate(zip(stamps, landmarks, priors)):
        a, b = ours.update(stamp, scan, prior), theirs.update(stamp, scan, prior)
        assert (a.status, a.corners, a.lines, a.prior_source, a.prior_rejected) == (
            b.status, b.corners, b.lines, b.prior_source, b.prior_rejected), k
        for field in ('pose', 'step'):
            assert np.abs(getattr(a, field) - getattr(b, field)).max() <= POSE_TOLERANCE, (
                k, field)
        for field in ('pose_covariance', 'step_covariance'):
            reference_value = getattr(b, field)
            assert np.abs(getattr(a, field) - reference_value).max() <= (
                COVARIANCE_TOLERANCE * np.abs(reference_value).max()), (k, field)
        matched += a.status in ('tracking', 'degenerate')
    assert matched >= 0.5 * len(stamps)


def test_the_odometry_runs_the_compiled_twin_while_the_compiled_core_serves(
        compiled_core, recordings, monkeypatch):
    calls = []
    search = compiled_core.search
    monkeypatch.setattr(compiled_core, 'search',
                        lambda *args: calls.append(1) or search(*args))
    stamps, landmarks, _ = recordings['tuw_gh25_moving']
    for compiled, expected in ((False, 0), (None, 2)):
        calls.clear()
        run = Odometry(compiled=compiled)
        for stamp, scan in zip(stamps[:3], landmarks[:3]):
            run.update(stamp, scan)
        assert len(calls) == expected
