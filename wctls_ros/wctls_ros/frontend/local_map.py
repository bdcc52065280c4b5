# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The odometry's local map: the recent scans' corners and lines fused in odom, one covariance.

Each scan is matched against the map moved into the previous scan's frame instead of against
that scan alone: a landmark seen over many scans is known better than one scan knows it, and
the pose no longer drifts as the sum of independent steps (docs/odometry.md#local-map).

**One joint covariance.** The map's landmarks share the past poses' errors (each was put where
a pose said), and the last pose shares theirs. The state is s = (X_last, m_1 ... m_n): the
last scan's pose in odom and every landmark's value in odom (a corner's x, y; a line's normal
form), with one full covariance P over all of it. Every scan moves it by one linear map to
first order, s' = T (s, e, p), e the current landmarks' noise and p the prior's; then
P' = T diag(P, R, P_p) T^T. Nothing is taken as independent that is not: the match uses the
landmarks' covariance relative to the last pose (the common error of map and pose cancels
there), the step's covariance is that of the match as a function of (s, e, p), and the pose's
the first block of P'.

- the match: the step x (the current pose in the last one's frame) minimises the fit of
  :func:`.odometry.fit` against the map in the last frame, m' = g(X_last, m). Its first-order
  sensitivity at the optimum, from sum J^T W r + P^-1 (x - x_p) = 0:
  dx = -H^-1 sum J_k^T W_k (dr_k/dm' dm'_k + dr_k/de de_k) + H^-1 P^-1 dp, H the information
  with the prior's where it joined;
- the pose: X = X_last (+) x;
- the fusion: an associated landmark becomes m + K (z - m), z the observation moved into odom
  by X, K the gain of the map's relative covariance against the observation's (any fixed gain
  keeps P exact; this one weighs them as the match does); a landmark not associated joins the
  map as z. Landmarks unseen for ``memory_scans`` scans, or seen once and then missed, leave
  it (their rows and columns of P: marginalised).

Pure numpy, no ROS. Units SI: m, rad.
"""

from typing import Optional, Sequence, Tuple

import numpy as np

from .frames import (Landmarks, rotation, spanned, step_corners, step_lines, step_points,
                     to_world_points, wrap_angle)


def _world_corners(xy: np.ndarray, pose: np.ndarray):
    """Return corners of a sensor frame in odom, d / d corner (2, 2), d / d pose (C, 2, 3)."""
    turn = rotation(pose[2])
    world = xy @ turn.T + pose[:2]
    by_pose = np.zeros((len(xy), 2, 3))
    by_pose[:, 0, 0] = by_pose[:, 1, 1] = 1.0
    by_pose[:, 0, 2] = -(world[:, 1] - pose[1])
    by_pose[:, 1, 2] = world[:, 0] - pose[0]
    return world, turn, by_pose


def _world_lines(line: np.ndarray, pose: np.ndarray):
    """
    Return lines of a sensor frame in odom, d / d line (L, 2, 2), d / d pose (L, 2, 3).

    (alpha + yaw, r + x cos + y sin) of the moved angle: no flip, so that one wall seen from
    one side has one value in odom whatever the sensor's pose.
    """
    angle = line[:, 0] + pose[2]
    cos, sin = np.cos(angle), np.sin(angle)
    lever = -pose[0] * sin + pose[1] * cos
    by_line = np.zeros((len(line), 2, 2))
    by_line[:, 0, 0] = by_line[:, 1, 1] = 1.0
    by_line[:, 1, 0] = lever
    by_pose = np.zeros((len(line), 2, 3))
    by_pose[:, 0, 2] = 1.0
    by_pose[:, 1, 0] = cos
    by_pose[:, 1, 1] = sin
    by_pose[:, 1, 2] = lever
    return (np.column_stack([wrap_angle(angle), line[:, 1] + pose[0] * cos + pose[1] * sin]),
            by_line, by_pose)


class LocalMap:
    """
    The recent scans' landmarks in odom and the last pose, with one joint covariance.

    :ivar pose: the last scan's pose in odom (x m, y m, yaw rad)
    :ivar covariance: the joint covariance of (pose, corners, lines), shape (3 + 2 n, 3 + 2 n)
    """

    def __init__(self, pose: np.ndarray, pose_covariance: np.ndarray, landmarks: Landmarks,
                 memory_scans: int):
        """
        Start a map from one scan's landmarks at its pose.

        :param pose: the scan's pose in odom (x m, y m, yaw rad)
        :param pose_covariance: its covariance, shape (3, 3)
        :param landmarks: the scan's landmarks in its sensor frame
        :param memory_scans: a landmark unseen for this many scans leaves the map
        """
        self.memory_scans = memory_scans
        self.pose = np.asarray(pose, dtype=float).copy()
        self.covariance = np.asarray(pose_covariance, dtype=float).copy()
        self.corner_xy = np.zeros((0, 2))
        self.line = np.zeros((0, 2))
        self.line_ends = np.zeros((0, 2, 2))
        self._corner_seen = np.zeros(0, dtype=np.intp)
        self._corner_hits = np.zeros(0, dtype=np.intp)
        self._line_seen = np.zeros(0, dtype=np.intp)
        self._line_hits = np.zeros(0, dtype=np.intp)
        self._scan = 0
        self.update((self.pose.copy(), np.eye(3), np.eye(3)), np.zeros((3, 0)),
                    np.zeros((3, 2 * _count(landmarks))), noise_covariance(landmarks), landmarks,
                    [], [], self.in_frame()[0], np.zeros((0, 3)))

    @property
    def size(self) -> int:
        """Return the landmarks in the map."""
        return len(self.corner_xy) + len(self.line)

    def _blocks(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return the state's column index of each corner's and each line's first coordinate."""
        corners = 3 + 2 * np.arange(len(self.corner_xy))
        return corners, 3 + 2 * len(self.corner_xy) + 2 * np.arange(len(self.line))

    def in_frame(self) -> Tuple[Landmarks, np.ndarray]:
        """
        Return the map moved into the last scan's frame, with the covariances relative to it.

        m' = g(X_last, m); a landmark's 2x2 covariance is E P E^T over its own and the pose's
        columns, E = [dg/dX, dg/dm]: the error the map and the pose share cancels.

        :return: (the landmarks, the Jacobian of every moved value by the state, shape
            (2 n, 3 + 2 n), corners first)
        """
        corner_index, line_index = self._blocks()
        size = len(self.covariance)
        jacobian = np.zeros((2 * self.size, size))
        corners, by_corner, by_step = step_corners(
            np.column_stack([self.corner_xy, np.zeros(len(self.corner_xy))]), self.pose)
        xy = corners[:, :2]
        count = len(self.corner_xy)
        for k, column in enumerate(corner_index):
            jacobian[2 * k:2 * k + 2, column:column + 2] = by_corner[k, :2, :2]
            jacobian[2 * k:2 * k + 2, :3] = by_step[k, :2]
        line, by_line, by_pose = step_lines(self.line, self.pose)
        for k, column in enumerate(line_index):
            row = 2 * (count + k)
            jacobian[row:row + 2, column:column + 2] = by_line[k]
            jacobian[row:row + 2, :3] = by_pose[k]
        moved = jacobian @ self.covariance @ jacobian.T
        blocks = np.array([moved[2 * k:2 * k + 2, 2 * k:2 * k + 2] for k in range(self.size)]
                          ).reshape(-1, 2, 2)
        ends = step_points(self.line_ends, self.pose)
        return (Landmarks(xy, blocks[:count], np.full((count, 2), -1), line, blocks[count:],
                          ends), jacobian)

    def update(self, moved: Tuple[np.ndarray, np.ndarray, np.ndarray], by_map: np.ndarray,
               by_noise: np.ndarray,
               noise_covariance: np.ndarray, landmarks: Landmarks,
               corner_pairs: Sequence[Tuple[int, int]], line_pairs: Sequence[Tuple[int, int]],
               frame: Landmarks, frame_jacobian: np.ndarray) -> np.ndarray:
        """
        Take a scan matched against :meth:`in_frame`: move the pose on, fuse, add, forget.

        :param moved: the scan's pose in odom, X_last (+) x for its step x from the last scan,
            and that composition's Jacobians by X_last and by x (3x3 each)
        :param by_map: d step / d(the moved map's values), shape (3, 2 n), corners first
        :param by_noise: d step / d(the noise: the scan's corners, its lines, the prior),
            shape (3, N)
        :param noise_covariance: the noise's covariance, shape (N, N), its first columns the
            scan's corners' (2 each), then its lines' (2 each), then any prior's
        :param landmarks: the scan's landmarks in its frame
        :param corner_pairs: (map index, scan index) of the associated corners
        :param line_pairs: (map index, scan index) of the associated lines
        :param frame: :meth:`in_frame`'s landmarks (the gain's relative covariances)
        :param frame_jacobian: :meth:`in_frame`'s Jacobian
        :return: the step's covariance, shape (3, 3)
        """
        by_state = by_map @ frame_jacobian
        size, noise = len(self.covariance), len(noise_covariance)
        width = size + noise
        # d step / d(state, noise), and the step's covariance.
        step_map = np.hstack([by_state, by_noise])
        joint = np.zeros((width, width))
        joint[:size, :size] = self.covariance
        joint[size:, size:] = noise_covariance
        step_covariance = step_map @ joint @ step_map.T
        pose, by_last, by_step = moved
        pose_row = by_step @ step_map
        pose_row[:, :3] += by_last
        self._scan += 1
        corner_index, line_index = self._blocks()
        corner_noise = size + 2 * np.arange(len(landmarks.corner_xy))
        line_noise = size + 2 * len(landmarks.corner_xy) + 2 * np.arange(len(landmarks.line))
        # The map's rows as it was, then the associated landmarks fused.
        corner_rows = np.zeros((len(self.corner_xy), 2, width))
        for k, column in enumerate(corner_index):
            corner_rows[k][:, column:column + 2] = np.eye(2)
        line_rows = np.zeros((len(self.line), 2, width))
        for k, column in enumerate(line_index):
            line_rows[k][:, column:column + 2] = np.eye(2)
        world_xy, turn, corner_by_pose = _world_corners(landmarks.corner_xy, pose)
        world_line, line_by_line, line_by_pose = _world_lines(landmarks.line, pose)
        world_ends = to_world_points(landmarks.line_ends, pose)

        def corner_observation(c: int) -> np.ndarray:
            row = corner_by_pose[c] @ pose_row
            row[:, corner_noise[c]:corner_noise[c] + 2] += turn
            return row

        def line_observation(c: int) -> np.ndarray:
            row = line_by_pose[c] @ pose_row
            row[:, line_noise[c]:line_noise[c] + 2] += line_by_line[c]
            return row

        for m, c in corner_pairs:
            # The gain of the relative covariances (as the match weighs them), in odom.
            relative = turn @ frame.corner_cov[m] @ turn.T
            observed = turn @ landmarks.corner_cov[c] @ turn.T
            gain = relative @ np.linalg.inv(relative + observed)
            self.corner_xy[m] = self.corner_xy[m] + gain @ (world_xy[c] - self.corner_xy[m])
            corner_rows[m] = (np.eye(2) - gain) @ corner_rows[m] + gain @ corner_observation(c)
            self._corner_seen[m] = self._scan
            self._corner_hits[m] += 1
        for m, c in line_pairs:
            relative = line_by_line[c] @ frame.line_cov[m] @ line_by_line[c].T
            observed = line_by_line[c] @ landmarks.line_cov[c] @ line_by_line[c].T
            gain = relative @ np.linalg.inv(relative + observed)
            innovation = world_line[c] - self.line[m]
            innovation[0] = float(wrap_angle(innovation[0]))
            self.line[m] = self.line[m] + gain @ innovation
            self.line[m, 0] = float(wrap_angle(self.line[m, 0]))
            line_rows[m] = (np.eye(2) - gain) @ line_rows[m] + gain @ line_observation(c)
            self.line_ends[m] = spanned(world_ends[c], self.line_ends[m])
            self._line_seen[m] = self._scan
            self._line_hits[m] += 1
        keep_corners = self._kept(self._corner_seen, self._corner_hits)
        keep_lines = self._kept(self._line_seen, self._line_hits)
        new_corners = sorted(set(range(len(landmarks.corner_xy))) - {c for _, c in corner_pairs})
        new_lines = sorted(set(range(len(landmarks.line))) - {c for _, c in line_pairs})
        # The new state: the pose, the corners kept and new, the lines kept and new.
        transform = np.vstack([pose_row, corner_rows[keep_corners].reshape(-1, width)]
                              + [corner_observation(c) for c in new_corners]
                              + [line_rows[keep_lines].reshape(-1, width)]
                              + [line_observation(c) for c in new_lines])
        covariance = transform @ joint @ transform.T
        self.covariance = 0.5 * (covariance + covariance.T)
        self.pose = pose
        self.corner_xy = np.concatenate([self.corner_xy[keep_corners],
                                         world_xy[new_corners].reshape(-1, 2)])
        self._corner_seen = np.concatenate([self._corner_seen[keep_corners],
                                            np.full(len(new_corners), self._scan)])
        self._corner_hits = np.concatenate([self._corner_hits[keep_corners],
                                            np.ones(len(new_corners), dtype=np.intp)])
        self.line = np.concatenate([self.line[keep_lines], world_line[new_lines].reshape(-1, 2)])
        self.line_ends = np.concatenate([self.line_ends[keep_lines],
                                         world_ends[new_lines].reshape(-1, 2, 2)])
        self._line_seen = np.concatenate([self._line_seen[keep_lines],
                                          np.full(len(new_lines), self._scan)])
        self._line_hits = np.concatenate([self._line_hits[keep_lines],
                                          np.ones(len(new_lines), dtype=np.intp)])
        return 0.5 * (step_covariance + step_covariance.T)

    def _kept(self, seen: np.ndarray, hits: np.ndarray) -> np.ndarray:
        """Return which landmarks stay: seen within the memory, and not a transient."""
        missed = self._scan - seen
        return (missed < self.memory_scans) & ~((hits <= 1) & (missed >= 1))


def _count(landmarks: Landmarks) -> int:
    """Return a scan's landmarks."""
    return len(landmarks.corner_xy) + len(landmarks.line)


def noise_covariance(landmarks: Landmarks,
                     prior_covariance: Optional[np.ndarray] = None) -> np.ndarray:
    """
    Return the covariance of a scan's noise: its corners', its lines', then a prior's.

    :param landmarks: the scan's landmarks
    :param prior_covariance: a prior's covariance, shape (3, 3), or None
    :return: block diagonal, shape (2 C + 2 L (+ 3), same)
    """
    blocks = list(landmarks.corner_cov) + list(landmarks.line_cov)
    if prior_covariance is not None:
        blocks.append(prior_covariance)
    size = sum(len(b) for b in blocks)
    out = np.zeros((size, size))
    start = 0
    for block in blocks:
        out[start:start + len(block), start:start + len(block)] = block
        start += len(block)
    return out


def fit_sensitivity(jacobian: np.ndarray, weight: np.ndarray, information: np.ndarray,
                    prior_information: Optional[np.ndarray]) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return d step / d residual of each pair and d step / d prior step, at a fit's optimum.

    From sum J_k^T W_k r_k + P^-1 (x - x_p) = 0: dx = -H^-1 sum J_k^T W_k dr_k + H^-1 P^-1
    dx_p, H = sum J_k^T W_k J_k (+ P^-1).

    :param jacobian: dr_k / dx, shape (K, 2, 3)
    :param weight: W_k, shape (K, 2, 2)
    :param information: sum J^T W J, shape (3, 3)
    :param prior_information: P^-1 where a prior joined, else None
    :return: (d x / d r_k, shape (K, 3, 2); d x / d x_p, shape (3, 3), zero without a prior)
    """
    total = information if prior_information is None else information + prior_information
    inverse = np.linalg.inv(total)
    by_residual = -np.einsum('ab,kib,kij->kaj', inverse, jacobian, weight)
    by_prior = np.zeros((3, 3)) if prior_information is None else inverse @ prior_information
    return by_residual, by_prior
