# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Our message types travel through the real middleware with every field intact."""

import math

from conftest import spin_until
import pytest

pytest.importorskip('rclpy')

from rclpy.node import Node  # noqa: E402
from wctls_msgs.msg import Corner, CornerArray, LineSegment, LineSegmentArray  # noqa: E402

# Runs nodes, emulators or signals against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime


def _corner(index):
    corner = Corner()
    corner.pose.pose.position.x = 1.25 + index
    corner.pose.pose.position.y = -0.5 * index
    yaw = 0.3 + index
    corner.pose.pose.orientation.z = math.sin(yaw / 2)
    corner.pose.pose.orientation.w = math.cos(yaw / 2)
    corner.pose.covariance = [0.001 * (k + 1) + index for k in range(36)]
    corner.first_line = index
    corner.second_line = index + 1
    corner.opening_angle = 1.5 + index
    corner.first_line_points, corner.second_line_points = 40 + index, 9
    corner.first_line_chi2_dof, corner.second_line_chi2_dof = 0.9 + index, 4.5
    corner.first_end_seen, corner.second_end_seen = True, bool(index)
    return corner


def test_corner_array_with_two_corners_round_trips(ros_context, executor):
    publisher_node = Node('corner_sender', context=ros_context)
    subscriber_node = Node('corner_receiver', context=ros_context)
    executor.add_node(publisher_node)
    executor.add_node(subscriber_node)
    received = []
    subscriber_node.create_subscription(CornerArray, 'corners', received.append, 10)
    publisher = publisher_node.create_publisher(CornerArray, 'corners', 10)

    sent = CornerArray()
    sent.header.frame_id = 'laser'
    sent.header.stamp.sec = 1700000000
    sent.header.stamp.nanosec = 123456789
    sent.method = 'wctls'
    sent.corners = [_corner(0), _corner(1)]

    # Discovery takes a moment: publish until the first copy arrives.
    assert spin_until(executor, lambda: received or publisher.publish(sent), timeout_s=10.0)
    got = received[0]
    assert got is not sent
    assert got == sent
    assert got.header.stamp.nanosec == 123456789
    assert [c.pose.covariance[35] for c in got.corners] == pytest.approx([0.036, 1.036])
    assert [(c.second_line_chi2_dof, c.second_end_seen) for c in got.corners] == [
        (4.5, False), (4.5, True)]


def test_line_segment_array_round_trips(ros_context, executor):
    node = Node('segment_loopback', context=ros_context)
    executor.add_node(node)
    received = []
    node.create_subscription(LineSegmentArray, 'lines', received.append, 10)
    publisher = node.create_publisher(LineSegmentArray, 'lines', 10)
    segment = LineSegment(angle=-2.0, radius=3.5, covariance=[1e-4, 2e-6, 2e-6, 4e-4],
                          first_index=1070, last_index=12, num_points=22,
                          residual_chi2_dof=1.25, landmark=True)
    segment.start.x, segment.end.y = 1.0, -2.0
    other = LineSegment(angle=0.5, radius=1.5, covariance=[4e-2, 0.0, 0.0, 1e-3],
                        first_index=20, last_index=31, num_points=12, residual_chi2_dof=3.0)
    sent = LineSegmentArray(method='ml', segments=[segment, other])
    sent.header.frame_id = 'laser'

    assert spin_until(executor, lambda: received or publisher.publish(sent), timeout_s=10.0)
    assert received[0] == sent
    assert [s.landmark for s in received[0].segments] == [True, False]
