# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
odometry_node: LaserScan in; nav_msgs/Odometry from the scan's corners and line landmarks out.

Subscribes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS) and runs feature_node's pipeline
on it itself: one callback per scan, no second topic to wait for or to pair by stamp, and the
extraction costs 0.1 ms a scan compiled (docs/performance.md). Publishes ``odom``
(nav_msgs/Odometry, REP-105: frame ``odom_frame``, child ``base_frame``, the pose and the
twist with their covariances, :mod:`wctls_ros.odometry_messages`) with the scan's stamp and,
with ``publish_tf``, the transform odom -> base_frame on ``/tf``. The laser's pose on the robot
is a parameter (``laser_x_m``, ``laser_y_m``, ``laser_yaw_deg``) or, with ``mount_from_tf``,
read from ``/tf_static`` (scans before it is known are left out, with a throttled warning).
``/diagnostics`` (1 Hz) counts the scans by status: tracking, degenerate (the constant-velocity
prior filled in what the landmarks leave free), prior (too few landmarks), reinitialized
(nothing consistent associated), and those left out waiting for the mount. A malformed scan is
a throttled warning and a prior step, never a crash or a NaN.
"""

import importlib
import math
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry as OdometryMessage
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Header

from .conversions import scan_features
from .core import start as start_core
from .frontend.frames import landmarks_from_features
from .frontend.odometry import Odometry, on_robot, STATUSES
from .node_main import declare_parameters, run_node
from .odometry_messages import (odometry_message, ODOMETRY_TYPES, planar_mount,
                                transform_message, TRANSFORM_TYPES)
from .outputs import ODOMETRY
from .params import ODOMETRY_NODE, odometry_settings

WARN_PERIOD_S = 5.0
DIAGNOSTICS_PERIOD_S = 1.0
# What robot_state_publisher gives /tf_static: every static transform, kept for late joiners.
TF_STATIC_QOS = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                           reliability=ReliabilityPolicy.RELIABLE)


def _rclpy_classes(names) -> dict:
    """Return the rclpy message classes of ROS type names."""
    classes = {}
    for name in names:
        package, _, kind = name.split('/')
        classes[name] = getattr(importlib.import_module(f'{package}.msg'), kind)
    return classes


class OdometryNode(Node):
    """Estimate the robot's motion from the features of every LaserScan."""

    def __init__(self, **kwargs):
        super().__init__('odometry_node', **kwargs)
        self._settings = odometry_settings(declare_parameters(self, ODOMETRY_NODE))
        settings = self._settings
        self._classes = _rclpy_classes(ODOMETRY_TYPES)
        self._odom = self.create_publisher(OdometryMessage, ODOMETRY.name, 10)
        self._tf = None
        # The mount and the odometry that starts at it (odom is the robot's first pose); with
        # mount_from_tf both wait for /tf_static.
        self._mount = None if settings.mount_from_tf else settings.mount
        self._odometry = None if self._mount is None else Odometry(settings.odometry,
                                                                   self._mount)
        self._static: dict = {}
        self._waiting = 0
        if settings.publish_tf or settings.mount_from_tf:
            # tf2_msgs is on every ROS install; the PyPI wheels lack it.
            try:
                from tf2_msgs.msg import TFMessage
            except ImportError as error:
                raise ValueError(f'{"publish_tf" if settings.publish_tf else "mount_from_tf"} '
                                 'needs the tf2_msgs package, which this install lacks: sudo '
                                 'apt install ros-jazzy-tf2-msgs') from error
        if settings.publish_tf:
            self._tf_classes = _rclpy_classes(TRANSFORM_TYPES)
            self._tf = self.create_publisher(TFMessage, '/tf', 100)
        if settings.mount_from_tf:
            self.create_subscription(TFMessage, '/tf_static', self._on_static, TF_STATIC_QOS)
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._counts = dict.fromkeys(STATUSES, 0)
        self._malformed = 0
        self._seconds: list = []
        self.create_subscription(LaserScan, 'scan', self._on_scan, qos_profile_sensor_data)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        self.get_logger().info(
            f'odometry of {settings.base_frame} in {settings.odom_frame} from the features of '
            f'{self.resolve_topic_name("scan")}' + (' (and TF)' if settings.publish_tf else ''))
        self.get_logger().info(start_core().describe())

    def _on_static(self, message) -> None:
        for transform in message.transforms:
            moved = transform.transform
            self._static[transform.child_frame_id] = (
                transform.header.frame_id,
                (moved.translation.x, moved.translation.y, moved.translation.z),
                (moved.rotation.x, moved.rotation.y, moved.rotation.z, moved.rotation.w))

    def _mount_known(self, laser_frame: str) -> bool:
        """Tell whether the mount is known, looking it up on /tf_static's transforms first."""
        if self._odometry is not None:
            return True
        base = self._settings.base_frame
        try:
            self._mount = planar_mount(self._static, base, laser_frame)
        except ValueError as error:
            self.get_logger().error(f'{error}; scans are left out',
                                    throttle_duration_sec=WARN_PERIOD_S)
            return False
        if self._mount is None:
            self.get_logger().warning(
                f'waiting for the transform {base} -> {laser_frame!r} on /tf_static (the '
                "laser's mount); scans are left out until then",
                throttle_duration_sec=WARN_PERIOD_S)
            return False
        x, y, yaw = self._mount
        self.get_logger().info(f'laser mount from /tf_static: x {x:.3f} m, y {y:.3f} m, yaw '
                               f'{math.degrees(yaw):.2f} deg')
        self._odometry = Odometry(self._settings.odometry, self._mount)
        return True

    def _on_scan(self, scan: LaserScan) -> None:
        started = time.perf_counter()
        settings = self._settings
        if not self._mount_known(scan.header.frame_id):
            self._waiting += 1
            return
        features, problems = scan_features(scan, settings.config)
        if problems:
            self._malformed += 1
            self.get_logger().warning(
                f'a scan from {scan.header.frame_id!r} gives no landmarks: ' + '; '.join(problems)
                + ' (the step is the prior)', throttle_duration_sec=WARN_PERIOD_S)
        landmarks = landmarks_from_features(features,
                                            settings.config.max_landmark_angle_sigma_rad)
        stamp = scan.header.stamp
        laser = self._odometry.update(stamp.sec + 1e-9 * stamp.nanosec, landmarks)
        update = on_robot(laser, self._mount)
        self._counts[update.status] += 1
        if update.status == 'reinitialized':
            self.get_logger().warning(
                'no consistent association between two scans (a kidnap, a scene that changed): '
                'the odometry is reinitialized, its covariance wide',
                throttle_duration_sec=WARN_PERIOD_S)
        header = Header(stamp=stamp, frame_id=settings.odom_frame)
        self._odom.publish(odometry_message(self._classes, update, header, settings.base_frame))
        if self._tf is not None:
            self._tf.publish(transform_message(self._tf_classes, update, header,
                                               settings.base_frame))
        self._seconds.append(time.perf_counter() - started)

    def _publish_diagnostics(self) -> None:
        seconds, self._seconds = self._seconds, []
        values = {f'scans {status}': count for status, count in self._counts.items()}
        values['scans malformed'] = self._malformed
        values['scans left out waiting for the mount'] = self._waiting
        values['processing time max (ms)'] = f'{1e3 * max(seconds or [0.0]):.2f}'
        level = DiagnosticStatus.OK if seconds else DiagnosticStatus.WARN
        status = DiagnosticStatus(
            level=level, name=f'{self.get_fully_qualified_name()}: odometry',
            message=('odometry' if seconds else 'waiting for the laser mount on /tf_static'
                     if self._odometry is None else 'no scans'),
            hardware_id=self._settings.base_frame,
            values=[KeyValue(key=key, value=str(value)) for key, value in values.items()])
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(array)


def main(args=None) -> int:
    """Run the node until Ctrl-C or shutdown; exit 1 on an invalid configuration."""
    return run_node('odometry_node', OdometryNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
