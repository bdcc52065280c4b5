# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
feature_node with publish_landmarks, against the real rclpy: ids that persist, every scan.

A still sensor in the simulated room sends scans with fresh noise: every scan gets one
LandmarkArray with the scan's header; its corners are the CornerArray's, in order, with the
same poses and covariances; each true corner keeps one id through the scans and is confirmed
from its third observation; a scan with no returns gets an empty LandmarkArray and costs no
id. Without the parameter nothing is published on landmarks. The pose_array bridge publishes
every scan's detections in the LandmarkArray's order; an unknown bridge is refused.
"""

from conftest import spin_until
import numpy as np
import pytest

pytest.importorskip('rclpy')
PoseArray = pytest.importorskip('geometry_msgs.msg').PoseArray

from scans import NODE_PARAMETERS, room_scan_message  # noqa: E402
from test_feature_node import Harness  # noqa: E402
from wctls_msgs.msg import Landmark, LandmarkArray  # noqa: E402
from wctls_ros.params import ConfigError  # noqa: E402

# Runs nodes against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime
SCANS = 6


def landmark_harness(context, executor, publish: bool, **more):
    harness = Harness(context, executor, {**NODE_PARAMETERS, 'publish_landmarks': publish,
                                          **more})
    harness.received['landmarks'] = []
    harness.peer.create_subscription(LandmarkArray, 'landmarks',
                                     harness.received['landmarks'].append, 10)
    return harness


def test_landmarks_keep_their_ids_scan_after_scan(ros_context, executor):
    harness = landmark_harness(ros_context, executor, True)
    for seed in range(SCANS):
        harness.exchange(room_scan_message(seed=seed, stamp=(1700000000 + seed, 5)), seed + 1)
        assert spin_until(executor, lambda: len(harness.received['landmarks']) >= seed + 1)
    arrays, corner_arrays = harness.received['landmarks'], harness.received['corners']
    assert len(arrays) == SCANS
    corner_ids = []
    for array, corners in zip(arrays, corner_arrays):
        assert array.header == corners.header
        corner_marks = [m for m in array.landmarks if m.kind == Landmark.KIND_CORNER]
        assert len(corner_marks) == len(corners.corners) >= 4
        for mark, corner in zip(corner_marks, corners.corners):
            assert mark.pose.pose.position.x == pytest.approx(corner.pose.pose.position.x)
            np.testing.assert_allclose(mark.pose.covariance, corner.pose.covariance)
        corner_ids.append([m.id for m in corner_marks])
        assert all(m.id >= 1 and m.hits >= 1 for m in array.landmarks)
    assert all(ids == corner_ids[0] for ids in corner_ids), corner_ids
    last = arrays[-1].landmarks
    assert all(m.state == Landmark.STATE_CONFIRMED and m.hits == SCANS and m.age == SCANS - 1
               for m in last if m.kind == Landmark.KIND_CORNER)
    assert [m.state for m in arrays[1].landmarks if m.kind == Landmark.KIND_CORNER] == [
        Landmark.STATE_TENTATIVE] * len(corner_ids[0])

    empty = room_scan_message(seed=99, stamp=(1700000100, 5))
    empty.ranges = [float('inf')] * len(empty.ranges)
    harness.exchange(empty, SCANS + 1)
    assert spin_until(executor, lambda: len(harness.received['landmarks']) == SCANS + 1)
    assert harness.received['landmarks'][-1].landmarks == []


def test_no_landmarks_without_the_parameter(ros_context, executor):
    harness = landmark_harness(ros_context, executor, False)
    harness.exchange(room_scan_message(seed=1))
    spin_until(executor, lambda: harness.received['landmarks'], 0.5)
    assert harness.received['landmarks'] == []


def test_the_pose_array_bridge_follows_the_landmark_array(ros_context, executor):
    harness = landmark_harness(ros_context, executor, True, landmark_bridges='pose_array')
    poses = []
    harness.peer.create_subscription(PoseArray, 'landmark_poses', poses.append, 10)
    harness.exchange(room_scan_message(seed=3))
    assert spin_until(executor, lambda: poses and harness.received['landmarks'])
    marks = harness.received['landmarks'][-1].landmarks
    assert poses[-1].header.frame_id == 'laser'
    assert [p.position.x for p in poses[-1].poses] == pytest.approx(
        [m.pose.pose.position.x for m in marks])


def test_an_unknown_bridge_is_refused_with_the_known_ones(ros_context, executor):
    with pytest.raises(ConfigError, match='choose among rtabmap, cartographer, pose_array'):
        landmark_harness(ros_context, executor, True, landmark_bridges='gmapping')
