# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""feature_node's dock outputs and the services that start and stop them, with the real rclpy."""

import math

from conftest import spin_until
import numpy as np
import pytest

pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped  # noqa: E402, I100
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from test_feature_node import Harness  # noqa: E402
from test_frontend_dock import APEX, dock_outline, plan_with, true_dock  # noqa: E402
from wctls_lab.simulation import full_turn_bearings, SENSOR_MODELS, simulate_scan  # noqa: E402
from wctls_ros.frontend.dock import DockShape, wrap_angle  # noqa: E402

# Runs nodes against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime

DOCKING = {'sensor': 'rplidar_s1', 'dock_enabled': True}
SHAPE = DockShape()
PLAN = plan_with([dock_outline(SHAPE)])
POSE = (APEX[0] - 1.0, APEX[1] + 0.05, 0.2)


def dock_scans(count, seed=0):
    """Return ``count`` S1-like LaserScans of the dock 1 m away, 0.1 s apart."""
    rng = np.random.default_rng(seed)
    angle_min, increment, bearings = full_turn_bearings()
    messages = []
    for k in range(count):
        ranges = simulate_scan(PLAN.scene(POSE), bearings, SENSOR_MODELS['s1_like'], rng)
        scan = LaserScan(angle_min=angle_min, angle_max=angle_min + (len(bearings) - 1)
                         * increment, angle_increment=increment, time_increment=1e-4,
                         scan_time=0.1, range_min=0.05, range_max=40.0,
                         ranges=ranges.astype(np.float32))
        scan.header.frame_id = 'laser'
        scan.header.stamp.sec, scan.header.stamp.nanosec = 1700000000 + k // 10, 10 ** 8 * (k % 10)
        messages.append(scan)
    return messages


class DockHarness(Harness):
    """The feature node and a peer that also collects the dock poses and calls the services."""

    def __init__(self, context, executor, parameters):
        super().__init__(context, executor, parameters)
        self.poses, self.with_covariance = [], []
        self.peer.create_subscription(PoseStamped, 'detected_dock_pose', self.poses.append, 10)
        self.peer.create_subscription(PoseWithCovarianceStamped,
                                      'detected_dock_pose_with_covariance',
                                      self.with_covariance.append, 10)

    def feed(self, scans):
        """Publish scans one at a time, each once the previous one's corners have arrived."""
        for scan in scans:
            self.exchange(scan, count=len(self.received['corners']) + 1)
        spin_until(self.executor, lambda: False, 0.2)      # the poses come after the corners

    def call(self, service):
        client = self.peer.create_client(Trigger, f'/feature_node/{service}_dock_detection')
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(Trigger.Request())
        assert spin_until(self.executor, future.done)
        return future.result()


def test_a_confirmed_dock_is_published_with_the_scan_header_and_its_covariance(
        ros_context, executor):
    harness = DockHarness(ros_context, executor, DOCKING)
    scans = dock_scans(8)
    harness.feed(scans)
    # Three agreeing detections before the first pose; the S1-like scans miss a few.
    assert 4 <= len(harness.poses) <= 6
    assert len(harness.with_covariance) == len(harness.poses)
    headers = [scan.header for scan in scans]
    truth = true_dock(PLAN, POSE, SHAPE)
    for pose, full in zip(harness.poses, harness.with_covariance):
        assert pose.header in headers and full.header == pose.header
        assert full.pose.pose == pose.pose
        position, q = pose.pose.position, pose.pose.orientation
        assert math.hypot(position.x - truth[0], position.y - truth[1]) < 0.03
        assert abs(wrap_angle(2 * math.atan2(q.z, q.w) - truth[2])) < math.radians(4)
        covariance = np.array(full.pose.covariance).reshape(6, 6)
        xy_yaw = covariance[np.ix_([0, 1, 5], [0, 1, 5])]
        assert np.count_nonzero(covariance) == np.count_nonzero(xy_yaw)
        assert np.all(np.linalg.eigvalsh(xy_yaw) > 0)


def test_the_dock_is_drawn_in_the_markers_only_while_it_is_seen(ros_context, executor):
    harness = DockHarness(ros_context, executor, DOCKING)
    harness.feed(dock_scans(6))
    arrows = [m for array in harness.received['markers'] for m in array.markers
              if m.ns == 'dock']
    assert harness.poses and len(arrows) == len(harness.poses)
    for arrow, pose in zip(arrows, harness.poses):
        assert arrow.type == arrow.ARROW and arrow.header == pose.header
        assert arrow.pose == pose.pose
    harness.call('stop')
    drawn = len(arrows)
    harness.feed(dock_scans(3, seed=1))
    assert drawn == len([m for array in harness.received['markers'] for m in array.markers
                         if m.ns == 'dock'])


def test_the_services_stop_start_and_toggle_the_detection(ros_context, executor):
    harness = DockHarness(ros_context, executor, DOCKING)
    harness.feed(dock_scans(6))
    assert harness.poses
    answer = harness.call('stop')
    assert answer.success and answer.message == 'dock detection off'
    published = len(harness.poses)
    harness.feed(dock_scans(6, seed=1))
    assert len(harness.poses) == published           # corners still arrive, docks do not
    assert harness.call('toggle').message == 'dock detection on'
    harness.feed(dock_scans(6, seed=2))
    assert len(harness.poses) > published
    assert harness.call('toggle').message == 'dock detection off'
    assert harness.call('start').message == 'dock detection on'


def test_detection_waits_for_a_start_when_not_on_at_start(ros_context, executor):
    harness = DockHarness(ros_context, executor, {**DOCKING, 'dock_detect_at_start': False})
    harness.feed(dock_scans(6))
    assert not harness.poses
    assert harness.call('start').success
    harness.feed(dock_scans(6, seed=3))
    assert harness.poses


def test_without_dock_enabled_there_is_no_dock_topic_nor_service(ros_context, executor):
    harness = DockHarness(ros_context, executor, {'sensor': 'rplidar_s1'})
    harness.feed(dock_scans(4))
    assert not harness.poses
    assert harness.node.count_publishers('detected_dock_pose') == 0
    names = [name for name, _ in harness.node.get_service_names_and_types()]
    assert not [name for name in names if 'dock_detection' in name]


def test_a_dock_description_that_cannot_be_is_refused_with_the_reason(ros_context, executor):
    harness = DockHarness(ros_context, executor, DOCKING)
    result = harness.node.set_parameters([Parameter('dock_face_shortfall_m', value=0.5)])[0]
    assert not result.successful and 'shorter than the faces' in result.reason
    assert harness.node.set_parameters([Parameter('dock_right_face_m', value=0.6)])[0].successful
    harness.feed(dock_scans(6))
    assert not harness.poses                        # a 0.3 m face is no 0.6 m one
