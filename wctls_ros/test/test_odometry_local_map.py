# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The odometry against a local map: its covariances by Monte Carlo, its Jacobians numerically.

Finite differences check the map's move into the last frame. The scene and its noisy
observations are those of test_frontend_odometry (landmarks drawn from their own covariances):
the truth is the simulated path. The map's landmarks share the past
poses' errors; the step's and the pose's covariances must hold all the same.
"""

import math

import numpy as np

from test_frontend_odometry import numeric_jacobian, observe
from wctls_ros.frontend.local_map import LocalMap
from wctls_ros.frontend.odometry import compose, inverse, Odometry, OdometryConfig

# A path through the room of test_frontend_odometry: 0.1 m and 3 deg per scan, then back.
STEP = np.array([0.1, 0.02, math.radians(3.0)])
SCANS = 16


def path():
    """Return the true poses of the path, shape (SCANS, 3)."""
    poses = [np.zeros(3)]
    for k in range(1, SCANS):
        poses.append(compose(poses[-1], STEP if k < SCANS // 2 else -STEP))
    return np.array(poses)


def run(config: OdometryConfig, rng):
    """Return the odometry's updates over the path, one noisy scan per pose."""
    odometry = Odometry(config)
    return [odometry.update(0.1 * k, observe(pose, rng)) for k, pose in enumerate(path())]


def nees(error, covariance):
    """Return e^T C^-1 e with the angle wrapped."""
    error = np.array(error, dtype=float)
    error[2] = math.remainder(error[2], 2 * math.pi)
    return float(error @ np.linalg.solve(covariance, error))


def test_the_step_and_pose_covariances_hold_against_the_map():
    """Monte Carlo over 200 runs: step and pose NEES are chi-squares of 3 dof."""
    rng = np.random.default_rng(11)
    truth = path()
    steps, poses, end_errors = [], [], []
    for _ in range(200):
        updates = run(OdometryConfig(map_memory_scans=10), rng)
        assert all(u.status == 'tracking' for u in updates[1:])
        for k in range(1, SCANS):
            steps.append(nees(updates[k].step - compose(inverse(truth[k - 1]), truth[k]),
                              updates[k].step_covariance))
            poses.append(nees(updates[k].pose - truth[k], updates[k].pose_covariance))
        end_errors.append(updates[-1].pose - truth[-1])
    steps, poses = np.array(steps), np.array(poses)
    assert 2.7 <= steps.mean() <= 3.3
    assert 0.93 <= np.mean(steps <= 7.815) <= 0.97
    assert 2.7 <= poses.mean() <= 3.3
    assert 0.93 <= np.mean(poses <= 7.815) <= 0.97
    # Every landmark in view all along: the end's error is one scan's, as its covariance says
    # (a sum of steps would grow as their count: scan to scan predicts 3-4 times as much).
    predicted = np.sqrt(np.diag(updates[-1].pose_covariance))
    ratio = np.std(end_errors, axis=0) / predicted
    assert np.all((0.8 <= ratio) & (ratio <= 1.2))


def test_a_still_sensor_does_not_drift_and_its_covariance_stops_growing():
    rng = np.random.default_rng(2)
    odometry = Odometry(OdometryConfig(map_memory_scans=10))
    updates = [odometry.update(0.1 * k, observe((0.0, 0.0, 0.0), rng)) for k in range(60)]
    assert all(u.status == 'tracking' for u in updates[1:])
    # Its error, the map's and the scan's own, stays within its covariance all along: no drift.
    errors = [nees(u.pose, u.pose_covariance) for u in updates[1:]]
    assert max(errors) < 16.27                                          # chi2 3 dof, 99.9 %
    # It settles: the last 20 scans' pose covariance grows by less than a tenth.
    assert np.trace(updates[-1].pose_covariance) < 1.1 * np.trace(updates[-21].pose_covariance)


def test_the_map_in_the_last_frame_moves_by_its_jacobian():
    rng = np.random.default_rng(4)
    landmarks = observe((0.3, -0.2, 0.4), rng)
    pose = np.array([0.3, -0.2, 0.4])
    local = LocalMap(pose, np.diag([1e-4, 2e-4, 1e-5]), landmarks, 10)
    _, jacobian = local.in_frame()

    def moved(state):
        other = LocalMap(pose, np.zeros((3, 3)), landmarks, 10)
        other.pose = state[:3]
        count = 2 * len(other.corner_xy)
        other.corner_xy = state[3:3 + count].reshape(-1, 2)
        other.line = state[3 + count:].reshape(-1, 2)
        frame, _ = other.in_frame()
        return np.concatenate([frame.corner_xy.ravel(), frame.line.ravel()])

    state = np.concatenate([local.pose, local.corner_xy.ravel(), local.line.ravel()])
    assert np.allclose(jacobian, numeric_jacobian(moved, state), atol=1e-6)
