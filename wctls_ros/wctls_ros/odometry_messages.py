# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
nav_msgs/Odometry (and the TF odom -> base_link) from the odometry, for rclpy and rosbags alike.

REP-105: the pose is the child frame's (base_link) in the header's frame (odom); the twist is
in the child frame, the step over the time since the previous scan. The 6x6 covariances hold
(x, y, yaw) in rows and columns 0, 1 and 5 (as feature_node's corners); z, roll and pitch,
which a planar odometry does not measure, get UNMEASURED_VARIANCE on the diagonal so that a
filter that fuses them by mistake gives them no weight. A twist with no time to divide by (the
first scan) is zero with UNMEASURED_VARIANCE on every axis. :func:`planar_mount` reads the
laser's pose on the robot from the static transforms of ``/tf_static``.
"""

import math
from typing import Mapping, Optional, Tuple

import numpy as np

from .frontend.odometry import OdometryUpdate

ODOMETRY = 'nav_msgs/msg/Odometry'
TF_MESSAGE = 'tf2_msgs/msg/TFMessage'
# The message types an Odometry is built from.
ODOMETRY_TYPES = (
    'nav_msgs/msg/Odometry', 'geometry_msgs/msg/PoseWithCovariance', 'geometry_msgs/msg/Pose',
    'geometry_msgs/msg/Point', 'geometry_msgs/msg/Quaternion',
    'geometry_msgs/msg/TwistWithCovariance', 'geometry_msgs/msg/Twist',
    'geometry_msgs/msg/Vector3')
TRANSFORM_TYPES = ('tf2_msgs/msg/TFMessage', 'geometry_msgs/msg/TransformStamped',
                   'geometry_msgs/msg/Transform', 'geometry_msgs/msg/Vector3',
                   'geometry_msgs/msg/Quaternion')
UNMEASURED_VARIANCE = 1e6
_PLANAR = np.array([0, 1, 5])


def _six_by_six(covariance: np.ndarray) -> np.ndarray:
    """Return a planar 3x3 covariance as a row-major 6x6 with the unmeasured axes wide."""
    out = np.diag([0.0, 0.0, UNMEASURED_VARIANCE, UNMEASURED_VARIANCE, UNMEASURED_VARIANCE,
                   0.0])
    out[np.ix_(_PLANAR, _PLANAR)] = covariance
    return out.reshape(36)


def odometry_message(classes: Mapping[str, type], update: OdometryUpdate, header,
                     child_frame_id: str):
    """
    Return one scan's odometry as a nav_msgs/Odometry.

    :param classes: ROS type name (each of ODOMETRY_TYPES) -> its message class (rclpy's or a
        rosbags typestore's)
    :param update: the robot's odometry of the scan
    :param header: the header to give it (stamp of the scan, frame_id odom)
    :param child_frame_id: the robot's frame (base_link)
    :return: the message
    """
    vector = classes['geometry_msgs/msg/Vector3']
    quaternion = classes['geometry_msgs/msg/Quaternion']
    yaw = float(update.pose[2])
    position = classes['geometry_msgs/msg/Point'](x=float(update.pose[0]),
                                                  y=float(update.pose[1]), z=0.0)
    pose = classes['geometry_msgs/msg/PoseWithCovariance'](
        pose=classes['geometry_msgs/msg/Pose'](
            position=position,
            orientation=quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))),
        covariance=_six_by_six(update.pose_covariance))
    if update.dt_s > 0.0:
        rate = update.step / update.dt_s
        rate_covariance = _six_by_six(update.step_covariance / update.dt_s ** 2)
    else:
        rate = np.zeros(3)
        rate_covariance = UNMEASURED_VARIANCE * np.eye(6).reshape(36)
    twist = classes['geometry_msgs/msg/TwistWithCovariance'](
        twist=classes['geometry_msgs/msg/Twist'](
            linear=vector(x=float(rate[0]), y=float(rate[1]), z=0.0),
            angular=vector(x=0.0, y=0.0, z=float(rate[2]))),
        covariance=rate_covariance)
    return classes['nav_msgs/msg/Odometry'](header=header, child_frame_id=child_frame_id,
                                            pose=pose, twist=twist)


def transform_message(classes: Mapping[str, type], update: OdometryUpdate, header,
                      child_frame_id: str):
    """
    Return the robot's pose as a tf2_msgs/TFMessage of one transform odom -> base_link.

    :param classes: ROS type name (each of TRANSFORM_TYPES) -> its message class
    :param update: the robot's odometry of the scan
    :param header: the transform's header (stamp of the scan, frame_id odom)
    :param child_frame_id: the robot's frame (base_link)
    :return: the message
    """
    yaw = float(update.pose[2])
    moved = classes['geometry_msgs/msg/Transform'](
        translation=classes['geometry_msgs/msg/Vector3'](x=float(update.pose[0]),
                                                         y=float(update.pose[1]), z=0.0),
        rotation=classes['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                         w=math.cos(yaw / 2)))
    stamped = classes['geometry_msgs/msg/TransformStamped'](
        header=header, child_frame_id=child_frame_id, transform=moved)
    return classes['tf2_msgs/msg/TFMessage'](transforms=[stamped])


# A laser whose scan plane is tilted this far from the robot's is refused, rad.
MAX_MOUNT_TILT_RAD = math.radians(2.0)


def _rotation(quaternion) -> np.ndarray:
    """Return the rotation matrix of a quaternion (x, y, z, w), normalised first."""
    x, y, z, w = np.asarray(quaternion, dtype=float) / np.linalg.norm(quaternion)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def planar_mount(transforms: Mapping[str, tuple], base_frame: str,
                 laser_frame: str) -> Optional[Tuple[float, float, float]]:
    """
    Return the laser's pose on the robot from static transforms, as (x m, y m, yaw rad).

    The chain from the laser's frame up to the robot's is composed in 3D (a mount may hang from
    other frames: base_link -> plate -> laser), then projected on the robot's plane.

    :param transforms: child frame -> (parent frame, translation (x, y, z) m, rotation
        quaternion (x, y, z, w)), as ``/tf_static`` gives them
    :param base_frame: the robot's frame
    :param laser_frame: the scan's frame
    :return: the mount, or None while the chain is incomplete
    :raises ValueError: when the laser's scan plane is tilted or upside down on the robot's
        (a planar odometry of a mirrored scan would turn the wrong way), or the frames loop
    """
    rotation, translation = np.eye(3), np.zeros(3)
    frame, seen = laser_frame, set()
    while frame != base_frame:
        if frame in seen:
            raise ValueError(f'the static transforms loop through {frame!r}')
        seen.add(frame)
        if frame not in transforms:
            return None
        frame, offset, quaternion = transforms[frame]
        parent = _rotation(quaternion)
        rotation, translation = parent @ rotation, parent @ translation + np.asarray(offset)
    tilt = math.acos(min(1.0, max(-1.0, float(rotation[2, 2]))))
    if tilt > MAX_MOUNT_TILT_RAD:
        raise ValueError(
            f'the scan plane of {laser_frame!r} is {math.degrees(tilt):.1f} deg from the plane '
            f'of {base_frame!r}' + (' (mounted upside down)' if tilt > math.pi / 2 else '')
            + ': a planar odometry needs it level; give laser_x_m, laser_y_m and '
            'laser_yaw_deg with mount_from_tf false for a scan flipped upstream')
    return (float(translation[0]), float(translation[1]),
            math.atan2(float(rotation[1, 0]), float(rotation[0, 0])))
