# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""bag_replay with the real rclpy: bags played through the real feature_node, timing, /clock."""

import os
import pathlib
import statistics
import subprocess
import time
import uuid

from conftest import keep_all_sent, spin_until
import pytest

pytest.importorskip('rclpy')

from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from scan_bags import (PERIOD_NS, real_bag, REAL_BAGS, START_NS,  # noqa: E402
                       write_empty_scan_bag, write_scan_bag, write_string_bag)
from scans import NODE_PARAMETERS  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402
from test_feature_node import installed_executable  # noqa: E402
from wctls_msgs.msg import CornerArray  # noqa: E402
from wctls_ros.bags import bag_info, BagError, read_scans  # noqa: E402
from wctls_ros.bags.replay_node import BagReplay  # noqa: E402
from wctls_ros.feature_node import FeatureNode  # noqa: E402

# One of the suite's slowest modules (make test-fast leaves it out), and one that runs
# nodes, emulators or signals against deadlines (make test runs it in its realtime group).
pytestmark = [pytest.mark.slow, pytest.mark.realtime]

PACKAGE = pathlib.Path(__file__).resolve().parents[1]


def overrides(values):
    return [Parameter(name, value=value) for name, value in values.items()]


def stamp_of(message):
    return message.header.stamp.sec, message.header.stamp.nanosec


def recorded_stamps(path, topic=None, start_ns=None):
    return [(r.scan.header.stamp.sec, r.scan.header.stamp.nanosec)
            for r in read_scans(path, topic, start_ns)]


class Graph:
    """
    The real feature_node, optionally a bag_replay, and a peer collecting what they send.

    In a namespace of their own: a node another test left in the session's ROS domain (a
    process still being torn down) would count as one of the subscribers the replay waits for.
    """

    def __init__(self, context, executor, feature_parameters=None, **replay_parameters):
        self.executor = executor
        self.namespace = f'/graph_{uuid.uuid4().hex[:12]}'
        self.feature = FeatureNode(
            context=context, use_global_arguments=False, namespace=self.namespace,
            parameter_overrides=overrides({**NODE_PARAMETERS, 'publish_markers': False,
                                           **(feature_parameters or {})}))
        self.peer = Node('peer', context=context, namespace=self.namespace)
        self.replay = None
        if replay_parameters:
            self.replay = BagReplay(context=context, use_global_arguments=False,
                                    namespace=self.namespace,
                                    parameter_overrides=overrides(replay_parameters))
        self.corners, self.scans, self.clock = [], [], []
        self.peer.create_subscription(CornerArray, 'corners', self.corners.append, 100)
        self.peer.create_subscription(LaserScan, 'scan', self.scans.append, keep_all_sent())
        self.peer.create_subscription(Clock, '/clock', self.clock.append, keep_all_sent())
        for node in (self.feature, self.peer, self.replay):
            if node is not None:
                executor.add_node(node)

    def accounted_for(self, stamps) -> bool:
        """
        Whether each scan of ``stamps`` gave a CornerArray, was skipped, or came before any.

        feature_node keeps one scan in its queue and processes the newest (a busy machine makes
        it skip some) and counts the ones it skipped, from the first scan it received on: those
        before it, overwritten in the queue, are neither seen nor counted.
        """
        if not self.corners:
            return False
        counters = self.feature.counters
        unseen = stamps.index(stamp_of(self.corners[0]))
        return len(self.corners) == counters.processed == len(stamps) - unseen - counters.skipped

    def play(self, stamps, timeout_s=30.0):
        """Step until the replay has ended and every scan of ``stamps`` is accounted for."""
        assert spin_until(self.executor, lambda: self.replay.done.done()
                          and self.accounted_for(stamps), timeout_s)
        spin_until(self.executor, lambda: False, 0.05)   # nothing more may arrive
        # Every CornerArray carries its scan's original stamp, in order.
        received = [stamp_of(m) for m in self.corners]
        assert received == [s for s in stamps if s in set(received)]
        return self.replay.done.result()


