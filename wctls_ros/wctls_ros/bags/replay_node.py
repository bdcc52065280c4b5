# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
bag_replay: plays the LaserScans of a ROS 1 or ROS 2 bag on ``scan`` at the recorded timing.

For machines without rosbag2 (and for ROS 1 bags anywhere): reads the bag with ``rosbags``,
publishes each scan as a sensor_msgs/LaserScan with its recorded header (stamp, frame_id) on
``scan`` (relative, remappable; reliable, keep last 10 like sllidar_ros2, which reliable and
best-effort subscribers both receive; ``qos_overrides./scan.publisher.*`` parameters change it)
when its log time comes, scaled by ``rate``. With ``publish_clock`` it also publishes the bag
time on ``/clock`` (best effort, keep last 1, like ``ros2 bag play --clock``) for nodes running
with ``use_sim_time``. Playback runs on a steady-clock timer, so the executor stays free, and
the process exits 0 at the end of the bag unless ``loop`` is set.
"""

import sys

from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.task import Future
from rosgraph_msgs.msg import Clock as ClockMessage
from sensor_msgs.msg import LaserScan

from .bag_io import bag_info, BagError, choose_scan_topic, read_scans
from ..conversions import laser_scan
from ..extras import explains_missing_extras
from ..node_main import declare_parameters, run_node, spin_until_shutdown
from ..params import BAG_REPLAY

SCAN_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)
CLOCK_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                       reliability=ReliabilityPolicy.BEST_EFFORT)
# Progress is logged at most this often, s (wall time).
PROGRESS_PERIOD_S = 5.0
# While waiting for subscribers, look again this often, s.
WAIT_POLL_S = 0.1
# At the end, wait at most this long for reliable subscribers to acknowledge the last scans, s.
DELIVERY_TIMEOUT_S = 2.0
_NS = 1_000_000_000


class BagReplay(Node):
    """Publish the LaserScans of a bag on ``scan`` at their recorded timing."""

    def __init__(self, **kwargs):
        super().__init__('bag_replay', **kwargs)
        declare_parameters(self, BAG_REPLAY)
        value = self._value
        self._bag = value('bag')
        if not self._bag:
            raise ValueError('parameter bag is required: --ros-args -p bag:=<path of the bag>')
        info = bag_info(self._bag)
        self._topic = choose_scan_topic(self._bag, value('topic'), info)
        self._total = info.topics[self._topic][1]
        self._start_ns = info.start_ns + round(value('start_offset_s') * _NS)
        self._end_ns = info.end_ns
        if self._start_ns > self._end_ns:
            raise ValueError(f'start_offset_s {value("start_offset_s")} is past the end of the '
                             f'bag ({(info.end_ns - info.start_ns) / _NS:.3f} s long)')

        self._scans = self.create_publisher(
            LaserScan, 'scan', SCAN_QOS,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self._clock_out = None
        if value('publish_clock'):
            self._clock_out = self.create_publisher(ClockMessage, '/clock', CLOCK_QOS)
        self._clock_period_ns = round(_NS / value('clock_rate_hz'))
        self._next_clock_ns = 0
        self._wait_for = value('wait_for_subscribers')
        self._rate = value('rate')
        self.add_post_set_parameters_callback(self._on_parameters_set)

        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._records = None        # iterator of the current pass
        self._next = None           # the next record to publish
        self._anchor = (0, 0)       # (steady ns, bag ns) that correspond
        self._pass = 0
        self._published = 0         # in this pass
        self._published_total = 0
        self._failed = False
        self.done = Future()
        self._timer = self.create_timer(0.0, self._tick, clock=self._steady)
        clock = 'with /clock' if self._clock_out else 'without /clock'
        self.get_logger().info(
            f'playing {self._total} scans of {self._topic} from {self._bag} on '
            f'{self._scans.topic_name} at rate {self._rate:g} {clock}'
            + (f', from {value("start_offset_s"):g} s' if self._start_ns > info.start_ns else '')
            + (', looping' if value('loop') else ''))

    def _value(self, name):
        return self.get_parameter(name).value

    def _bag_time(self, steady_ns: int) -> int:
        wall, bag = self._anchor
        return bag + round((steady_ns - wall) * self._rate)

    def _due(self, bag_ns: int) -> int:
        wall, bag = self._anchor
        return wall + round((bag_ns - bag) / self._rate)

    def _on_parameters_set(self, parameters):
        for parameter in parameters:
            if parameter.name == 'rate' and parameter.value != self._rate:
                now = self._steady.now().nanoseconds
                self._anchor = (now, self._bag_time(now))
                self._rate = parameter.value
                self._wake_at(now)
                self.get_logger().info(f'rate {self._rate:g}')

    def _wake_at(self, steady_ns: int) -> None:
        """Re-arm the playback timer to fire at a steady-clock time."""
        if self.done.done():
            return
        delay = max(0, steady_ns - self._steady.now().nanoseconds)
        self._timer.timer_period_ns = delay
        self._timer.reset()

    def _tick(self):
        now = self._steady.now().nanoseconds
        if self._records is None:
            matched = self._scans.get_subscription_count()
            if matched < self._wait_for:
                self.get_logger().info(
                    f'waiting for {self._wait_for} subscriber(s) on {self._scans.topic_name} '
                    f'({matched} now)', throttle_duration_sec=PROGRESS_PERIOD_S)
                self._wake_at(now + round(WAIT_POLL_S * _NS))
                return
            self._next = self._begin_pass(now)
        if self._next is not None and self._next.timestamp_ns <= self._bag_time(now):
            # One scan per callback: when behind, the others wait for the next (immediate) call
            # so that subscriptions in the same executor are served in between.
            self._publish_clock(now)
            self._publish(self._next)
            self._next = self._read_next(now)
        if self._clock_out is not None and now >= self._next_clock_ns:
            self._publish_clock(now)
        if self._next is None:
            return
        wake = self._due(self._next.timestamp_ns)
        if self._clock_out is not None:
            wake = min(wake, self._next_clock_ns)
        self._wake_at(wake)

    def _begin_pass(self, now: int):
        self._pass += 1
        self._published = 0
        self._anchor = (now, self._start_ns)
        self._next_clock_ns = now
        self._records = read_scans(self._bag, self._topic, self._start_ns)
        return self._read_next(now)

    def _read_next(self, now: int):
        try:
            return next(self._records)
        except StopIteration:
            pass
        except BagError as error:
            self._failed = True
            self.get_logger().error(f'{error}; ending this pass',
                                    throttle_duration_sec=PROGRESS_PERIOD_S)
        return self._end_pass(now)

    def _end_pass(self, now: int):
        self.get_logger().info(f'end of the bag: published {self._published} scans in pass '
                               f'{self._pass}')
        if self._value('loop') and self._published > 0:
            return self._begin_pass(now)
        if self._published == 0 and not self._failed:
            self.get_logger().error(f'no scans of {self._topic} after the start offset')
            self._failed = True
        self._timer.cancel()
        self.done.set_result(1 if self._failed else 0)
        return None

    def _publish(self, record) -> None:
        try:
            message = laser_scan(record.scan)
        except Exception as error:  # noqa: B902 - a bad message in a bag must not stop playback
            self.get_logger().warning(f'skipping a scan logged at {record.timestamp_ns} ns: '
                                      f'{error!r}', throttle_duration_sec=PROGRESS_PERIOD_S)
            return
        self._scans.publish(message)
        self._published += 1
        self._published_total += 1
        span = max(1, self._end_ns - self._start_ns)
        self.get_logger().info(
            f'pass {self._pass}: {self._published} scans published, bag time '
            f'{(record.timestamp_ns - self._start_ns) / _NS:.1f} of {span / _NS:.1f} s '
            f'({100.0 * (record.timestamp_ns - self._start_ns) / span:.0f} %)',
            throttle_duration_sec=PROGRESS_PERIOD_S)

    def _publish_clock(self, now: int) -> None:
        if self._clock_out is None:
            return
        bag_ns = self._bag_time(now)
        message = ClockMessage()
        message.clock.sec, message.clock.nanosec = divmod(bag_ns, _NS)
        self._clock_out.publish(message)
        self._next_clock_ns = now + self._clock_period_ns

    @property
    def published(self) -> int:
        """
        Return how many scans were published in all passes so far.

        :return: the count
        """
        return self._published_total

    def wait_for_delivery(self) -> bool:
        """
        Wait (bounded) until reliable subscribers have acknowledged every published scan.

        :return: True when all were acknowledged in time
        """
        return self._scans.wait_for_all_acked(Duration(seconds=DELIVERY_TIMEOUT_S))


def _play(executor, node) -> int:
    """Spin until the bag has been played (or shutdown); return the node's exit status."""
    spin_until_shutdown(executor, node.done.done)
    node.wait_for_delivery()
    return node.done.result() if node.done.done() else 0


@explains_missing_extras('bag_replay')
def main(args=None) -> int:
    """Play the bag; exit 0 at its end, 1 on a bad bag or configuration."""
    return run_node('bag_replay', BagReplay, _play, (BagError, ValueError), args)


if __name__ == '__main__':
    sys.exit(main())
