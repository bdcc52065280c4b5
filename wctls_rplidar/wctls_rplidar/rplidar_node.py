# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``rplidar_node``: an RPLIDAR as a ROS 2 lifecycle node, with sllidar_ros2's parameters.

Lifecycle (rclpy.lifecycle): configure opens the port and reads the device info and health
(the motor stays idle), activate starts the motor and the scan, deactivate stops them, cleanup
closes the port, shutdown (from any state) stops the motor and closes the port. With
``autostart`` (the default) the node configures and activates itself at start, so a plain
``ros2 run`` scans at once and, with no device yet, keeps retrying until one answers; without it
a lifecycle manager or the launch file drives the transitions, and configure fails, naming the
likely cause, when the device has not answered within ``configure_timeout``. However the node
ends (a transition, destroy_node after Ctrl-C, SIGTERM or an exception) the driver is closed,
which stops the scan and the motor.

A change_state request the current state does not allow (configure while active, cleanup while
unconfigured) is refused with ``success: false`` and a warning, and the node goes on: the rclpy
of Jazzy raises on it inside the service and ends the node (ros2/rclpy#1209, fixed upstream by
ros2/rclpy#1319). A shutdown request names whichever of the three shutdown transitions; the
current state's is taken. Requests are handled one at a time.

Publishes sensor_msgs/LaserScan on ``scan`` (reliable, keep last 10, like sllidar_ros2; a
lifecycle publisher: only while active), with ``fixed_beams`` N > 0 the same turns as N fixed
beams on ``scan_fixed`` (:func:`~wctls_rplidar.laserscan.fixed_scan`), and
diagnostic_msgs/DiagnosticArray on ``/diagnostics`` (1 Hz, in every state); offers
``start_motor`` and ``stop_motor`` (std_srvs/Empty, while active). Angles, orientations and
the time order of the beams: :mod:`wctls_rplidar.laserscan`. The device is read on a
background thread (:class:`~wctls_rplidar.driver.RplidarDriver`), which publishes each turn
as soon as it is complete. Unlike sllidar_ros2, header.stamp is the measurement time of the
turn's first sample (raw angle ~0; on the device's clock for the formats that carry it,
:class:`~wctls_rplidar.turns.TurnAssembler`) and scan_time the measured rotation period.
That time is mapped onto the node's ROS clock as each turn is published, so with
``use_sim_time`` the stamps are on the simulated clock; until the first /clock message that clock
stands at 0 and no turn is published (a throttled error says why).
"""

import array
import itertools
import signal
import statistics
import sys
import threading
import time
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from lifecycle_msgs.msg import Transition
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Empty

from .driver import DriverConfig, DriverState, RplidarDriver
from .laserscan import (compensation_multiple, fixed_scan, orientation_offset_rad, RANGE_MIN_M,
                        ScanArrays, turn_to_scan)
from .parameters import declare_all
from .protocol import HealthStatus, StreamCounts

SCAN_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)
DIAGNOSTICS_PERIOD_S = 1.0
# How often configure and close look whether the device has answered, s.
_POLL_S = 0.02
# A report period with this share of frames damaged or lost, or of samples rejected, is WARN.
DAMAGED_LINK_SHARE = 0.01
_LATENCY_WINDOW = 1000
# The shutdown transitions, one per primary state it leaves.
_SHUTDOWN_TRANSITIONS = (Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,
                         Transition.TRANSITION_INACTIVE_SHUTDOWN,
                         Transition.TRANSITION_ACTIVE_SHUTDOWN)
_LEVELS = {DriverState.SCANNING: DiagnosticStatus.OK,
           DriverState.MOTOR_STOPPED: DiagnosticStatus.OK,
           DriverState.CONNECTING: DiagnosticStatus.WARN,
           DriverState.RESETTING: DiagnosticStatus.WARN,
           DriverState.FAILED: DiagnosticStatus.ERROR,
           DriverState.CLOSED: DiagnosticStatus.STALE}


class RplidarNode(LifecycleNode):
    """
    The RPLIDAR driver node.

    :param kwargs: passed to ``LifecycleNode.__init__`` (e.g. ``context``,
        ``parameter_overrides``)
    :raises ValueError: on an invalid channel_type
    """

    def __init__(self, **kwargs):
        super().__init__('rplidar_node', **kwargs)
        self._transition_lock = threading.Lock()
        # rclpy keeps the service's callback here; the guard takes its place (see the module).
        self._unguarded_change_state = self._service_change_state.callback
        self._service_change_state.callback = self._change_state
        values = declare_all(self)
        self._frame_id = values['frame_id']
        self._inverted = values['inverted']
        self._angle_compensate = values['angle_compensate']
        self._scan_frequency_hz = values['scan_frequency']
        self._serial_port = values['serial_port'] if values['channel_type'] == 'serial' else ''
        self._orientation = values['orientation']
        orientation_offset_rad(self._orientation)        # refuses an unknown one at start
        self._fixed_beams = values['fixed_beams']
        self._autostart = values['autostart']
        self._configure_timeout_s = values['configure_timeout']
        self._config = DriverConfig(
            channel_type=values['channel_type'], serial_port=values['serial_port'],
            serial_baudrate=values['serial_baudrate'], tcp_ip=values['tcp_ip'],
            tcp_port=values['tcp_port'], scan_mode=values['scan_mode'],
            scan_frequency_hz=self._scan_frequency_hz, data_timeout_s=values['data_timeout'],
            health_reset_attempts=values['health_reset_attempts'])
        self._driver: Optional[RplidarDriver] = None
        self._active = False
        self._latency_lock = threading.Lock()
        self._latencies_s = []
        self._last_report = (0, 0, StreamCounts(), time.monotonic())
        self._scan_pub = self.create_lifecycle_publisher(LaserScan, 'scan', SCAN_QOS)
        self._fixed_scan_pub = (self.create_lifecycle_publisher(LaserScan, 'scan_fixed', SCAN_QOS)
                                if self._fixed_beams else None)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_service(Empty, 'start_motor', self._start_motor)
        self.create_service(Empty, 'stop_motor', self._stop_motor)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        if self._autostart:
            if self.trigger_configure() == TransitionCallbackReturn.SUCCESS:
                self.trigger_activate()

    @property
    def driver(self) -> Optional[RplidarDriver]:
        """Give access to the RPLIDAR reader: its status and CPU time (None unconfigured)."""
        return self._driver

    def publish_latencies_s(self) -> list:
        """
        Return the recent delays from a turn's last byte to its LaserScan being published.

        :return: seconds, oldest first (at most the last 1000 turns)
        """
        with self._latency_lock:
            return list(self._latencies_s)

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Open the port and read the device info and health, the motor idle.

        With ``autostart`` the driver is left trying in the background (a device plugged in
        later is found); otherwise the transition fails, naming the likely cause, when the
        device has not answered within ``configure_timeout``.

        :param state: the state transitioned from
        :return: SUCCESS, or FAILURE without an answer
        """
        driver = RplidarDriver(self._config, self._publish_turn, self.get_logger())
        driver.set_motor(False)
        driver.start()
        self._driver = driver
        if self._autostart:
            return TransitionCallbackReturn.SUCCESS
        deadline = time.monotonic() + self._configure_timeout_s
        while time.monotonic() < deadline:
            status = driver.status()
            if status.state == DriverState.MOTOR_STOPPED:
                self.get_logger().info(f'configured: {status.device.describe()}, health '
                                       f'status {status.health.status}')
                return TransitionCallbackReturn.SUCCESS
            if status.state == DriverState.FAILED:
                break
            time.sleep(_POLL_S)
        reason = driver.status().message or 'no answer'
        self._close_driver()
        self.get_logger().error(f'configure failed: {reason}')
        return TransitionCallbackReturn.FAILURE

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Start the motor and the scan; publish.

        :param state: the state transitioned from
        :return: SUCCESS
        """
        self._active = True
        self._driver.set_motor(True)
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Stop publishing, the scan and the motor (the port stays open).

        :param state: the state transitioned from
        :return: SUCCESS
        """
        self._active = False
        self._driver.set_motor(False)
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Close the port.

        :param state: the state transitioned from
        :return: SUCCESS
        """
        self._close_driver()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Stop the motor and close the port, from any state.

        :param state: the state transitioned from
        :return: SUCCESS
        """
        self._active = False
        self._close_driver()
        return super().on_shutdown(state)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Stop the motor and close the port after a failed transition.

        :param state: the state transitioned from
        :return: SUCCESS (back to unconfigured)
        """
        self._active = False
        self._close_driver()
        return super().on_error(state)

    def destroy_node(self):
        """Stop the motor and close the port, whatever the state, then destroy the node."""
        self._active = False
        self._close_driver()
        super().destroy_node()

    def _close_driver(self):
        """
        Close the driver, which ends the scan and stops the motor the model's way.

        The driver's close sends STOP and then the model's motor-off (MOTOR_SPEED 0, PWM 0 or
        the DTR line) on the link it holds, without a new handshake: quick on every exit, and
        no error when the device is already gone.
        """
        driver, self._driver = self._driver, None
        if driver is not None:
            driver.close()

    def _change_state(self, request, response):
        """
        Serve change_state: refuse a transition the current state does not have, else make it.

        :param request: lifecycle_msgs/ChangeState request (transition id, or label)
        :param response: its response
        :return: the response, ``success`` False for a refused or failed transition
        """
        with self._transition_lock:
            _, state = self._state_machine.current_state
            available = {label: transition_id for transition_id, label, *_
                         in self._state_machine.available_transitions}
            asked = request.transition.label or str(request.transition.id)
            transition_id = (available.get(request.transition.label) if request.transition.label
                             else request.transition.id)
            if transition_id in _SHUTDOWN_TRANSITIONS:
                transition_id = available.get('shutdown')
            if transition_id not in available.values():
                self.get_logger().warning(
                    f'change_state: transition {asked} is not possible from the {state} state '
                    f'(possible: {", ".join(available) or "none"}): refused')
                response.success = False
                return response
            request.transition.id, request.transition.label = transition_id, ''
            try:
                return self._unguarded_change_state(request, response)
            except rclpy_implementation.RCLError as error:
                self.get_logger().error(f'change_state: transition {asked} from the {state} '
                                        f'state failed: {error}')
                response.success = False
                return response

    def _publish_turn(self, turn, mode):
        """Publish one turn as a LaserScan, and as a fixed-count one if asked (reader thread)."""
        if not self._active:
            return
        stamp_ns = _ros_minus_monotonic_ns(self.get_clock()) + int(turn.first_sample_s * 1e9)
        if stamp_ns < 0:
            # Under use_sim_time the ROS clock stands at 0 until /clock is heard.
            raise ValueError('the ROS clock is not running (use_sim_time is true and no /clock '
                             'has been received): turns are not published until it runs')
        stamp = Time(nanoseconds=stamp_ns).to_msg()
        multiple = compensation_multiple(mode.us_per_sample, self._scan_frequency_hz)
        self._scan_pub.publish(self._message(
            turn_to_scan(turn, self._angle_compensate, self._inverted, multiple,
                         self._orientation), stamp, mode.max_distance_m))
        if self._fixed_scan_pub is not None:
            self._fixed_scan_pub.publish(self._message(
                fixed_scan(turn, self._fixed_beams, self._inverted, self._orientation), stamp,
                mode.max_distance_m))
        latency_s = time.monotonic() - turn.last_byte_s
        with self._latency_lock:
            self._latencies_s.append(latency_s)
            del self._latencies_s[:-_LATENCY_WINDOW]

    def _message(self, scan: ScanArrays, stamp, range_max_m: float) -> LaserScan:
        """Return the LaserScan message of a laid-out turn."""
        msg = LaserScan()
        msg.header.frame_id = self._frame_id
        msg.header.stamp = stamp
        msg.angle_min = scan.angle_min
        msg.angle_max = scan.angle_max
        msg.angle_increment = scan.angle_increment
        msg.time_increment = scan.time_increment
        msg.scan_time = scan.scan_time
        msg.range_min = RANGE_MIN_M
        msg.range_max = range_max_m
        msg.ranges = array.array('f', scan.ranges.tobytes())
        msg.intensities = array.array('f', scan.intensities.tobytes())
        return msg

    def _start_motor(self, request, response):
        if self._motor_request_refused('start_motor'):
            return response
        self.get_logger().info('start_motor: starting the motor and the scan')
        self._driver.set_motor(True)
        return response

    def _stop_motor(self, request, response):
        if self._motor_request_refused('stop_motor'):
            return response
        self.get_logger().info('stop_motor: stopping the scan and idling the motor')
        self._driver.set_motor(False)
        return response

    def _motor_request_refused(self, service: str) -> bool:
        """Refuse a motor service call outside the active state (with a warning)."""
        if self._active:
            return False
        self.get_logger().warning(f'{service}: ignored while the node is not active (the '
                                  'lifecycle activate and deactivate transitions start and '
                                  'stop the motor)')
        return True

    def _publish_diagnostics(self):
        driver = self._driver
        if driver is None:
            self._publish_unconfigured()
            return
        status = driver.status()
        now = time.monotonic()
        turns, withheld_turns, stream, since = self._last_report
        rate_hz = (status.turns - turns) / max(now - since, 1e-9)
        recent = status.stream - stream
        recent_withheld = status.withheld_turns - withheld_turns
        self._last_report = (status.turns, status.withheld_turns, status.stream, now)
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
        byte_share = status.damage.byte_share
        withholding = status.state == DriverState.SCANNING and (
            status.damage.withheld or recent_withheld > 0)
        if withholding:
            # The decoder publishes no return it cannot vouch for: say so in plain words.
            level = max(level, DiagnosticStatus.WARN)
            measured = ('' if byte_share is None
                        else f' {100 * byte_share:.0f} % of bytes corrupted or lost,')
            count = (f' ({recent_withheld} turns published without their returns in the last '
                     f'{DIAGNOSTICS_PERIOD_S:g} s)' if recent_withheld else '')
            message = f'{message}; link damaged:{measured} scans withheld{count}'
        damaged = _share(recent.damaged_frames + recent.lost_frames, recent.frames)
        rejected = _share(recent.rejected_samples, recent.samples)
        if recent.resyncs or max(damaged, rejected) >= DAMAGED_LINK_SHARE:
            level = max(level, DiagnosticStatus.WARN)
            message = (f'{message}; damaged link: {100 * damaged:.1f} % of the frames damaged '
                       f'or lost, {100 * rejected:.1f} % of the samples rejected, '
                       f'{recent.resyncs} resyncs in the last {DIAGNOSTICS_PERIOD_S:g} s '
                       '(check the cable and the USB power)')
            if rate_hz == 0.0:
                # The driver withholds what it cannot decode with confidence: say so loudly.
                level = DiagnosticStatus.ERROR
                message = (f'{message}; nothing published: the stream is too damaged to '
                           'decode with confidence')
        values = {
            'state': status.state.value,
            'link': status.link,
            'scan rate (Hz)': f'{rate_hz:.2f}',
            'turns published': str(status.turns),
            'turns dropped': str(status.dropped_turns),
            'publishing state': 'withheld' if withholding else 'publishing',
            'turns withheld': str(status.withheld_turns),
            'bytes damaged (%)': 'n/a' if byte_share is None else f'{100 * byte_share:.2f}',
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

    def _publish_unconfigured(self):
        """Report that no device is open (lifecycle state unconfigured)."""
        array_msg = DiagnosticArray()
        array_msg.header.stamp = self.get_clock().now().to_msg()
        array_msg.status = [DiagnosticStatus(
            level=DiagnosticStatus.STALE, name=f'{self.get_name()}: RPLIDAR',
            message='unconfigured: no device open', hardware_id=self._serial_port or 'tcp',
            values=[KeyValue(key='state', value='unconfigured')])]
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
    """
    Run the node until Ctrl-C or SIGTERM, the way ros2/demos do on Jazzy.

    A bad start (bad ROS arguments, a parameter of the wrong type or out of range, an invalid
    channel_type) is one fatal log line and status 1, never a traceback. The first Ctrl-C ends
    the node; the ones after it are ignored (``ros2 launch`` forwards the terminal's again, and
    users press it twice), so the clean-up that stops the motor runs to its end. The executor's
    waits are bounded: rclpy's signal handler wakes it before it shuts the context down, and an
    unbounded wait would then sleep until the next message.

    :param args: command-line arguments for rclpy.init (default: sys.argv)
    :return: exit status: 0 on a clean end, 1 on a bad start
    """
    logger = rclpy.logging.get_logger('rplidar_node')
    interrupts = itertools.count()

    def interrupt_once(signal_number, frame):
        if next(interrupts) == 0:       # one C call: no window between the test and the count
            raise KeyboardInterrupt

    # Installed before rclpy.init, which chains its own handler (waking the executor) to it.
    signal.signal(signal.SIGINT, interrupt_once)
    try:
        rclpy.init(args=args)
    except (rclpy_implementation.RCLError, rclpy_implementation.UnknownROSArgsError) as error:
        logger.fatal(f'cannot start: {str(error).split(", at ")[0]}')
        return 1
    node = None
    try:
        node = RplidarNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (ParameterException, ValueError) as error:
        logger.fatal(str(error))
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