def test_a_bag_plays_through_the_feature_node_at_recorded_timing(tmp_path, ros_context,
                                                                 executor):
    stamps = write_scan_bag(tmp_path / 'bag', count=8)
    graph = Graph(ros_context, executor, bag=str(tmp_path / 'bag'), rate=2.0,
                  wait_for_subscribers=2)
    started = time.monotonic()
    assert graph.play(stamps) == 0
    elapsed = time.monotonic() - started
    # 7 gaps of 0.1 s at rate 2: 0.35 s of playback (plus discovery and processing).
    assert 0.3 < elapsed < 10.0
    assert [stamp_of(m) for m in graph.scans] == stamps
    assert all(m.header.frame_id == 'laser' and len(m.corners) == 5 for m in graph.corners)
    assert graph.replay.published == 8


def test_sqlite3_bag_with_start_offset_and_loop(tmp_path, ros_context, executor):
    stamps = write_scan_bag(tmp_path / 'bag', count=6, storage='sqlite3')
    graph = Graph(ros_context, executor, bag=str(tmp_path / 'bag'), rate=20.0, loop=True,
                  start_offset_s=0.25, wait_for_subscribers=2)
    assert spin_until(executor, lambda: len(graph.scans) >= 9, timeout_s=20.0)
    # Scans 0.3, 0.4 and 0.5 s into the bag, over and over.
    assert [stamp_of(m) for m in graph.scans[:9]] == stamps[3:] * 3
    assert not graph.replay.done.done()
    # rate changes while playing; what the bag is cannot.
    assert graph.replay.set_parameters([Parameter('rate', value=50.0)])[0].successful
    assert not graph.replay.set_parameters([Parameter('bag', value='other')])[0].successful
    graph.replay.set_parameters([Parameter('loop', value=False)])
    assert spin_until(executor, graph.replay.done.done, timeout_s=10.0)
    assert graph.replay.done.result() == 0


def test_clock_follows_the_bag_time(tmp_path, ros_context, executor):
    stamps = write_scan_bag(tmp_path / 'bag', count=5)      # logged 0.1 s apart from START_NS
    graph = Graph(ros_context, executor, bag=str(tmp_path / 'bag'), rate=1.0,
                  publish_clock=True, clock_rate_hz=50.0, wait_for_subscribers=2)
    assert graph.play(stamps) == 0
    times = [m.clock.sec * 1_000_000_000 + m.clock.nanosec for m in graph.clock]
    # From the bag's start, forward only, a tick with each scan (at or after its log time) and at
    # 50 Hz between them: about 25 on an idle machine. A busy one delays the replay's timer: the
    # ticks are fewer, and the clock, which follows the steady clock times the rate, passes the
    # last scan's time by as much as it was delayed.
    assert times == sorted(times) and len(times) >= 5
    assert START_NS <= times[0] < START_NS + PERIOD_NS
    assert times[-1] >= START_NS + 4 * PERIOD_NS


@pytest.mark.parametrize('name,count', REAL_BAGS)
def test_real_bags_give_a_corner_array_per_scan_with_the_original_stamps(name, count,
                                                                         ros_context, executor):
    path = real_bag(name)
    log_ns = [record.timestamp_ns for record in read_scans(path)]
    assert len(log_ns) == count
    # The last 40 or so scans (this also tests start_offset_s), one per 50 ms: feature_node keeps
    # one scan in its queue and would skip what it cannot keep up with, and here the replay, the
    # node and the listener share one executor on a machine that may be busy. The offset starts
    # a microsecond early: the SICK bags log some scans at the same instant.
    start_ns = log_ns[-40] - 1000
    stamps = recorded_stamps(path, start_ns=start_ns)
    period_s = statistics.median(b - a for a, b in zip(log_ns, log_ns[1:])) * 1e-9
    graph = Graph(ros_context, executor, {'range_sigma_m': 0.03}, bag=str(path),
                  rate=period_s / 0.05, start_offset_s=(start_ns - bag_info(path).start_ns) / 1e9,
                  wait_for_subscribers=2)
    assert graph.play(stamps, timeout_s=40.0) == 0
    received = [stamp_of(m) for m in graph.corners]
    assert len(stamps) >= 40
    assert sum(len(m.corners) for m in graph.corners) > len(received)


