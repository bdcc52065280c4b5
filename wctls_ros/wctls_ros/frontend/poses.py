# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A sensor's poses by time: read from a pose file, interpolated to the scans' stamps.

A pose file is a CSV with the header ``stamp_s,x_m,y_m,yaw_rad`` (the robot's pose in a fixed
frame, by time); the sensor's pose on the robot is composed with the interpolated pose. What
``score`` compares a moving sensor's landmarks with and what ``process_bag --tracks`` moves its
tracks by. Pure numpy.
"""

import csv

import numpy as np

# The pose file's columns.
POSE_COLUMNS = ('stamp_s', 'x_m', 'y_m', 'yaw_rad')


class PoseError(ValueError):
    """Poses that cannot be read, or that do not cover the scans."""


def load_poses(path) -> np.ndarray:
    """
    Read a pose file: CSV with a header ``stamp_s,x_m,y_m,yaw_rad``, one row per pose.

    :param path: the file
    :return: shape (P, 4): stamp s, x m, y m, yaw rad, by stamp
    :raises PoseError: on an unreadable file, missing columns or values that are not numbers
    """
    try:
        with open(path, newline='') as stream:
            reader = csv.DictReader(stream)
            missing = [c for c in POSE_COLUMNS if c not in (reader.fieldnames or ())]
            if missing:
                raise PoseError(f'{path}: the pose file needs the columns '
                                f'{",".join(POSE_COLUMNS)}; {",".join(missing)} missing')
            rows = [[float(row[c]) for c in POSE_COLUMNS] for row in reader]
    except OSError as error:
        raise PoseError(f'{path}: cannot read the pose file: {error.strerror or error}') \
            from error
    except (TypeError, ValueError) as error:
        if isinstance(error, PoseError):
            raise
        raise PoseError(f'{path}: a value of the pose file is not a number ({error})') \
            from error
    poses = np.array(rows, dtype=float).reshape(-1, 4)
    if len(poses) < 2 or not np.isfinite(poses).all():
        raise PoseError(f'{path}: the pose file needs at least 2 rows of finite numbers')
    return poses[np.argsort(poses[:, 0], kind='stable')]


def poses_at(poses: np.ndarray, stamps_s: np.ndarray, offset=(0.0, 0.0, 0.0)):
    """
    Interpolate the poses to the scans' stamps, and compose the sensor's offset.

    :param poses: rows of stamp s, x m, y m, yaw rad, by stamp
    :param stamps_s: the scans' stamps, s
    :param offset: the sensor's pose in the posed frame (x m, y m, yaw rad)
    :return: the sensor pose at each stamp (x m, y m, yaw rad), shape (T, 3); NaN where the
        stamp is outside the poses' span
    """
    covered = (stamps_s >= poses[0, 0]) & (stamps_s <= poses[-1, 0])
    at = stamps_s[covered]
    yaw = np.interp(at, poses[:, 0], np.unwrap(poses[:, 3]))
    x = np.interp(at, poses[:, 0], poses[:, 1])
    y = np.interp(at, poses[:, 0], poses[:, 2])
    dx, dy, dyaw = offset
    sensor = np.full((len(stamps_s), 3), np.nan)
    sensor[covered] = np.column_stack([x + np.cos(yaw) * dx - np.sin(yaw) * dy,
                                       y + np.sin(yaw) * dx + np.cos(yaw) * dy,
                                       np.angle(np.exp(1j * (yaw + dyaw)))])
    return sensor
