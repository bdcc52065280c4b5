# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""feature_node builds every output with rosbags' classes when the definitions agree (rclpy)."""

import pytest

pytest.importorskip('rclpy')
pytest.importorskip('rosbags')

from scans import NODE_PARAMETERS, room_scan_message  # noqa: E402, I100
from test_feature_node import Harness  # noqa: E402
from wctls_msgs.msg import CornerArray  # noqa: E402
from wctls_ros.outputs import codec_types, DOCK_OUTPUTS, FEATURES, LANDMARK_OUTPUTS  # noqa: E402

# Runs nodes against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime

# What the node publishes with rclpy's own classes: rclpy's topics, the lifecycle's, diagnostics.
BUILT_BY_RCLPY = {'rcl_interfaces/msg/Log', 'rcl_interfaces/msg/ParameterEvent',
                  'lifecycle_msgs/msg/TransitionEvent', 'diagnostic_msgs/msg/DiagnosticArray'}
EVERY_OUTPUT = dict(NODE_PARAMETERS, dock_enabled=True, publish_landmarks=True)


@pytest.mark.parametrize('parameters, published', [
    (NODE_PARAMETERS, FEATURES + LANDMARK_OUTPUTS),
    (EVERY_OUTPUT, FEATURES + LANDMARK_OUTPUTS + DOCK_OUTPUTS)])
def test_every_type_the_node_builds_is_checked_and_the_fast_classes_kept(
        ros_context, executor, parameters, published):
    # A new output type once switched the fast classes off without a word: the check counted
    # the types it had found instead of naming the ones it needs.
    harness = Harness(ros_context, executor, parameters)
    harness.exchange(room_scan_message())
    node = harness.node
    mine = (node.get_name(), node.get_namespace())
    own_types = {info.topic_type for publisher in node.publishers
                 for info in node.get_publishers_info_by_topic(publisher.topic_name)
                 if (info.node_name, info.node_namespace) == mine}
    own_types |= {info.topic_type for info in node.get_subscriptions_info_by_topic('/scan')
                  if (info.node_name, info.node_namespace) == mine}
    assert set(codec_types(published)) == own_types - BUILT_BY_RCLPY
    # The classes chosen are rosbags' (a stock install's fallback is rclpy's own).
    assert node._types.CornerArray is not CornerArray
