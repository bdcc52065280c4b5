# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""feature_node's lifecycle transitions against the real rclpy: what each state subscribes."""

from conftest import spin_until
import pytest

pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402, I100
from lifecycle_msgs.msg import State  # noqa: E402
from rclpy.lifecycle import TransitionCallbackReturn  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from scans import NODE_PARAMETERS, room_scan_message  # noqa: E402
from test_feature_node import Harness  # noqa: E402

# Runs nodes against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime

MANUAL = {**NODE_PARAMETERS, 'autostart': False}


def state_id(node) -> int:
    """Return the node's lifecycle state id."""
    return node._state_machine.current_state[0]


def nothing_arrives(harness, scan, seconds=0.5) -> bool:
    """Publish a scan now and then for ``seconds``; tell whether no CornerArray came back."""
    before = len(harness.received['corners'])
    spin_until(harness.executor, lambda: harness.scans.publish(scan) or False, seconds)
    return len(harness.received['corners']) == before


def test_each_transition_subscribes_publishes_stops_and_frees(ros_context, executor):
    harness = Harness(ros_context, executor, MANUAL)
    node, scan = harness.node, room_scan_message()
    spin_until(executor, lambda: False, 0.2)
    assert state_id(node) == State.PRIMARY_STATE_UNCONFIGURED
    assert node.count_subscribers('scan') == 0 and node.count_publishers('corners') == 0

    # configure: publishers exist, nothing is subscribed yet.
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert state_id(node) == State.PRIMARY_STATE_INACTIVE
    assert spin_until(executor, lambda: node.count_publishers('corners') == 1)
    assert node.count_subscribers('scan') == 0 and nothing_arrives(harness, scan)

    # activate: every scan is answered.
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    corners, _ = harness.exchange(scan)
    assert len(corners.corners) == 5

    # deactivate: unsubscribed, nothing published.
    assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
    assert spin_until(executor, lambda: node.count_subscribers('scan') == 0)
    assert nothing_arrives(harness, scan)
    processed = node.counters.processed

    # cleanup frees the publishers; configure and activate again answer again.
    assert node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
    assert state_id(node) == State.PRIMARY_STATE_UNCONFIGURED
    assert spin_until(executor, lambda: node.count_publishers('corners') == 0)
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    corners, _ = harness.exchange(scan, count=2)
    assert len(corners.corners) == 5 and node.counters.processed == processed + 1

    # shutdown from active frees everything.
    assert node.trigger_shutdown() == TransitionCallbackReturn.SUCCESS
    assert state_id(node) == State.PRIMARY_STATE_FINALIZED
    assert spin_until(executor, lambda: node.count_subscribers('scan') == 0
                      and node.count_publishers('corners') == 0)


def test_autostart_is_active_at_once(ros_context, executor):
    harness = Harness(ros_context, executor)
    assert state_id(harness.node) == State.PRIMARY_STATE_ACTIVE
    corners, _ = harness.exchange(room_scan_message())
    assert len(corners.corners) == 5


def test_configure_refuses_an_invalid_configuration_and_stays_unconfigured(
        ros_context, executor):
    harness = Harness(ros_context, executor,
                      {**MANUAL, 'range_min_m': 5.0, 'range_max_m': 4.0})
    node = harness.node
    assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert state_id(node) == State.PRIMARY_STATE_UNCONFIGURED
    assert node.count_publishers('corners') == 0
    # Fixed while unconfigured, the next configure reads the new values.
    assert node.set_parameters([Parameter('range_min_m', value=0.1)])[0].successful
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    corners, _ = harness.exchange(room_scan_message())
    assert len(corners.corners) == 5


def test_a_change_while_inactive_applies_once_active(ros_context, executor):
    harness = Harness(ros_context, executor, MANUAL)
    node = harness.node
    assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert node.set_parameters([Parameter('method', value='ml')])[0].successful
    assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
    corners, _ = harness.exchange(room_scan_message())
    assert corners.method == 'ml'


def test_diagnostics_say_the_node_is_not_subscribed_before_activate(ros_context, executor):
    harness = Harness(ros_context, executor, MANUAL)
    messages = []
    harness.peer.create_subscription(
        DiagnosticArray, '/diagnostics', lambda array: messages.extend(
            status.message for status in array.status if 'features' in status.name), 10)
    assert spin_until(executor, lambda: messages, 5.0)
    assert messages[-1] == 'unconfigured: not subscribed to scans'
    assert harness.node.trigger_configure() == TransitionCallbackReturn.SUCCESS
    count = len(messages)
    assert spin_until(executor, lambda: len(messages) > count, 5.0)
    assert messages[-1] == 'inactive: not subscribed to scans'
