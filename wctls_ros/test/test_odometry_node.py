# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
odometry_node with the real rclpy: the RPLIDAR car's scans in, nav_msgs/Odometry out.

With a wheel odometry on a topic (a peer publishing nav_msgs/Odometry): its steps at the scans'
stamps, and what the node does without them.
"""

import math
import pathlib

from conftest import spin_until
import numpy as np
import pytest

pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402, I100
from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402
from wctls_lab.evaluation.poses import load_poses, poses_at  # noqa: E402
from wctls_lab.evaluation.scans import load_scans  # noqa: E402
from wctls_ros.frontend.odometry import compose, inverse  # noqa: E402
from wctls_ros.odometry_node import OdometryNode  # noqa: E402

pytestmark = pytest.mark.realtime

RECORDING = pathlib.Path(__file__).resolve().parents[2] / 'data' / 'rplidar_barc_moving'
SCANS = 120
# The laser sits 0.12 m behind the tracked body (the recording's laser_mount.yaml).
PARAMETERS = {'sensor': 'rplidar_a2', 'laser_x_m': -0.12}


class Harness:
    """An odometry node plus a peer publishing scans and collecting the Odometry."""

    def __init__(self, context, executor, parameters=PARAMETERS):
        self.node = OdometryNode(
            context=context, use_global_arguments=False,
            parameter_overrides=[Parameter(k, value=v) for k, v in parameters.items()])
        self.peer = Node('peer', context=context)
        for node in (self.node, self.peer):
            executor.add_node(node)
        self.executor = executor
        self.scans = self.peer.create_publisher(
            LaserScan, 'scan', QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.odometry = []
        self.diagnostics = []
        self.peer.create_subscription(Odometry, 'odom', self.odometry.append, 100)
        self.peer.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append,
                                      10)
        assert spin_until(executor, lambda: self.scans.get_subscription_count() > 0)

    def exchange(self, scan):
        """Publish a scan and step until its Odometry has arrived."""
        count = len(self.odometry)
        self.scans.publish(scan)
        assert spin_until(self.executor, lambda: len(self.odometry) > count, timeout_s=10.0)
        return self.odometry[-1]


def recorded_scans():
    """Return the recording's first scans as LaserScan messages, and their stamps."""
    recording = load_scans(RECORDING, limit=SCANS)
    out = []
    for ranges, stamp_ns in zip(recording.ranges, recording.stamps_ns):
        scan = LaserScan(angle_min=recording.angle_min,
                         angle_max=recording.angle_min + (len(ranges) - 1)
                         * recording.angle_increment,
                         angle_increment=recording.angle_increment, range_min=recording.range_min,
                         range_max=recording.range_max, ranges=ranges.astype(np.float32))
        scan.header.frame_id = 'laser'
        scan.header.stamp.sec, scan.header.stamp.nanosec = divmod(int(stamp_ns), 10 ** 9)
        out.append(scan)
    return out, recording.stamps_ns * 1e-9


def pose_of(message):
    pose = message.pose.pose
    return np.array([pose.position.x, pose.position.y,
                     2 * math.atan2(pose.orientation.z, pose.orientation.w)])


@pytest.mark.skipif(not RECORDING.is_dir(), reason='no recording')
def test_the_cars_odometry_follows_its_tracking_system(ros_context, executor):
    harness = Harness(ros_context, executor)
    scans, stamps = recorded_scans()
    messages = [harness.exchange(scan) for scan in scans]
    assert [m.header.stamp for m in messages] == [s.header.stamp for s in scans]
    assert {(m.header.frame_id, m.child_frame_id) for m in messages} == {('odom', 'base_link')}
    for message in messages:
        for covariance in (message.pose.covariance, message.twist.covariance):
            matrix = np.array(covariance).reshape(6, 6)
            assert np.isfinite(matrix).all() and np.allclose(matrix, matrix.T)
            assert np.linalg.eigvalsh(matrix[np.ix_([0, 1, 5], [0, 1, 5])]).min() >= 0.0
    # The tracked body's motion since the first scan, against the published pose.
    reference = poses_at(load_poses(RECORDING / 'poses.csv'), stamps)
    steps = np.diff(reference[:, :2], axis=0)
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(steps[:, 0], steps[:, 1]))])
    assert travelled[-1] > 5.0
    for message, pose, path in zip(messages, reference, travelled):
        relative = compose(inverse(reference[0]), pose)
        published = pose_of(message)
        assert math.hypot(*(published[:2] - relative[:2])) < 0.05 + 0.1 * path
        assert abs(math.remainder(published[2] - relative[2], 2 * math.pi)) < math.radians(10.0)
    # The published pose covariance grows with the path.
    first, final = (np.array(messages[k].pose.covariance).reshape(6, 6) for k in (1, -1))
    assert final[0, 0] + final[1, 1] > first[0, 0] + first[1, 1]
    assert spin_until(executor, lambda: any(
        status.name.endswith('odometry') for array in harness.diagnostics
        for status in array.status))


