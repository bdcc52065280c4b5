# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Landmarks moved between frames, with the Jacobians that carry their covariances along.

Two moves, both first order (docs/derivation.md, "Landmark tracks"):

- **into the world frame** by a sensor pose (x, y, yaw) with its covariance, as ``score``
  compares observations of a moving sensor (:func:`world_landmarks`);
- **into the next scan's sensor frame** by the step the sensor made since the previous scan,
  (dx_m, dy_m, dyaw_rad) in the previous scan's sensor frame (:func:`step_corners`,
  :func:`step_lines`): what the tracker predicts its landmarks with. A point p of the previous
  frame is p' = R(dyaw)^T (p - t) in the new one; a line (alpha, r) is
  (alpha - dyaw, r - dx cos alpha - dy sin alpha), its normal flipped to point away from the
  sensor when r' < 0.

Lines are in normal form: alpha the angle of the normal from the sensor towards the line, rad,
r >= 0 its distance, m. A scan's landmarks as a front end takes them from the features
(:class:`Landmarks`, :func:`landmarks_from_features`) are what the re-observation test and the
odometry (:mod:`.odometry`) move. Pure numpy.
"""

from dataclasses import dataclass
import math
from typing import Tuple

import numpy as np

from ..core import Features, line_landmarks


@dataclass(frozen=True)
class Landmarks:
    """
    The corners and lines of one scan in the sensor frame.

    :ivar corner_xy: corner positions, shape (C, 2), m
    :ivar corner_cov: their covariances, shape (C, 2, 2), m^2
    :ivar corner_lines: the two walls each corner joins, as indices into the lines, shape
        (C, 2) (-1: a wall that is not a line landmark)
    :ivar line: (normal angle rad, distance m) of each line landmark's infinite line, shape
        (L, 2)
    :ivar line_cov: their covariances, shape (L, 2, 2)
    :ivar line_ends: each line landmark's first and last end, shape (L, 2, 2), m
    """

    corner_xy: np.ndarray
    corner_cov: np.ndarray
    corner_lines: np.ndarray
    line: np.ndarray
    line_cov: np.ndarray
    line_ends: np.ndarray


def wrap_angle(angle):
    """
    Return angles wrapped into (-pi, pi].

    :param angle: angles, rad (any shape)
    :return: the same angles in (-pi, pi]
    """
    if isinstance(angle, float):
        # One angle in Python floats, the same value: numpy's remainder of floats and Python's
        # are one algorithm (fmod, then the divisor's sign), without numpy's cost per call.
        return math.pi - (math.pi - angle) % (2.0 * math.pi)
    return np.pi - np.mod(np.pi - angle, 2 * np.pi)


def rotation(yaw: float) -> np.ndarray:
    """
    Return the 2D rotation by yaw.

    :param yaw: the angle, rad
    :return: shape (2, 2)
    """
    cos, sin = math.cos(yaw), math.sin(yaw)
    return np.array([[cos, -sin], [sin, cos]])


def to_world_points(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """
    Return points of the sensor frame in the world frame of a sensor pose.

    :param points: shape (..., 2), m
    :param pose: the sensor's pose (x m, y m, yaw rad)
    :return: shape (..., 2), m
    """
    return points @ rotation(pose[2]).T + pose[:2]


def world_landmarks(corner_xy: np.ndarray, corner_cov: np.ndarray, line: np.ndarray,
                    line_cov: np.ndarray, pose: np.ndarray, pose_cov: np.ndarray):
    """
    Move one scan's corners and lines into the world frame, their covariances with the pose's.

    :param corner_xy: corner positions in the sensor frame, shape (C, 2), m
    :param corner_cov: their covariances, shape (C, 2, 2), m^2
    :param line: (normal angle rad, distance m) of each line, shape (L, 2)
    :param line_cov: their covariances, shape (L, 2, 2)
    :param pose: the sensor's pose (x m, y m, yaw rad)
    :param pose_cov: its covariance, shape (3, 3)
    :return: (corner xy (C, 2), their covariances (C, 2, 2), lines (L, 2), theirs (L, 2, 2))
    """
    x, y, yaw = pose
    turn = rotation(yaw)
    xy = to_world_points(corner_xy, pose)
    # d(world xy) / d(x, y, yaw)
    pose_jacobian = np.zeros((len(xy), 2, 3))
    pose_jacobian[:, :, :2] = np.eye(2)
    pose_jacobian[:, 0, 2] = -(xy[:, 1] - y)
    pose_jacobian[:, 1, 2] = xy[:, 0] - x
    world_corner_cov = (turn @ corner_cov @ turn.T
                        + pose_jacobian @ pose_cov @ pose_jacobian.transpose(0, 2, 1))
    angle = line[:, 0] + yaw
    radius = line[:, 1] + x * np.cos(angle) + y * np.sin(angle)
    # d(world angle, radius) / d(angle, radius) and / d(x, y, yaw)
    lever = -x * np.sin(angle) + y * np.cos(angle)
    line_jacobian = np.zeros((len(angle), 2, 2))
    line_jacobian[:, 0, 0] = 1.0
    line_jacobian[:, 1, 0] = lever
    line_jacobian[:, 1, 1] = 1.0
    line_pose = np.zeros((len(angle), 2, 3))
    line_pose[:, 0, 2] = 1.0
    line_pose[:, 1, 0] = np.cos(angle)
    line_pose[:, 1, 1] = np.sin(angle)
    line_pose[:, 1, 2] = lever
    world_line_cov = (line_jacobian @ line_cov @ line_jacobian.transpose(0, 2, 1)
                      + line_pose @ pose_cov @ line_pose.transpose(0, 2, 1))
    flip = radius < 0.0                  # the normal points from the origin to the line
    radius = np.where(flip, -radius, radius)
    angle = wrap_angle(np.where(flip, angle + np.pi, angle))
    world_line_cov[flip, 0, 1] *= -1.0
    world_line_cov[flip, 1, 0] *= -1.0
    return xy, world_corner_cov, np.column_stack([angle, radius]), world_line_cov


def step_points(points: np.ndarray, step: np.ndarray) -> np.ndarray:
    """
    Return points of the previous sensor frame in the frame after a step.

    :param points: shape (..., 2), m
    :param step: the sensor's step (dx m, dy m, dyaw rad) in the previous frame
    :return: R(dyaw)^T (p - t), shape (..., 2), m
    """
    return (points - step[:2]) @ rotation(step[2])


def step_corners(pose: np.ndarray, step: np.ndarray) -> Tuple[np.ndarray, np.ndarray,
                                                              np.ndarray]:
    """
    Return corners (x, y, yaw) of the previous sensor frame in the frame after a step.

    :param pose: the corners, shape (C, 3): x m, y m, yaw rad
    :param step: the sensor's step (dx m, dy m, dyaw rad) in the previous frame
    :return: (the moved corners (C, 3), d moved / d corner (C, 3, 3), d moved / d step
        (C, 3, 3))
    """
    cos, sin = math.cos(step[2]), math.sin(step[2])
    turn_back = np.array([[cos, sin], [-sin, cos]])              # R(dyaw)^T
    turn_back_d_yaw = np.array([[-sin, cos], [-cos, -sin]])      # d R(dyaw)^T / d dyaw
    offset = pose[:, :2] - step[:2]
    moved = np.column_stack([offset @ turn_back.T, wrap_angle(pose[:, 2] - step[2])])
    by_corner = np.zeros((len(pose), 3, 3))
    by_corner[:, :2, :2] = turn_back
    by_corner[:, 2, 2] = 1.0
    by_step = np.zeros((len(pose), 3, 3))
    by_step[:, :2, :2] = -turn_back
    by_step[:, :2, 2] = offset @ turn_back_d_yaw.T
    by_step[:, 2, 2] = -1.0
    return moved.reshape(-1, 3), by_corner, by_step


def step_lines(line: np.ndarray, step: np.ndarray) -> Tuple[np.ndarray, np.ndarray,
                                                            np.ndarray]:
    """
    Return lines (alpha, r) of the previous sensor frame in the frame after a step.

    :param line: the lines, shape (L, 2): normal angle rad, distance m
    :param step: the sensor's step (dx m, dy m, dyaw rad) in the previous frame
    :return: (the moved lines (L, 2), d moved / d line (L, 2, 2), d moved / d step (L, 2, 3))
    """
    dx, dy, dyaw = step
    cos, sin = np.cos(line[:, 0]), np.sin(line[:, 0])
    radius = line[:, 1] - dx * cos - dy * sin
    by_line = np.zeros((len(line), 2, 2))
    by_line[:, 0, 0] = 1.0
    by_line[:, 1, 0] = dx * sin - dy * cos
    by_line[:, 1, 1] = 1.0
    by_step = np.zeros((len(line), 2, 3))
    by_step[:, 0, 2] = -1.0
    by_step[:, 1, 0] = -cos
    by_step[:, 1, 1] = -sin
    flip = radius < 0.0            # the sensor crossed the line: the normal turns round
    by_line[flip, 1] *= -1.0
    by_step[flip, 1] *= -1.0
    angle = wrap_angle(np.where(flip, line[:, 0] - dyaw + np.pi, line[:, 0] - dyaw))
    return np.column_stack([angle, np.abs(radius)]).reshape(-1, 2), by_line, by_step


def relative_step(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """
    Return the step from one sensor pose to the next, in the first pose's frame.

    :param before: the first pose (x m, y m, yaw rad) in a fixed frame
    :param after: the second pose in the same frame
    :return: (dx m, dy m, dyaw rad): the second pose in the first's frame
    """
    dx, dy = rotation(before[2]).T @ (np.asarray(after[:2]) - before[:2])
    return np.array([dx, dy, float(wrap_angle(after[2] - before[2]))])


def overlapping(ends: np.ndarray, track_ends: np.ndarray) -> np.ndarray:
    """
    Return which segments overlap which tracks' stretches of wall, along each segment's line.

    :param ends: the segments' ends, shape (N, 2, 2), m
    :param track_ends: the ends of the stretch each track has seen, shape (K, 2, 2), m
    :return: shape (N, K): the two extents share a stretch of positive length
    """
    direction = ends[:, 1] - ends[:, 0]
    direction = direction / np.maximum(np.linalg.norm(direction, axis=1), 1e-12)[:, None]
    own = np.sort(np.einsum('nei,ni->ne', ends, direction), axis=1)
    other = np.sort(np.einsum('kei,ni->nke', track_ends, direction), axis=2)
    return (np.minimum(own[:, None, 1], other[..., 1])
            > np.maximum(own[:, None, 0], other[..., 0]))


def spanned(ends: np.ndarray, track_ends: np.ndarray) -> np.ndarray:
    """
    Return segments' ends stretched over the stretch of their tracks seen before.

    :param ends: the segments' ends, shape (..., 2, 2), m
    :param track_ends: their tracks' ends, shape (..., 2, 2), m
    :return: the ends of the union of both extents along each segment's line, shape (..., 2, 2)
    """
    direction = ends[..., 1, :] - ends[..., 0, :]
    direction = direction / np.maximum(np.linalg.norm(direction, axis=-1), 1e-12)[..., None]
    along = np.einsum('...ei,...i->...e', np.concatenate([ends, track_ends], axis=-2),
                      direction)
    foot = ends[..., 0, :] - along[..., :1] * direction
    extent = np.stack([along.min(axis=-1), along.max(axis=-1)], axis=-1)
    return foot[..., None, :] + extent[..., None] * direction[..., None, :]


def to_world(landmarks: Landmarks, pose: np.ndarray, pose_cov: np.ndarray):
    """
    Move one scan's landmarks into the world frame, their covariances with the pose's.

    :param landmarks: the scan's landmarks in the sensor frame
    :param pose: the sensor's pose (x m, y m, yaw rad)
    :param pose_cov: its covariance, shape (3, 3)
    :return: (corner xy (C, 2), their covariances (C, 2, 2), lines (L, 2), theirs (L, 2, 2))
    """
    return world_landmarks(landmarks.corner_xy, landmarks.corner_cov, landmarks.line,
                           landmarks.line_cov, pose, pose_cov)


def finite_only(landmarks: Landmarks) -> Landmarks:
    """
    Return the landmarks whose values and covariances are all finite.

    :param landmarks: a scan's landmarks
    :return: the finite ones (corner_lines of a dropped line become -1)
    """
    values = (landmarks.corner_xy, landmarks.corner_cov, landmarks.line, landmarks.line_cov,
              landmarks.line_ends)
    if np.isfinite(np.concatenate([np.ravel(v) for v in values])).all():
        return landmarks                # every value finite (the usual scan): one pass
    corners = (np.isfinite(landmarks.corner_xy).all(axis=1)
               & np.isfinite(landmarks.corner_cov).all(axis=(1, 2)))
    lines = (np.isfinite(landmarks.line).all(axis=1)
             & np.isfinite(landmarks.line_cov).all(axis=(1, 2))
             & np.isfinite(landmarks.line_ends).all(axis=(1, 2)))
    if corners.all() and lines.all():
        return landmarks
    index = np.where(lines, np.cumsum(lines) - 1, -1)
    walls = landmarks.corner_lines[corners]
    walls = np.where(walls >= 0, index[np.maximum(walls, 0)], -1) if len(index) else walls
    return Landmarks(landmarks.corner_xy[corners], landmarks.corner_cov[corners], walls,
                     landmarks.line[lines], landmarks.line_cov[lines], landmarks.line_ends[lines])


def landmarks_from_features(features: Features, max_landmark_angle_sigma_rad: float,
                            covariance_scale: float = 1.0) -> Landmarks:
    """
    Return one scan's corners and line landmarks, as a front end of feature_node takes them.

    :param features: the core's Features of the scan
    :param max_landmark_angle_sigma_rad: the bound of the line landmark rule, rad
        (:func:`~wctls_ros.core.line_landmarks`): the other segments are no lines here
    :param covariance_scale: multiply every covariance by this (1: as the extractor gives them)
    :return: the landmarks (corner covariances: their position block)
    """
    corners = features.corners
    is_landmark = line_landmarks(features.segments, max_landmark_angle_sigma_rad)
    segments = features.segments.select(is_landmark)
    # Each segment's index among the landmarks (-1 for the others), for the corners' walls.
    line_index = np.where(is_landmark, np.cumsum(is_landmark) - 1, -1)
    walls = np.column_stack([corners.first_segment, corners.second_segment]).astype(np.intp)
    corner_cov = np.asarray(corners.covariance)[:, :2, :2].reshape(-1, 2, 2)
    return Landmarks(np.asarray(corners.xy_m, dtype=float).reshape(-1, 2),
                     covariance_scale * corner_cov,
                     line_index[walls].reshape(-1, 2),
                     np.column_stack([segments.angle_rad, segments.radius_m]).reshape(-1, 2),
                     covariance_scale * np.asarray(segments.covariance).reshape(-1, 2, 2),
                     np.stack([segments.start_xy_m, segments.end_xy_m], axis=1).reshape(-1, 2, 2))
