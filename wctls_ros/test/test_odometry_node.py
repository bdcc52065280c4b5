# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""odometry_node with the real rclpy: the RPLIDAR car's scans in, nav_msgs/Odometry out."""

import math
import pathlib

from conftest import spin_until
import numpy as np
import pytest

pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402, I100
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
