# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The sensor's poses for ``score``: from a pose file or from odometry or TF in the bag.

A pose file is a CSV with the header ``stamp_s,x_m,y_m,yaw_rad`` (the robot's pose in a fixed
frame, by time). In a bag, a ``nav_msgs/msg/Odometry`` topic gives the pose of its child frame
in its frame; a ``tf2_msgs/msg/TFMessage`` topic (``/tf``) the transforms from one named frame to
another, taken directly (a chain of transforms is not composed). Either is interpolated to each
scan's stamp, and the sensor's pose on the robot composed with it.
"""

import csv
import math
import pathlib
from typing import Tuple

import numpy as np
from wctls_ros.frontend.poses import load_poses, POSE_COLUMNS, PoseError, poses_at

__all__ = ['load_poses', 'POSE_COLUMNS', 'PoseError', 'poses_at', 'poses_from_bag',
           'write_poses']

ODOMETRY = 'nav_msgs/msg/Odometry'
TF_MESSAGE = 'tf2_msgs/msg/TFMessage'


def write_poses(path, stamps_s: np.ndarray, poses: np.ndarray) -> pathlib.Path:
    """
    Write a pose file as :func:`load_poses` reads it.

    :param path: the file
    :param stamps_s: stamps, s, shape (T,)
    :param poses: x m, y m, yaw rad, shape (T, 3)
    :return: the path
    """
    path = pathlib.Path(path)
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(POSE_COLUMNS)
        writer.writerows([[f'{s:.9f}'] + [f'{v:.9f}' for v in pose]
                          for s, pose in zip(stamps_s, poses)])
    return path


def _yaw(rotation) -> float:
    """Return the yaw of a geometry_msgs Quaternion, rad."""
    return math.atan2(2.0 * (rotation.w * rotation.z + rotation.x * rotation.y),
                      1.0 - 2.0 * (rotation.y ** 2 + rotation.z ** 2))


def poses_from_bag(path, topic: str, frames: Tuple[str, str] = ('odom', 'base_link')):
    """
    Read the robot's poses from an odometry or a TF topic of a bag.

    :param path: a ROS 2 bag (mcap or sqlite3) or a ROS 1 bag
    :param topic: a nav_msgs/msg/Odometry or tf2_msgs/msg/TFMessage topic
    :param frames: (parent, child) of the transforms a TF topic gives (leading '/' ignored)
    :return: shape (P, 4): stamp s, x m, y m, yaw rad, by stamp (header stamps)
    :raises PoseError: on an unreadable bag, a missing topic or type, or too few poses
    """
    from rosbags.highlevel import AnyReader
    from wctls_ros.bags import typestore
    parent, child = (frame.lstrip('/') for frame in frames)
    rows = []
    try:
        with AnyReader([pathlib.Path(path)], default_typestore=typestore()) as reader:
            connections = [c for c in reader.connections if c.topic == topic]
            if not connections or connections[0].msgtype not in (ODOMETRY, TF_MESSAGE):
                found = sorted(f'{c.topic} ({c.msgtype})' for c in reader.connections
                               if c.msgtype in (ODOMETRY, TF_MESSAGE))
                raise PoseError(f'{path}: no {ODOMETRY} or {TF_MESSAGE} topic {topic}; the bag '
                                f'has {", ".join(found) or "none"}')
            for connection, _, raw in reader.messages(connections=connections):
                message = reader.deserialize(raw, connection.msgtype)
                if connection.msgtype == ODOMETRY:
                    pose = message.pose.pose
                    rows.append((message.header.stamp, pose.position.x, pose.position.y,
                                 _yaw(pose.orientation)))
                    continue
                for transform in message.transforms:
                    if (transform.header.frame_id.lstrip('/') == parent
                            and transform.child_frame_id.lstrip('/') == child):
                        moved = transform.transform
                        rows.append((transform.header.stamp, moved.translation.x,
                                     moved.translation.y, _yaw(moved.rotation)))
    except PoseError:
        raise
    except Exception as error:  # noqa: B902 - rosbags raises many kinds on a damaged bag
        raise PoseError(f'{path}: cannot read the poses of {topic}: {error}') from error
    if len(rows) < 2:
        raise PoseError(f'{path}: {topic} holds {len(rows)} poses (of a TF topic: transforms '
                        f'from {parent} to {child}); at least 2 are needed')
    poses = np.array([(stamp.sec + 1e-9 * stamp.nanosec, x, y, yaw)
                      for stamp, x, y, yaw in rows], dtype=float)
    return poses[np.argsort(poses[:, 0], kind='stable')]
