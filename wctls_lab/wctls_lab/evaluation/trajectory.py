# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A trajectory against a reference: relative and absolute error, and its covariance's consistency.

- **RPE per metre**: pairs of poses (i, j) chosen on the reference (j the first pose at least
  ``delta_m`` of reference path after i, as evo's ``pairs_from_reference=True``); the error of
  the relative motion E = (ref_i^-1 ref_j)^-1 (est_i^-1 est_j), its translation |E_xy| and
  rotation |E_yaw| over the pair's reference path length: mean %/m and deg/m;
- **ATE**: RMS position error after the SE(2) alignment of the estimate onto the reference
  (least squares, no scale: evo's SE(3) alignment of a planar trajectory can return a mirror
  image);
- **per step**: the share of steps within 10 cm and 2 deg of the reference step;
- **step NEES**: e^T (C + C_ref)^-1 e of each step's error e (dx, dy, dyaw in the previous
  frame) with C the step's reported covariance and C_ref the reference's own: its per-pose
  jitter (sigma_m each axis, sigma_rad) propagated through ref_{k-1}^-1 ref_k from both poses
  (docs/odometry.md#evaluation); mean (3 when honest) and the share inside the 95 % gate
  (7.815, chi-square 3 dof);
- **standing still**: how far the estimate drifts over a recording of a still sensor.

Pure numpy.
"""

from dataclasses import dataclass
import math
import time
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from wctls_ros.core import extract_features, FeatureConfig
from wctls_ros.frontend.frames import landmarks_from_features, wrap_angle
from wctls_ros.frontend.odometry import (compose, compose_jacobians, inverse, inverse_jacobian,
                                         Odometry, OdometryConfig, Prior)

from .scans import StaticScans

GATE_3DOF_95 = 7.815
STEP_TOLERANCE_M = 0.10
STEP_TOLERANCE_RAD = math.radians(2.0)


@dataclass(frozen=True)
class TrajectoryErrors:
    """
    How an estimated trajectory compares with its reference.

    :ivar steps: steps compared
    :ivar path_m: the reference's path length, m
    :ivar rpe_pairs: RPE pairs
    :ivar rpe_percent_per_m: mean translation error per metre of reference path, %
    :ivar rpe_deg_per_m: mean rotation error per metre, deg/m
    :ivar ate_m: RMS position error after SE(2) alignment, m
    :ivar steps_within: share of steps within 10 cm and 2 deg of the reference step
    :ivar nees_mean: mean step NEES (3 when honest)
    :ivar nees_in_gate: share of steps whose NEES lies inside the 95 % gate
    """

    steps: int
    path_m: float
    rpe_pairs: int
    rpe_percent_per_m: float
    rpe_deg_per_m: float
    ate_m: float
    steps_within: float
    nees_mean: float
    nees_in_gate: float

    def summary(self) -> Dict[str, float]:
        """
        Return the figures by name.

        :return: field -> value
        """
        return {name: float(getattr(self, name)) for name in self.__dataclass_fields__}

    def lines(self) -> List[str]:
        """
        Return the figures as text lines.

        :return: one line per kind of figure
        """
        return [f'trajectory: {self.steps} steps over {self.path_m:.2f} m of reference path',
                f'RPE over {self.rpe_pairs} pairs of >= 1 m: {self.rpe_percent_per_m:.2f} %/m, '
                f'{self.rpe_deg_per_m:.2f} deg/m; ATE (SE(2) aligned) {self.ate_m:.3f} m',
                f'steps within 10 cm and 2 deg: {100 * self.steps_within:.1f} %; step NEES mean '
                f'{self.nees_mean:.2f} (3 = honest), {100 * self.nees_in_gate:.1f} % inside '
                'the 95 % gate']


def relative(poses: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """
    Return the motions from poses[first] to poses[second] in the frame of the first.

    :param poses: (x m, y m, yaw rad), shape (T, 3)
    :param first: indices, shape (K,)
    :param second: indices, shape (K,)
    :return: shape (K, 3)
    """
    return np.array([compose(inverse(poses[i]), poses[j]) for i, j in zip(first, second)]
                    ).reshape(-1, 3)


def align_se2(estimate_xy: np.ndarray, reference_xy: np.ndarray) -> np.ndarray:
    """
    Return the rigid SE(2) motion that best lays the estimate on the reference.

    :param estimate_xy: positions, shape (T, 2), m
    :param reference_xy: positions, shape (T, 2), m
    :return: (x m, y m, yaw rad) to compose before the estimate
    """
    mean_e, mean_r = estimate_xy.mean(axis=0), reference_xy.mean(axis=0)
    a, b = estimate_xy - mean_e, reference_xy - mean_r
    yaw = math.atan2(float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])),
                     float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
    cos, sin = math.cos(yaw), math.sin(yaw)
    moved = np.array([cos * mean_e[0] - sin * mean_e[1], sin * mean_e[0] + cos * mean_e[1]])
    return np.array([*(mean_r - moved), yaw])


def reference_step_covariance(reference: np.ndarray, k: int, sigma_m: float,
                              sigma_rad: float) -> np.ndarray:
    """
    Return the covariance of the reference's step k-1 -> k from its per-pose jitter.

    :param reference: reference poses, shape (T, 3)
    :param k: the step's second pose (>= 1)
    :param sigma_m: the reference poses' position jitter, each axis, m
    :param sigma_rad: their heading jitter, rad
    :return: shape (3, 3)
    """
    before, after = reference[k - 1], reference[k]
    by_first, by_second = compose_jacobians(inverse(before), after)
    jitter = np.diag([sigma_m ** 2, sigma_m ** 2, sigma_rad ** 2])
    by_before = by_first @ inverse_jacobian(before)
    return by_before @ jitter @ by_before.T + by_second @ jitter @ by_second.T


def trajectory_errors(estimate: np.ndarray, steps: np.ndarray, step_covariances: np.ndarray,
                      reference: np.ndarray, reference_sigma_m: float,
                      reference_sigma_rad: float, delta_m: float = 1.0) -> TrajectoryErrors:
    """
    Compare an estimated trajectory and its steps with the reference.

    :param estimate: estimated poses (x m, y m, yaw rad), shape (T, 3)
    :param steps: the estimate's step into each pose from the one before (row 0 unused),
        shape (T, 3)
    :param step_covariances: their covariances, shape (T, 3, 3)
    :param reference: the reference poses at the same stamps, shape (T, 3)
    :param reference_sigma_m: the reference's per-pose position jitter, each axis, m
    :param reference_sigma_rad: its heading jitter, rad
    :param delta_m: the RPE's reference path length per pair, m
    :return: the figures (NaN where nothing was compared)
    """
    estimate, reference = np.asarray(estimate, float), np.asarray(reference, float)
    count = len(reference)
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(reference[:, :2], axis=0).T))])
    first = np.arange(count)
    second = np.searchsorted(path, path + delta_m)
    keep = second < count
    first, second = first[keep], second[keep]
    trans, rot = [], []
    if len(first):
        ref_rel = relative(reference, first, second)
        est_rel = relative(estimate, first, second)
        error = np.array([compose(inverse(r), e) for r, e in zip(ref_rel, est_rel)])
        length = path[second] - path[first]
        trans = np.hypot(error[:, 0], error[:, 1]) / length
        rot = np.abs(wrap_angle(error[:, 2])) / length
    alignment = align_se2(estimate[:, :2], reference[:, :2]) if count >= 2 else np.zeros(3)
    aligned = np.array([compose(alignment, pose) for pose in estimate]).reshape(-1, 3)
    ate = (float(np.sqrt(np.mean(np.sum((aligned[:, :2] - reference[:, :2]) ** 2, axis=1))))
           if count else math.nan)
    ref_steps = relative(reference, np.arange(count - 1), np.arange(1, count))
    step_error = steps[1:] - ref_steps
    step_error[:, 2] = wrap_angle(step_error[:, 2])
    within = ((np.hypot(step_error[:, 0], step_error[:, 1]) <= STEP_TOLERANCE_M)
              & (np.abs(step_error[:, 2]) <= STEP_TOLERANCE_RAD))
    nees = np.array([e @ np.linalg.solve(c + reference_step_covariance(
        reference, k + 1, reference_sigma_m, reference_sigma_rad), e)
        for k, (e, c) in enumerate(zip(step_error, step_covariances[1:]))])

    def mean(values) -> float:
        return float(np.mean(values)) if len(values) else math.nan

    return TrajectoryErrors(count - 1, float(path[-1]) if count else 0.0, len(first),
                            100.0 * mean(trans), math.degrees(mean(rot)) if len(rot) else
                            math.nan, ate, mean(within), mean(nees),
                            mean(nees <= GATE_3DOF_95))


def drift(estimate: np.ndarray) -> np.ndarray:
    """
    Return how far the estimate of a still sensor lies from its start at each pose.

    :param estimate: estimated poses (x m, y m, yaw rad), shape (T, 3)
    :return: distance from the first pose, shape (T,), m
    """
    return np.hypot(estimate[:, 0] - estimate[0, 0], estimate[:, 1] - estimate[0, 1])


@dataclass(frozen=True)
class OdometryRun:
    """
    The odometry of a recording, scan by scan, in the laser's frame.

    :ivar stamps_s: each scan's stamp, shape (T,), s
    :ivar poses: the laser's pose in odom, shape (T, 3)
    :ivar pose_covariances: their covariances, shape (T, 3, 3)
    :ivar steps: the step into each scan from the one before, shape (T, 3)
    :ivar step_covariances: their covariances, shape (T, 3, 3)
    :ivar statuses: each scan's status
    :ivar odometry_s: the odometry's time per scan (the extraction left out), s
    :ivar prior_sources: the prior each scan's step took ('constant_velocity' or 'wheel')
    :ivar prior_rejected: whether the landmarks rejected the prior handed in with each scan
    """

    stamps_s: np.ndarray
    poses: np.ndarray
    pose_covariances: np.ndarray
    steps: np.ndarray
    step_covariances: np.ndarray
    statuses: Tuple[str, ...]
    odometry_s: float
    prior_sources: Tuple[str, ...] = ()
    prior_rejected: Tuple[bool, ...] = ()


def run_odometry(scans: StaticScans, config: FeatureConfig,
                 odometry_config: OdometryConfig = OdometryConfig(),
                 priors: Optional[Sequence[Optional[Prior]]] = None) -> OdometryRun:
    """
    Extract every scan's landmarks and run the odometry over them.

    :param scans: consecutive scans
    :param config: the pipeline configuration
    :param odometry_config: the odometry's settings
    :param priors: per scan, the laser's step from the scan before from another source
        (wheel odometry) with its covariance, or None (the constant velocity); None: none
    :return: the run
    """
    odometry = Odometry(odometry_config)
    updates, spent = [], 0.0
    for k, (ranges, stamp_ns) in enumerate(zip(scans.ranges, scans.stamps_ns)):
        features = extract_features(ranges, scans.angle_min, scans.angle_increment, config,
                                    scans.range_min, scans.range_max)
        landmarks = landmarks_from_features(features, config.max_landmark_angle_sigma_rad)
        prior = None if priors is None else priors[k]
        start = time.perf_counter()
        updates.append(odometry.update(stamp_ns * 1e-9, landmarks, prior))
        spent += time.perf_counter() - start

    def stacked(name: str, shape: Tuple[int, ...]) -> np.ndarray:
        return np.array([getattr(u, name) for u in updates]).reshape((-1,) + shape)

    return OdometryRun(stacked('stamp_s', ()), stacked('pose', (3,)),
                       stacked('pose_covariance', (3, 3)), stacked('step', (3,)),
                       stacked('step_covariance', (3, 3)), tuple(u.status for u in updates),
                       spent / max(len(updates), 1), tuple(u.prior_source for u in updates),
                       tuple(u.prior_rejected for u in updates))


def score_trajectory(scans: StaticScans, config: FeatureConfig, poses: np.ndarray,
                     sigma_m: float, sigma_rad: float,
                     odometry_config: OdometryConfig = OdometryConfig()) -> TrajectoryErrors:
    """
    Run the odometry over a recording and compare it with the sensor's reference poses.

    :param scans: consecutive scans
    :param config: the pipeline configuration
    :param poses: the sensor's reference pose at each scan, shape (T, 3), NaN rows where
        unknown (left out)
    :param sigma_m: the reference's per-pose position jitter, each axis, m
    :param sigma_rad: its heading jitter, rad
    :param odometry_config: the odometry's settings
    :return: the figures
    """
    run = run_odometry(scans, config, odometry_config)
    known = np.isfinite(poses).all(axis=1)
    return trajectory_errors(run.poses[known], run.steps[known], run.step_covariances[known],
                             poses[known], sigma_m, sigma_rad)
