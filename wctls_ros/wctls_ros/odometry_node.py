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
With ``wheel_odometry_topic`` (nav_msgs/Odometry) or ``wheel_odometry_tf_frame`` (its
transform to base_frame on ``/tf``), the robot's wheel odometry is the prior: its pose
interpolated at each scan's stamp, the step between two scans moved onto the laser by the
mount, with the message's twist covariance or the parameters' model
(:mod:`wctls_ros.frontend.wheel`); where it has none for a step (none yet, stale, time that ran
backwards) the constant velocity fills in, with a throttled warning.
``/diagnostics`` (1 Hz) counts the scans by status: tracking, degenerate (the prior filled in
what the landmarks leave free), prior (too few landmarks), reinitialized (nothing consistent
associated), and those left out waiting for the mount; with a wheel odometry, the steps it
gave, those the landmarks rejected and those it had none for, by reason. A malformed scan or
wheel message is a throttled warning, never a crash or a NaN.
"""

import importlib
import math
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry as OdometryMessage
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Header

from .conversions import scan_features
from .core import start as start_core
from .frontend.frames import landmarks_from_features, wrap_angle
from .frontend.odometry import Odometry, on_robot, STATUSES
from .frontend.wheel import laser_prior, WHEEL_ADDED, WHEEL_MISSING, WheelPoses
from .node_main import declare_parameters, run_node
from .odometry_messages import (odometry_message, ODOMETRY_TYPES, planar_mount,
                                transform_message, TRANSFORM_TYPES, UNMEASURED_VARIANCE)
from .outputs import ODOMETRY
from .params import ODOMETRY_NODE, odometry_settings

WARN_PERIOD_S = 5.0
DIAGNOSTICS_PERIOD_S = 1.0
# What robot_state_publisher gives /tf_static: every static transform, kept for late joiners.
TF_STATIC_QOS = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                           reliability=ReliabilityPolicy.RELIABLE)
# The wheel odometry: best effort matches reliable publishers too; deep enough for 100 Hz
# while a scan is processed.
WHEEL_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
_PLANAR = (0, 1, 5)


def planar_yaw(x: float, y: float, z: float, w: float) -> float:
    """
    Return the heading of a rotation quaternion (its yaw about z), rad.

    :param x: quaternion x
    :param y: quaternion y
    :param z: quaternion z
    :param w: quaternion w
    :return: yaw, rad
    """
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


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
        wheel = settings.wheel
        if settings.publish_tf or settings.mount_from_tf or wheel.tf_frame:
            # tf2_msgs is on every ROS install; the PyPI wheels lack it.
            try:
                from tf2_msgs.msg import TFMessage
            except ImportError as error:
                needs = ('publish_tf' if settings.publish_tf else 'mount_from_tf'
                         if settings.mount_from_tf else 'wheel_odometry_tf_frame')
                raise ValueError(f'{needs} needs the tf2_msgs package, which this install '
                                 'lacks: sudo apt install ros-jazzy-tf2-msgs') from error
        if settings.publish_tf:
            self._tf_classes = _rclpy_classes(TRANSFORM_TYPES)
            self._tf = self.create_publisher(TFMessage, '/tf', 100)
        if settings.mount_from_tf:
            self.create_subscription(TFMessage, '/tf_static', self._on_static, TF_STATIC_QOS)
        # The wheel odometry: its poses, the last scan's stamp, and what became of its steps.
        self._wheel = WheelPoses(wheel.timeout_s) if wheel.enabled else None
        self._previous_scan_s = None
        self._wheel_counts = dict.fromkeys(('used', 'rejected') + WHEEL_MISSING, 0)
        self._wheel_counts['messages not finite'] = 0
        self._wheel_missing_now = False
        self._wheel_child_warned = False
        source = ''
        if wheel.topic:
            name = self.resolve_topic_name(wheel.topic)
            if name == self.resolve_topic_name(ODOMETRY.name):
                raise ValueError(f'wheel_odometry_topic {name} is the topic odometry_node '
                                 f'publishes on: remap its output (e.g. {ODOMETRY.name}:='
                                 'laser_odom)')
            self.create_subscription(OdometryMessage, wheel.topic, self._on_wheel, WHEEL_QOS)
            source = f'; the prior from the wheel odometry on {name}'
        elif wheel.tf_frame:
            self.create_subscription(TFMessage, '/tf', self._on_tf, 100)
            source = (f'; the prior from the wheel odometry on /tf ({wheel.tf_frame} -> '
                      f'{settings.base_frame})')
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._counts = dict.fromkeys(STATUSES, 0)
        self._malformed = 0
        self._seconds: list = []
        self.create_subscription(LaserScan, 'scan', self._on_scan, qos_profile_sensor_data)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        self.get_logger().info(
            f'odometry of {settings.base_frame} in {settings.odom_frame} from the features of '
            f'{self.resolve_topic_name("scan")}' + (' (and TF)' if settings.publish_tf else '')
            + source)
        self.get_logger().info(start_core().describe())

    def _add_wheel(self, stamp, pose, rate_covariance) -> None:
        """Keep one wheel pose (x m, y m, yaw rad) at a header stamp."""
        added = self._wheel.add(stamp.sec + 1e-9 * stamp.nanosec, pose, rate_covariance)
        if added == WHEEL_ADDED[1]:
            self._wheel_counts['messages not finite'] += 1
            self.get_logger().warning('a wheel odometry message that is not finite is left out',
                                      throttle_duration_sec=WARN_PERIOD_S)
        elif added == WHEEL_ADDED[2]:
            self.get_logger().warning(
                "the wheel odometry's time ran backwards (a bag from its start, a simulation "
                'reset): its earlier poses are dropped', throttle_duration_sec=WARN_PERIOD_S)

    def _on_wheel(self, message) -> None:
        if message.child_frame_id != self._settings.base_frame and not self._wheel_child_warned:
            self._wheel_child_warned = True
            self.get_logger().warning(
                f'the wheel odometry is of {message.child_frame_id!r}, not of base_frame '
                f'{self._settings.base_frame!r}: taken as the same frame (the mount is '
                f'{self._settings.base_frame} -> laser)')
        pose = message.pose.pose
        q = pose.orientation
        # Drivers mark an unmeasured axis with a huge variance (up to DBL_MAX): capped at the
        # 1e6 of odometry_messages, which keeps it unmeasured and the arithmetic finite.
        covariance = np.clip(np.asarray(message.twist.covariance, dtype=float).reshape(6, 6)[
            np.ix_(_PLANAR, _PLANAR)], -UNMEASURED_VARIANCE, UNMEASURED_VARIANCE)
        self._add_wheel(message.header.stamp, (pose.position.x, pose.position.y,
                                               planar_yaw(q.x, q.y, q.z, q.w)),
                        covariance if np.any(covariance != 0.0) else None)

    def _on_tf(self, message) -> None:
        wheel, base = self._settings.wheel.tf_frame, self._settings.base_frame
        for transform in message.transforms:
            if transform.header.frame_id == wheel and transform.child_frame_id == base:
                moved = transform.transform
                q = moved.rotation
                self._add_wheel(transform.header.stamp,
                                (moved.translation.x, moved.translation.y,
                                 planar_yaw(q.x, q.y, q.z, q.w)), None)

    def _wheel_prior(self, stamp_s: float):
        """Return the laser's prior from the wheel for the step to this scan, or None."""
        previous, self._previous_scan_s = self._previous_scan_s, stamp_s
        if self._wheel is None or previous is None:
            return None
        wheel = self._settings.wheel
        step, stated, why = self._wheel.step(previous, stamp_s)
        if step is None:
            self._wheel_counts[why] += 1
            self._wheel_missing_now = True
            self.get_logger().warning(
                f'no wheel odometry for the step to the scan at {stamp_s:.3f} s ({why}): the '
                'constant-velocity prior fills in', throttle_duration_sec=WARN_PERIOD_S)
            return None
        model = wheel.model
        covariance = model.covariance(step)
        if wheel.use_message_covariance and stated is not None:
            covariance = stated + np.diag([model.floor_m ** 2, model.floor_m ** 2,
                                           model.floor_rad ** 2])
        step[2] = float(wrap_angle(step[2]))
        try:
            return laser_prior(step, covariance, self._mount)
        except ValueError as error:
            self.get_logger().warning(
                f"the wheel odometry's covariance is refused ({error}): the model's instead",
                throttle_duration_sec=WARN_PERIOD_S)
            return laser_prior(step, model.covariance(step), self._mount)

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
        stamp_s = stamp.sec + 1e-9 * stamp.nanosec
        laser = self._odometry.update(stamp_s, landmarks, self._wheel_prior(stamp_s))
        update = on_robot(laser, self._mount)
        self._counts[update.status] += 1
        if update.prior_rejected:
            self._wheel_counts['rejected'] += 1
            self.get_logger().warning(
                "the landmarks contradict the wheel odometry's step (a wheel that slipped, a "
                'robot carried): the step is theirs', throttle_duration_sec=WARN_PERIOD_S)
        elif update.prior_source == 'wheel':
            self._wheel_counts['used'] += 1
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
        if self._wheel is not None:
            names = {'used': 'wheel prior: steps given', 'rejected':
                     'wheel prior: steps the landmarks rejected',
                     'messages not finite': 'wheel prior: messages not finite'}
            values.update({names.get(key, f'wheel prior: none for a step, {key}'): count
                           for key, count in self._wheel_counts.items()})
        values['processing time max (ms)'] = f'{1e3 * max(seconds or [0.0]):.2f}'
        missing, self._wheel_missing_now = self._wheel_missing_now, False
        level = DiagnosticStatus.OK if seconds and not missing else DiagnosticStatus.WARN
        status = DiagnosticStatus(
            level=level, name=f'{self.get_fully_qualified_name()}: odometry',
            message=('odometry, the constant velocity standing in for the wheel' if seconds and
                     missing else 'odometry' if seconds
                     else 'waiting for the laser mount on /tf_static'
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
