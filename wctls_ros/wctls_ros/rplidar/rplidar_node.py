# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``rplidar_node``: the RPLIDAR S1 as a ROS 2 node, with sllidar_ros2's parameters and conventions.

Publishes sensor_msgs/LaserScan on ``scan`` (reliable, keep last 10, like sllidar_ros2) and
diagnostic_msgs/DiagnosticArray on ``/diagnostics`` (1 Hz); offers ``start_motor`` and
``stop_motor`` (std_srvs/Empty). The device is read on a background thread
(:class:`~wctls_ros.rplidar.driver.RplidarDriver`), which publishes each turn as soon as it is
complete. Unlike sllidar_ros2, header.stamp is the measurement time of the turn's first sample
(raw angle ~0, published angle ~+pi; the sensor sweeps toward -pi) and scan_time the measured
rotation period.
"""

import array
import statistics
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Empty

from .driver import DriverConfig, DriverState, RplidarDriver
from .laserscan import compensation_multiple, RANGE_MIN_M, turn_to_scan
from .protocol import HealthStatus, StreamCounts
from ..node_main import declare_parameters, run_node
from ..params import RPLIDAR_NODE

SCAN_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)
DIAGNOSTICS_PERIOD_S = 1.0
# A report period with this share of frames damaged or lost, or of samples rejected, is WARN.
DAMAGED_LINK_SHARE = 0.01
_LATENCY_WINDOW = 1000
_LEVELS = {DriverState.SCANNING: DiagnosticStatus.OK,
           DriverState.MOTOR_STOPPED: DiagnosticStatus.OK,
           DriverState.CONNECTING: DiagnosticStatus.WARN,
           DriverState.RESETTING: DiagnosticStatus.WARN,
           DriverState.FAILED: DiagnosticStatus.ERROR,
           DriverState.CLOSED: DiagnosticStatus.STALE}


class RplidarNode(Node):
    """
    The RPLIDAR driver node.

    :param kwargs: passed to ``Node.__init__`` (e.g. ``context``, ``parameter_overrides``)
    :raises ValueError: on an invalid channel_type
    """

    def __init__(self, **kwargs):
        super().__init__('rplidar_node', **kwargs)
        values = declare_parameters(self, RPLIDAR_NODE)
        self._frame_id = values['frame_id']
        self._inverted = values['inverted']
        self._angle_compensate = values['angle_compensate']
        self._scan_frequency_hz = values['scan_frequency']
        self._serial_port = values['serial_port'] if values['channel_type'] == 'serial' else ''
        config = DriverConfig(
            channel_type=values['channel_type'], serial_port=values['serial_port'],
            serial_baudrate=values['serial_baudrate'], tcp_ip=values['tcp_ip'],
            tcp_port=values['tcp_port'], scan_mode=values['scan_mode'],
            scan_frequency_hz=self._scan_frequency_hz, data_timeout_s=values['data_timeout'],
            health_reset_attempts=values['health_reset_attempts'])
        self._latency_lock = threading.Lock()
        self._latencies_s = []
        self._last_report = (0, StreamCounts(), time.monotonic())
        self._scan_pub = self.create_publisher(LaserScan, 'scan', SCAN_QOS)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_service(Empty, 'start_motor', self._start_motor)
        self.create_service(Empty, 'stop_motor', self._stop_motor)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        self._driver = RplidarDriver(config, self._publish_turn, self.get_logger())
        self._driver.start()

    @property
    def driver(self) -> RplidarDriver:
        """Give access to the RPLIDAR reader: its status and CPU time."""
        return self._driver

    def publish_latencies_s(self) -> list:
        """
        Return the recent delays from a turn's last byte to its LaserScan being published.

        :return: seconds, oldest first (at most the last 1000 turns)
        """
        with self._latency_lock:
            return list(self._latencies_s)

    def destroy_node(self):
        """Stop the reader thread, then destroy the node."""
        self._driver.close()
        super().destroy_node()

    def _publish_turn(self, turn, mode):
        """Publish one turn as a LaserScan (called on the reader thread)."""
        scan = turn_to_scan(turn, self._angle_compensate, self._inverted,
                            compensation_multiple(mode.us_per_sample, self._scan_frequency_hz))
        msg = LaserScan()
        msg.header.frame_id = self._frame_id
        msg.header.stamp = Time(nanoseconds=_ros_minus_monotonic_ns(self.get_clock())
                                + int(turn.first_sample_s * 1e9)).to_msg()
        msg.angle_min = scan.angle_min
        msg.angle_max = scan.angle_max
        msg.angle_increment = scan.angle_increment
        msg.time_increment = scan.time_increment
        msg.scan_time = scan.scan_time
        msg.range_min = RANGE_MIN_M
        msg.range_max = mode.max_distance_m
        msg.ranges = array.array('f', scan.ranges.tobytes())
        msg.intensities = array.array('f', scan.intensities.tobytes())
        self._scan_pub.publish(msg)
        latency_s = time.monotonic() - turn.last_byte_s
        with self._latency_lock:
            self._latencies_s.append(latency_s)
            del self._latencies_s[:-_LATENCY_WINDOW]

    def _start_motor(self, request, response):
        self.get_logger().info('start_motor: starting the motor and the scan')
        self._driver.set_motor(True)
        return response

    def _stop_motor(self, request, response):
        self.get_logger().info('stop_motor: stopping the scan and idling the motor')
        self._driver.set_motor(False)
        return response

    def _publish_diagnostics(self):
        status = self._driver.status()
        now = time.monotonic()
        turns, stream, since = self._last_report
        rate_hz = (status.turns - turns) / max(now - since, 1e-9)
        recent = status.stream - stream
        self._last_report = (status.turns, status.stream, now)
        latencies = self.publish_latencies_s()[-100:]
        level = _LEVELS[status.state]
        message = status.message
        if status.state == DriverState.SCANNING and rate_hz == 0.0:
            level, message = DiagnosticStatus.WARN, f'{message}, but no complete turn lately'
        if status.health is not None and status.health.status == HealthStatus.WARNING:
            # The S1 scans on with a warning, but it is a warning: never report it as OK.
            level = max(level, DiagnosticStatus.WARN)
            message = (f'{message}; the device reports a health warning (code '
                       f'0x{status.health.error_code:04X})')
        if status.mode_fallback:
            level = max(level, DiagnosticStatus.WARN)
            message = f'{message}; {status.mode_fallback}'
        if status.handshake_warnings:
            # Scanning on values that replaced the device's own: never report it as OK.
            level = max(level, DiagnosticStatus.WARN)
            message = (f'{message}; implausible handshake answers replaced: '
                       f'{"; ".join(status.handshake_warnings)}')
        damaged = _share(recent.damaged_frames + recent.lost_frames, recent.frames)
        rejected = _share(recent.rejected_samples, recent.samples)
        if recent.resyncs or max(damaged, rejected) >= DAMAGED_LINK_SHARE:
            level = max(level, DiagnosticStatus.WARN)
            message = (f'{message}; damaged link: {100 * damaged:.1f} % of the frames damaged '
                       f'or lost, {100 * rejected:.1f} % of the samples rejected, '
                       f'{recent.resyncs} resyncs in the last {DIAGNOSTICS_PERIOD_S:g} s '
                       '(check the cable and the USB power)')
        values = {
            'state': status.state.value,
            'link': status.link,
            'scan rate (Hz)': f'{rate_hz:.2f}',
            'turns published': str(status.turns),
            'turns dropped': str(status.dropped_turns),
            # Rates over the last report period, then totals since the start.
            'frames damaged or lost (%)': f'{100 * damaged:.2f}',
            'frames realigned (%)': f'{100 * _share(recent.realigned_frames, recent.frames):.2f}',
            'samples rejected (%)': f'{100 * rejected:.2f}',
            'start angles replaced (%)': (
                f'{100 * _share(recent.replaced_angles, recent.frames):.2f}'),
            'resyncs': str(status.stream.resyncs),
            'frames': str(status.stream.frames),
            'frames damaged': str(status.stream.damaged_frames),
            'frames realigned': str(status.stream.realigned_frames),
            'frames lost': str(status.stream.lost_frames),
            'samples': str(status.stream.samples),
            'samples rejected': str(status.stream.rejected_samples),
            'start angles replaced': str(status.stream.replaced_angles),
            'bytes discarded': str(status.stream.discarded_bytes + status.flushed_bytes),
            'reconnects': str(status.reconnects),
            'next reconnect after (s)': f'{status.backoff_s:g}',
            'handshake answers replaced': '; '.join(status.handshake_warnings) or 'none',
            'health resets': str(status.resets),
            'publish latency median (ms)': (f'{1e3 * statistics.median(latencies):.2f}'
                                            if latencies else 'n/a'),
        }
        if status.device is not None:
            values['device'] = status.device.describe()
            # REP-138's hardware keys.
            values['Vendor Name'] = 'SLAMTEC'
            values['Product Name'] = f'RPLIDAR {status.device.model_name}'
            values['Firmware Version'] = status.device.firmware_version
        if self._serial_port:
            values['Serial Port'] = self._serial_port
        if status.baudrate:
            values['Serial Baud'] = str(status.baudrate)
        if status.health is not None:
            values['health'] = (f'status {status.health.status}, '
                                f'code 0x{status.health.error_code:04X}')
        if status.mode is not None:
            values['scan mode'] = status.mode.describe()
        array_msg = DiagnosticArray()
        array_msg.header.stamp = self.get_clock().now().to_msg()
        array_msg.status = [DiagnosticStatus(
            level=level, name=f'{self.get_name()}: RPLIDAR', message=message,
            hardware_id=(status.device.serial_number.hex().upper() if status.device
                         else status.link),
            values=[KeyValue(key=k, value=v) for k, v in values.items()])]
        self._diagnostics_pub.publish(array_msg)


def _ros_minus_monotonic_ns(clock) -> int:
    """
    Return the ROS clock minus the monotonic clock, from the closest of three pairs of readings.

    A reading interrupted between the two clocks (a loaded machine) would shift every stamp.

    :param clock: the node's ROS clock
    :return: ns
    """
    pairs = []
    for _ in range(3):
        before = time.monotonic_ns()
        now = clock.now().nanoseconds
        after = time.monotonic_ns()
        pairs.append((after - before, now - (before + after) // 2))
    return min(pairs)[1]


def _share(part: int, whole: int) -> float:
    """Return part / whole, 0 for an empty whole."""
    return part / whole if whole else 0.0


def main(args=None) -> int:
    """Run the node until shut down; exit 1 on an invalid configuration."""
    return run_node('rplidar_node', RplidarNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