def test_a_malformed_scan_gives_a_prior_step_and_no_nan(ros_context, executor):
    harness = Harness(ros_context, executor)
    scan = LaserScan(angle_min=0.0, angle_max=1.0, angle_increment=0.0, range_min=0.1,
                     range_max=10.0, ranges=[1.0] * 5)
    scan.header.frame_id = 'laser'
    for sec in (10, 11):
        scan.header.stamp.sec = sec
        message = harness.exchange(scan)
        assert np.isfinite(np.array(message.pose.covariance)).all()
        assert np.isfinite(pose_of(message)).all()
    assert pose_of(message) == pytest.approx(np.zeros(3))


def test_tf_without_tf2_msgs_is_refused_naming_it(ros_context):
    try:
        import tf2_msgs.msg  # noqa: F401
        pytest.skip('tf2_msgs is installed here')
    except ImportError:
        pass
    with pytest.raises(ValueError, match='apt install ros-jazzy-tf2-msgs'):
        OdometryNode(context=ros_context, use_global_arguments=False,
                     parameter_overrides=[Parameter('publish_tf', value=True)])


# The wheel odometry's robot drives a circle of 2 m at 0.5 m/s; the laser sits 0.3 m ahead,
# turned 90 deg left.
WHEEL_PARAMETERS = {'sensor': 'rplidar_a2', 'laser_x_m': 0.3, 'laser_yaw_deg': 90.0,
                    'wheel_odometry_topic': 'wheel/odom'}
WHEEL_START_S = 10.0


def arc(t):
    """Return the robot's pose at t s after WHEEL_START_S."""
    yaw = 0.25 * t
    return np.array([2.0 * math.sin(yaw), 2.0 * (1.0 - math.cos(yaw)), yaw])


def wheel_message(t, twist_variances=(0.0, 0.0, 0.0), child_frame_id='base_link'):
    """Return the wheel odometry at t s after WHEEL_START_S as a nav_msgs/Odometry."""
    message = Odometry(child_frame_id=child_frame_id)
    message.header.frame_id = 'odom'
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(
        round((WHEEL_START_S + t) * 1e9), 10 ** 9)
    x, y, yaw = arc(t)
    message.pose.pose.position.x, message.pose.pose.position.y = x, y
    message.pose.pose.orientation.z = math.sin(yaw / 2)
    message.pose.pose.orientation.w = math.cos(yaw / 2)
    covariance = np.zeros((6, 6))
    covariance[[0, 1, 5], [0, 1, 5]] = twist_variances
    message.twist.covariance = covariance.reshape(36).tolist()
    return message


def empty_scan(t):
    """Return a full-turn scan without a return (no landmarks) at t s after WHEEL_START_S."""
    scan = LaserScan(angle_min=-math.pi, angle_max=math.pi, angle_increment=2 * math.pi / 359,
                     range_min=0.1, range_max=10.0, ranges=[math.inf] * 360)
    scan.header.frame_id = 'laser'
    scan.header.stamp.sec, scan.header.stamp.nanosec = divmod(
        round((WHEEL_START_S + t) * 1e9), 10 ** 9)
    return scan