def test_bad_bags_and_parameters_are_refused_with_the_reason(tmp_path, ros_context):
    write_string_bag(tmp_path / 'strings')
    write_scan_bag(tmp_path / 'scans', count=2)
    (tmp_path / 'garbage.bag').write_bytes(b'#ROSBAG V2.0\n' + bytes(range(256)) * 4)
    cases = [
        ({}, ValueError, 'parameter bag is required'),
        ({'bag': str(tmp_path / 'missing')}, BagError, 'no bag at'),
        ({'bag': str(tmp_path / 'garbage.bag')}, BagError, 'corrupt, truncated'),
        ({'bag': str(tmp_path / 'strings')}, BagError, 'holds no sensor_msgs/msg/LaserScan'),
        ({'bag': str(tmp_path / 'scans'), 'topic': '/other'}, BagError, 'no LaserScan topic'),
        ({'bag': str(tmp_path / 'scans'), 'start_offset_s': 5.0}, ValueError,
         'past the end of the bag'),
    ]
    for parameters, kind, reason in cases:
        with pytest.raises(kind, match=reason):
            BagReplay(context=ros_context, use_global_arguments=False,
                      parameter_overrides=overrides(parameters))


def test_installed_replay_feeds_a_sim_time_feature_node_and_exits_0(tmp_path, ros_context,
                                                                    executor):
    executable = installed_executable('bag_replay')
    stamps = write_scan_bag(tmp_path / 'bag', count=6)
    graph = Graph(ros_context, executor, {'use_sim_time': True})
    process = subprocess.Popen(
        [str(executable), '--ros-args', '-r', f'__ns:={graph.namespace}',
         '-p', f'bag:={tmp_path / "bag"}', '-p', 'rate:=2.0',
         '-p', 'publish_clock:=true', '-p', 'wait_for_subscribers:=2'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert spin_until(executor, lambda: process.poll() is not None
                          and graph.accounted_for(stamps), timeout_s=30.0)
    finally:
        if process.poll() is None:
            process.terminate()
        output, _ = process.communicate(timeout=10)
    assert process.returncode == 0, output
    assert 'end of the bag: published 6 scans' in output
    received = [stamp_of(m) for m in graph.corners]
    assert len(received) >= 3 and received == [s for s in stamps if s in set(received)]
    # The feature node runs on the bag's clock, which ends where the replay ended: with the
    # last scan, or later by as much as a busy machine delayed it (30 s at rate 2 at most).
    now = graph.feature.get_clock().now().nanoseconds
    assert START_NS + 5 * PERIOD_NS <= now <= START_NS + 60_000_000_000


@pytest.mark.parametrize('arguments,reason', [
    (['-p', 'bag:=/nonexistent/bag'], 'no bag at /nonexistent/bag'),
    (['-p', 'rate:=1000.0'], 'rate out of range'),
    (['-p', 'rate:=2'], "expecting type 'DOUBLE'"),
])
def test_installed_replay_exits_1_with_a_clear_message_and_no_traceback(arguments, reason):
    executable = installed_executable('bag_replay')
    result = subprocess.run([str(executable), '--ros-args'] + arguments, capture_output=True,
                            text=True, timeout=30)
    output = result.stdout + result.stderr
    assert result.returncode == 1, output
    assert reason in output and 'Traceback' not in output


def test_installed_replay_refuses_a_fifo_and_an_empty_scan_topic_in_one_fatal_line(tmp_path):
    executable = installed_executable('bag_replay')
    os.mkfifo(tmp_path / 'fifo.bag')
    write_empty_scan_bag(tmp_path / 'empty')
    cases = [(tmp_path / 'fifo.bag', 'is not a regular file or a folder'),
             (tmp_path / 'empty', 'its LaserScan topic /scan holds no messages')]
    for bag, reason in cases:
        # A timeout, not a hang, if the FIFO is opened.
        result = subprocess.run([str(executable), '--ros-args', '-p', f'bag:={bag}'],
                                capture_output=True, text=True, timeout=30)
        lines = (result.stdout + result.stderr).splitlines()
        assert result.returncode == 1 and len(lines) == 1, lines
        assert '[FATAL]' in lines[0] and reason in lines[0]
