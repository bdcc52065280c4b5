# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A scan's landmarks (corners and line landmarks) and their move into another frame.

What the re-observation test (:mod:`wctls_ros.evaluation.reobservation`) and the odometry
(:mod:`.odometry`) share: the landmarks as a front end takes them from the features, and the
first-order propagation of their covariances, with a pose's, into the frame of that pose
(docs/odometry.md#moving-landmarks). Pure numpy.
"""

from dataclasses import dataclass
import math

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


def wrap(angle):
    """Return angles wrapped into (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, 2 * np.pi)


def to_world(landmarks: Landmarks, pose: np.ndarray, pose_cov: np.ndarray):
    """
    Move one scan's landmarks into the world frame, their covariances with the pose's.

    :param landmarks: the scan's landmarks in the sensor frame
    :param pose: the sensor's pose (x m, y m, yaw rad)
    :param pose_cov: its covariance, shape (3, 3)
    :return: (corner xy (C, 2), their covariances (C, 2, 2), lines (L, 2), theirs (L, 2, 2))
    """
    x, y, yaw = pose
    turn = rotation(yaw)
    xy = moved(landmarks.corner_xy, pose)
    # d(world xy) / d(x, y, yaw)
    pose_jacobian = np.zeros((len(xy), 2, 3))
    pose_jacobian[:, :, :2] = np.eye(2)
    pose_jacobian[:, 0, 2] = -(xy[:, 1] - y)
    pose_jacobian[:, 1, 2] = xy[:, 0] - x
    corner_cov = (turn @ landmarks.corner_cov @ turn.T
                  + pose_jacobian @ pose_cov @ pose_jacobian.transpose(0, 2, 1))
    angle = landmarks.line[:, 0] + yaw
    radius = landmarks.line[:, 1] + x * np.cos(angle) + y * np.sin(angle)
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
    line_cov = (line_jacobian @ landmarks.line_cov @ line_jacobian.transpose(0, 2, 1)
                + line_pose @ pose_cov @ line_pose.transpose(0, 2, 1))
    flip = radius < 0.0                  # the normal points from the origin to the line
    radius = np.where(flip, -radius, radius)
    angle = wrap(np.where(flip, angle + np.pi, angle))
    line_cov[flip, 0, 1] *= -1.0
    line_cov[flip, 1, 0] *= -1.0
    return xy, corner_cov, np.column_stack([angle, radius]), line_cov


def rotation(yaw: float) -> np.ndarray:
    """Return the 2D rotation by yaw (rad)."""
    cos, sin = math.cos(yaw), math.sin(yaw)
    return np.array([[cos, -sin], [sin, cos]])


def moved(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Return points of the sensor frame (..., 2) in the world frame of pose (x, y, yaw)."""
    return points @ rotation(pose[2]).T + pose[:2]


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


def finite_only(landmarks: Landmarks) -> Landmarks:
    """
    Return the landmarks whose values and covariances are all finite.

    :param landmarks: a scan's landmarks
    :return: the finite ones (corner_lines of a dropped line become -1)
    """
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