class WheelHarness(Harness):
    """The harness with a peer publishing the wheel odometry."""

    def __init__(self, context, executor, parameters=WHEEL_PARAMETERS):
        super().__init__(context, executor, parameters)
        self.wheel = self.peer.create_publisher(
            Odometry, 'wheel/odom', QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        assert spin_until(executor, lambda: self.wheel.get_subscription_count() > 0)

    def send_wheel(self, messages):
        """Publish wheel messages and step until the node holds the last of them."""
        for message in messages:
            self.wheel.publish(message)
        last = messages[-1].header.stamp
        kept = self.node._wheel._stamps
        assert spin_until(self.executor, lambda: bool(kept) and kept[-1] == pytest.approx(
            last.sec + 1e-9 * last.nanosec, abs=1e-9), timeout_s=10.0)

    def diagnostic_values(self, predicate):
        """Step until a diagnostics message's values satisfy a predicate; return them."""
        def found():
            for array in self.diagnostics:
                for status in array.status:
                    values = {v.key: v.value for v in status.values}
                    if status.name.endswith('odometry') and predicate(values):
                        self.found = values
                        return True
            return False
        assert spin_until(self.executor, found, timeout_s=10.0)
        return self.found


def step_of(message, previous):
    """Return the robot's step between two published Odometry messages, by the twist."""
    dt = (message.header.stamp.sec - previous.header.stamp.sec) + 1e-9 * (
        message.header.stamp.nanosec - previous.header.stamp.nanosec)
    twist = message.twist.twist
    return np.array([twist.linear.x, twist.linear.y, twist.angular.z]) * dt, dt


def test_the_wheel_odometrys_step_at_the_scans_stamps_is_the_prior(ros_context, executor):
    harness = WheelHarness(ros_context, executor)
    variances = (4e-4, 1e-4, 9e-4)
    harness.send_wheel([wheel_message(0.02 * k, variances) for k in range(51)])
    # Scans between the wheel's stamps, without landmarks: the step is the wheel's alone.
    stamps = [0.05 + 0.1 * k for k in range(10)]
    messages = [harness.exchange(empty_scan(t)) for t in stamps]
    for k in range(1, len(messages)):
        step, dt = step_of(messages[k], messages[k - 1])
        assert np.allclose(step, compose(inverse(arc(stamps[k - 1])), arc(stamps[k])),
                           atol=5e-5)
        # The message's twist covariance, plus the model's floors over the interval squared.
        planar = np.ix_([0, 1, 5], [0, 1, 5])
        twist = np.array(messages[k].twist.covariance).reshape(6, 6)[planar]
        floors = np.diag([0.002 ** 2, 0.002 ** 2, math.radians(0.2) ** 2]) / dt ** 2
        assert np.allclose(twist, np.diag(variances) + floors, rtol=1e-6, atol=1e-12)
    # The pose, the wheel's from the first scan, in odom (the robot's first pose).
    assert np.allclose(pose_of(messages[-1]),
                       compose(inverse(arc(stamps[0])), arc(stamps[-1])), atol=2e-4)
    values = harness.diagnostic_values(lambda v: v.get('scans prior') == str(len(stamps)))
    assert values['wheel prior: steps given'] == str(len(stamps) - 1)
    assert values['wheel prior: steps the landmarks rejected'] == '0'


def test_a_wheel_axis_marked_unmeasured_stays_unmeasured_and_finite(ros_context, executor):
    # A driver's "not measured": DBL_MAX on the lateral velocity.
    harness = WheelHarness(ros_context, executor)
    harness.send_wheel([wheel_message(0.02 * k, (4e-4, 1.7e308, 9e-4)) for k in range(11)])
    first = harness.exchange(empty_scan(0.05))
    second = harness.exchange(empty_scan(0.15))
    step, dt = step_of(second, first)
    assert np.allclose(step, compose(inverse(arc(0.05)), arc(0.15)), atol=5e-5)
    twist = np.array(second.twist.covariance).reshape(6, 6)
    assert np.isfinite(twist).all()
    assert twist[1, 1] == pytest.approx(1e6, rel=1e-6)          # capped, still unmeasured
    assert twist[0, 0] == pytest.approx(4e-4 + 0.002 ** 2 / dt ** 2, rel=1e-6)


def test_without_wheel_messages_the_constant_velocity_fills_in_and_says_why(
        ros_context, executor):
    harness = WheelHarness(ros_context, executor, dict(WHEEL_PARAMETERS, wheel_timeout_s=0.2))
    # None yet: two scans, one step, the constant velocity.
    harness.exchange(empty_scan(0.0))
    harness.exchange(empty_scan(0.1))
    # The wheel from 0.1 s to 0.5 s: the step to the scan at 0.5 s is the wheel's; at 0.8 s the
    # newest pose is 0.3 s old: stale.
    harness.send_wheel([wheel_message(0.1 + 0.02 * k) for k in range(21)])
    given = harness.exchange(empty_scan(0.5))
    stale = harness.exchange(empty_scan(0.8))
    # The wheel's clock runs back (a bag from its start): what spans the jump is refused.
    harness.send_wheel([wheel_message(-5.0 + 0.02 * k) for k in range(5)])
    back = harness.exchange(empty_scan(0.9))
    for message in (given, stale, back):
        for values in (pose_of(message), message.pose.covariance, message.twist.covariance):
            assert np.isfinite(np.asarray(values)).all()
    step, _ = step_of(given, harness.odometry[-4])
    assert np.allclose(step, compose(inverse(arc(0.1)), arc(0.5)), atol=5e-5)
    values = harness.diagnostic_values(
        lambda v: v.get('wheel prior: none for a step, backwards') == '1')
    assert values['wheel prior: steps given'] == '1'
    assert values['wheel prior: none for a step, none yet'] == '1'
    assert values['wheel prior: none for a step, stale'] == '1'
    assert any(status.level == DiagnosticStatus.WARN and 'constant velocity' in status.message
               for array in harness.diagnostics for status in array.status)


@pytest.mark.skipif(not RECORDING.is_dir(), reason='no recording')
def test_the_cars_scans_with_a_wheel_odometry_follow_it(ros_context, executor):
    # The car's tracked body as its wheel odometry (no wheel log survives: the tracking
    # system's poses stand in), the model's floors its jitter over a step (5 mm and 0.5 deg
    # per pose, docs/odometry.md#measured).
    harness = WheelHarness(ros_context, executor, dict(
        PARAMETERS, wheel_odometry_topic='wheel/odom', wheel_sigma_floor_m=0.007,
        wheel_sigma_floor_deg=0.7))
    scans, stamps = recorded_scans()
    reference = poses_at(load_poses(RECORDING / 'poses.csv'), stamps)
    wheel = []
    for scan, (x, y, yaw) in zip(scans, reference):
        message = Odometry(child_frame_id='base_link')
        message.header.stamp = scan.header.stamp
        message.pose.pose.position.x, message.pose.pose.position.y = x, y
        message.pose.pose.orientation.z = math.sin(yaw / 2)
        message.pose.pose.orientation.w = math.cos(yaw / 2)
        wheel.append(message)
    messages = []
    for k, scan in enumerate(scans):
        harness.send_wheel(wheel[k:k + 1])
        messages.append(harness.exchange(scan))
    steps = np.diff(reference[:, :2], axis=0)
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(steps[:, 0], steps[:, 1]))])
    for message, pose, path in zip(messages, reference, travelled):
        relative = compose(inverse(reference[0]), pose)
        assert math.hypot(*(pose_of(message)[:2] - relative[:2])) < 0.05 + 0.1 * path
    values = harness.diagnostic_values(
        lambda v: sum(int(v[f'scans {s}']) for s in ('tracking', 'degenerate', 'prior',
                                                     'reinitialized')) == SCANS)
    given = int(values['wheel prior: steps given'])
    assert given + int(values['wheel prior: steps the landmarks rejected']) == SCANS - 1
    assert given >= 0.95 * (SCANS - 1)


def test_a_wheel_topic_that_is_the_nodes_own_output_is_refused(ros_context):
    with pytest.raises(ValueError, match='remap its output'):
        OdometryNode(context=ros_context, use_global_arguments=False,
                     parameter_overrides=[Parameter('wheel_odometry_topic', value='odom')])
    with pytest.raises(ValueError, match='publish_tf must be false'):
        OdometryNode(context=ros_context, use_global_arguments=False,
                     parameter_overrides=[Parameter('wheel_odometry_tf_frame', value='odom'),
                                          Parameter('publish_tf', value=True)])
