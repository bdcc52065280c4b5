# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
feature_node: LaserScan in; corners, line segments and RViz markers out, once per scan.

Subscribes ``scan`` (sensor_msgs/LaserScan, best effort, so reliable and best-effort
publishers both reach it) and publishes ``corners`` (wctls_msgs/CornerArray), ``lines``
(wctls_msgs/LineSegmentArray: every segment, each flagged a line landmark or not,
:mod:`wctls_ros.core.landmarks`) and ``markers`` (visualization_msgs/MarkerArray), each with the
scan's header. Topic names are relative, so they follow the node's namespace and remappings.
The input queue holds one scan: a node that falls behind processes the newest scan and counts
the ones it skipped (from the publisher's sequence numbers: skipped while busy or lost on the
way), in a throttled warning and on ``/diagnostics`` (1 Hz), with DDS's own count of lost scans.

The scan is taken as its CDR bytes and decoded, and the outputs are built, serialised and
published as CDR bytes. With rosbags installed its message classes do it, in a fraction of the
time rclpy's take (docs/results/message_path.md), with the same bytes on the wire, as long as
rosbags' definitions are this ROS install's (the node checks the type hashes at start-up);
otherwise rclpy's classes do (a stock ROS install has no rosbags).

The feature pipeline starts at once: the numpy one, while a thread loads the compiled one from
numba's cache (about a second) or, on the first start on a machine, has it compiled in another
process (about 15 s); the compiled one takes over when ready (:mod:`wctls_ros.core.runtime`).
Each step is logged.

A lifecycle node (rclpy.lifecycle), like rplidar_node: configure reads and checks the
parameters and creates the publishers, activate subscribes ``scan`` and publishes, deactivate
unsubscribes (nothing is published), cleanup frees the publishers, shutdown (from any state)
frees everything. ``/diagnostics`` is published in every state. With ``autostart`` (the
default) the node configures and activates itself at start, so a plain ``ros2 run`` and the
launch files work at once; without it a lifecycle manager drives the transitions.
"""

from dataclasses import dataclass, field
import statistics
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

from .conversions import (copy_header, corner_array, dock_marker, dock_pose_messages,
                          line_segment_array, marker_array, MessageTypes, mismatched_types,
                          rclpy_types, scan_features, typestore)
from .core import (CoreStatus, CornerSet, Features, line_landmarks, SegmentSet,
                   start as start_core, status as core_status)
from .extras import missing_extra
from .frontend.dock import dock_returns, find_docks, track_dock, TrackerState
from .landmark_messages import landmark_array, landmark_markers, LandmarkStream
from .landmark_publishers import bridge_names, BridgePublishers
from .node_main import declare_parameters, run_node
from .outputs import (codec_types, CORNERS, DOCK_OUTPUTS, FEATURES, LANDMARK_MARKERS,
                      LANDMARK_OUTPUTS, LANDMARKS, LINES, MARKERS, message_class, SCAN, Topic)
from .params import AUTOSTART, dock_settings, FEATURE_NODE, feature_settings, landmark_settings

# A throttled warning repeats at most this often, s.
WARN_PERIOD_S = 5.0
DIAGNOSTICS_PERIOD_S = 1.0
# The sensor-data profile with a queue of one scan: when extraction falls behind, DDS keeps the
# newest scan only, and the node never works through a backlog of stale ones.
SCAN_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


@dataclass
class ScanCounters:
    """
    What happened to the scans, since start-up and since the last diagnostics report.

    :ivar processed: scans turned into features and published
    :ivar skipped: scans missing from the publisher's sequence numbers: overwritten in the
        one-scan queue while the node was busy, or lost on the way (rclpy cannot tell which);
        counted while one publisher is matched (rclpy does not say which publisher sent a scan)
    :ivar lost: scans DDS reports lost (its message-lost event; Fast DDS counts a best-effort
        scan replaced in the queue as lost too, so these overlap with ``skipped``)
    :ivar malformed: scans dropped because they cannot be interpreted (published empty) or
        not even decoded (not published: they have no header to publish with)
    :ivar work_limited: scans on which the per-scan work bound stopped splitting early
    :ivar implausible_noise: scans dropped because their range-noise estimate exceeded
        max_range_sigma_m (published empty)
    :ivar implausible_features: segments and corners left out because their position std was
        beyond the plausibility bound for their range
    :ivar seconds: extraction and publishing time of each scan since the last report, s
    """

    processed: int = 0
    skipped: int = 0
    lost: int = 0
    malformed: int = 0
    work_limited: int = 0
    implausible_noise: int = 0
    implausible_features: int = 0
    seconds: list = field(default_factory=list)


class FeatureNode(LifecycleNode):
    """
    Extract corners and segments with covariances from every LaserScan (a lifecycle node).

    :param kwargs: passed to ``LifecycleNode.__init__`` (e.g. ``context``,
        ``parameter_overrides``)
    :raises ValueError: with ``autostart``, on parameters that make no valid configuration
    """

    def __init__(self, **kwargs):
        super().__init__('feature_node', **kwargs)
        values = declare_parameters(self, FEATURE_NODE)
        # As ros2/demos do: a change is checked whole before it is accepted, applied after.
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._total, self._recent = ScanCounters(), ScanCounters()
        self._last_sequence = None
        self._dds_lost_total = 0
        self._frame_id = ''
        self._configured = False
        self._scans = None
        self._dock = None
        self._dock_publishers: tuple = ()
        self._dock_services: tuple = ()
        self._detecting = False
        self._dock_track = TrackerState()
        self._docks_published = 0
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        if values[AUTOSTART]:
            feature_settings(values)          # a bad configuration ends ros2 run: status 1
            bridge_names(str(values['landmark_bridges']))
            if self.trigger_configure() == TransitionCallbackReturn.SUCCESS:
                self.trigger_activate()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Read and check the parameters, create the publishers, start loading the pipeline.

        :param state: the state transitioned from
        :return: SUCCESS, or FAILURE (the reason logged) on an invalid configuration
        """
        try:
            self._config, self._style, self._publish_markers = self._settings()
            values = self._values()
            self._dock = dock_settings(values)
            self._publish_landmarks, *step_sigmas = landmark_settings(values)
            bridge_names(str(values['landmark_bridges']))
        except ValueError as error:
            self.get_logger().error(f'configure failed: {error}')
            return TransitionCallbackReturn.FAILURE
        self._landmark_stream = LandmarkStream(*step_sigmas)
        self._corners = self._create_publisher(CORNERS)
        self._lines = self._create_publisher(LINES)
        self._markers = self._create_publisher(MARKERS)
        self._landmarks = self._create_publisher(LANDMARKS)
        self._landmark_markers = self._create_publisher(LANDMARK_MARKERS)
        self._bridges = BridgePublishers(self, str(values['landmark_bridges']))
        if self._dock is not None:
            self._configure_dock()
        self._configured = True
        # Never waits for a compile: the numpy pipeline serves until the compiled one is ready
        # (the process's one choice: a second configure is told the same).
        self.get_logger().info(start_core(on_change=self._on_core_change).describe())
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Subscribe to the scans and publish the features of each.

        :param state: the state transitioned from
        :return: SUCCESS
        """
        # The scan arrives as its CDR bytes, decoded with the same classes the outputs are
        # built with (rosbags' decode in about half the time rclpy's take).
        self._last_sequence = None
        self._scans = self.create_subscription(
            message_class(SCAN.type_name), SCAN.name, self._on_scan, SCAN_QOS, raw=True,
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_scans_lost))
        self._types = self._message_types()
        self.get_logger().info(f'extracting features with {self._config.method} from '
                               f'{self.resolve_topic_name("scan")}')
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Unsubscribe from the scans; nothing is published until activated again.

        :param state: the state transitioned from
        :return: SUCCESS
        """
        self._unsubscribe()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Free the publishers; configure reads the parameters again.

        :param state: the state transitioned from
        :return: SUCCESS
        """
        self._free_publishers()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """
        Unsubscribe and free the publishers, from any state.

        :param state: the state transitioned from
        :return: SUCCESS
        """
        self._unsubscribe()
        self._free_publishers()
        return super().on_shutdown(state)

    def _configure_dock(self) -> None:
        """Create the dock's publishers and the services that start and stop its detection."""
        # Reliable, keep last 10: what opennav_docking subscribes detected_dock_pose with.
        self._dock_publishers = tuple(map(self._create_publisher, DOCK_OUTPUTS))
        self._dock_services = tuple(
            self.create_service(Trigger, f'~/{name}_dock_detection', callback)
            for name, callback in (('start', self._start_detection),
                                   ('stop', self._stop_detection),
                                   ('toggle', self._toggle_detection)))
        self._detecting = self._dock.detect_at_start
        self._dock_track = TrackerState()

    def _start_detection(self, request, response):
        return self._set_detection(True, response)

    def _stop_detection(self, request, response):
        return self._set_detection(False, response)

    def _toggle_detection(self, request, response):
        # opennav_docking calls its one detector service to start and again to stop.
        return self._set_detection(not self._detecting, response)

    def _set_detection(self, on: bool, response):
        """Turn dock detection on or off; answer a std_srvs/Trigger call."""
        if on and not self._detecting:
            self._dock_track = TrackerState()       # start afresh: confirm the dock again
        self._detecting = on
        response.success = True
        response.message = f'dock detection {"on" if on else "off"}' + (
            '' if self._scans is not None else ' (the node is not active: no scans yet)')
        self.get_logger().info(response.message)
        return response

    def _unsubscribe(self) -> None:
        scans, self._scans = self._scans, None
        if scans is not None:
            self.destroy_subscription(scans)

    def _free_publishers(self) -> None:
        if self._configured:
            for publisher in (self._corners, self._lines, self._markers, self._landmarks,
                              self._landmark_markers, *self._bridges.publishers,
                              *self._dock_publishers):
                self.destroy_publisher(publisher)
            for service in self._dock_services:
                self.destroy_service(service)
        self._dock_publishers, self._dock_services = (), ()
        self._configured = False

    def _create_publisher(self, topic: Topic):
        """Create the lifecycle publisher of one of our topics (:mod:`wctls_ros.outputs`)."""
        return self.create_lifecycle_publisher(message_class(topic.type_name), topic.name, 10)

    def _message_types(self) -> MessageTypes:
        """Choose the classes the scan is decoded and the outputs built with: rosbags' if fit."""
        mine = (self.get_name(), self.get_namespace())
        publishers = (self._corners, self._lines, self._markers, self._landmarks,
                      self._landmark_markers, *self._dock_publishers)
        endpoints = [info for publisher in publishers
                     for info in self.get_publishers_info_by_topic(publisher.topic_name)]
        endpoints += self.get_subscriptions_info_by_topic(self._scans.topic_name)
        # The type hashes of this node's own endpoints, for every type it builds or decodes
        # with the codec; one not seen yet (discovery) counts as unknown, never as fit.
        installed = {info.topic_type: str(info.topic_type_hash) for info in endpoints
                     if (info.node_name, info.node_namespace) == mine}
        expected = codec_types(FEATURES + LANDMARK_OUTPUTS
                               + (DOCK_OUTPUTS if self._dock_publishers else ()))
        try:
            store = typestore()
        except ImportError as error:
            self.get_logger().info(
                "decoding scans and building the outputs with rclpy's message classes: "
                f'{missing_extra(error) or error}')
            return rclpy_types()
        unseen = [name for name in expected if name not in installed]
        mismatched = mismatched_types(store, {name: installed[name] for name in expected
                                              if name in installed})
        if not unseen and not mismatched:
            return MessageTypes.from_typestore(store)
        reason = (f"rosbags' definitions of {', '.join(mismatched)} are not this ROS install's"
                  if mismatched else
                  f"this node's own endpoints of {', '.join(unseen)} were not discovered")
        self.get_logger().warning(
            "decoding scans and building the outputs with rclpy's message classes (slower): "
            f'{reason}')
        return rclpy_types()

    def _on_core_change(self, status: CoreStatus) -> None:
        """Log a compile's start, and which pipeline serves in the end (called from a thread)."""
        self.get_logger().info(f'now running the {status.describe()}' if status.name == 'numba'
                               else status.describe())

    def _values(self, changes=()) -> dict:
        """Return the current parameter values with ``changes`` applied."""
        values = {spec.name: self.get_parameter(spec.name).value for spec in FEATURE_NODE}
        values.update({p.name: p.value for p in changes if p.name in values})
        return values

    def _settings(self, changes=()):
        """Return the settings of the current parameters with ``changes`` applied (validated)."""
        return feature_settings(self._values(changes))

    def _check_parameters(self, changes) -> SetParametersResult:
        try:
            self._settings(changes)
            dock_settings(self._values(changes))
        except (ValueError, TypeError) as error:
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, changes) -> None:
        # Takes effect on the next scan (callbacks of this node never run concurrently);
        # unconfigured, configure reads them.
        if self._configured:
            self._config, self._style, self._publish_markers = self._settings()
            values = self._values()
            self._dock = dock_settings(values)
            self._publish_landmarks, *step_sigmas = landmark_settings(values)
            self._landmark_stream.motion = LandmarkStream(*step_sigmas).motion

    @property
    def counters(self) -> ScanCounters:
        """Give the scan counts since start-up (also on /diagnostics)."""
        return self._total

    def _count(self, name: str, amount: int = 1):
        for counters in (self._total, self._recent):
            setattr(counters, name, getattr(counters, name) + amount)

    def _on_scans_lost(self, status) -> None:
        # From DDS's running total, which only grows here: its change field read 2^32 - 1 (a
        # count gone back by one, unsigned) after a large message was dropped.
        if status.total_count > self._dds_lost_total:
            self._count('lost', status.total_count - self._dds_lost_total)
            self._dds_lost_total = status.total_count

    def _count_skipped(self, info: dict):
        """Count the gaps in the publication sequence: scans skipped while busy, or lost."""
        sequence = info.get('publication_sequence_number')
        # Each publisher numbers its own messages, and rclpy does not say which one sent a
        # scan: with several, a gap is not a gap.
        if sequence is None or self._scans.get_publisher_count() != 1:
            self._last_sequence = None
            return
        if self._last_sequence is not None and sequence > self._last_sequence + 1:
            self._count('skipped', sequence - self._last_sequence - 1)
            last = self._recent.seconds[-1:] or [0.0]
            self.get_logger().warning(
                f'falling behind or losing scans: {self._total.skipped} scans skipped so far '
                f'(the last took {1e3 * last[0]:.1f} ms); the newest scan is processed, never a '
                'backlog',
                throttle_duration_sec=WARN_PERIOD_S)
        self._last_sequence = sequence

    def _extract(self, scan) -> Features:
        features, problems = scan_features(scan, self._config)
        if problems:
            self._count('malformed')
            self.get_logger().warning(
                f'dropping a scan from {scan.header.frame_id!r}: ' + '; '.join(problems),
                throttle_duration_sec=WARN_PERIOD_S)
        if features.work_limited:
            self._count('work_limited')
            self.get_logger().warning(
                f'a scan from {scan.header.frame_id!r} needed more splitting than the per-scan '
                'work bound allows; its returns that are still not straight were left out',
                throttle_duration_sec=WARN_PERIOD_S)
        if features.noise_implausible:
            self._count('implausible_noise')
            self.get_logger().warning(
                f'dropping a scan from {scan.header.frame_id!r}: its returns scatter '
                f'{1e3 * features.range_sigma_m:.0f} mm about their neighbours, beyond '
                f'max_range_sigma_m ({1e3 * self._config.max_range_sigma_m:.0f} mm)',
                throttle_duration_sec=WARN_PERIOD_S)
        if features.implausible_features:
            self._count('implausible_features', features.implausible_features)
        return features

    def _publish_tracks(self, features: Features, scan, header, types: MessageTypes) -> None:
        """Track the scan's landmarks; publish them with their ids, and on every bridge."""
        detections, tracked = self._landmark_stream.track(
            features, scan, self._config.max_landmark_angle_sigma_rad)
        self._landmarks.publish(types.serialize(landmark_array(detections, tracked, header,
                                                               types)))
        if self._landmark_markers.get_subscription_count():
            self._landmark_markers.publish(types.serialize(landmark_markers(
                detections, tracked, header, types, self._style.corner_size_m)))
        self._bridges.publish(detections, tracked, scan.header)

    def _on_scan(self, serialized: bytes, info: dict):
        started = time.perf_counter()
        self._count_skipped(info)
        types = self._types
        try:
            scan = types.deserialize(serialized, 'sensor_msgs/msg/LaserScan')
        except Exception as error:  # noqa: B902 - whatever bytes arrive, the node goes on
            self._count('malformed')
            self.get_logger().warning(f'dropping a scan that cannot be decoded: {error!r}',
                                      throttle_duration_sec=WARN_PERIOD_S)
            return
        self._frame_id = scan.header.frame_id
        try:
            features = self._extract(scan)
        except Exception as error:  # noqa: B902 - a bad scan must never stop the node
            self.get_logger().error(f'feature extraction failed: {error!r}',
                                    throttle_duration_sec=WARN_PERIOD_S)
            self._count('malformed')
            features = Features(self._config.method, SegmentSet.empty(), CornerSet.empty())
        try:
            header = copy_header(scan.header, types)
            self._corners.publish(types.serialize(corner_array(features, header, types)))
            is_landmark = line_landmarks(features.segments,
                                         self._config.max_landmark_angle_sigma_rad)
            self._lines.publish(types.serialize(
                line_segment_array(features, header, types, is_landmark=is_landmark)))
            if self._publish_landmarks:
                self._publish_tracks(features, scan, header, types)
            # Markers are costly to build (a Marker per corner label and ellipse): only for a
            # listener such as RViz.
            if self._publish_markers and self._markers.get_subscription_count():
                self._markers.publish(types.serialize(
                    marker_array(features, header, self._style, types, is_landmark=is_landmark)))
            if self._dock is not None and self._detecting:
                self._publish_dock(features, scan, header, types)
        except Exception:  # noqa: B902 - only a shutdown (Ctrl-C mid-callback) is expected here
            if self.context.ok():
                raise
            return
        self._count('processed')
        self._recent.seconds.append(time.perf_counter() - started)

    def _publish_dock(self, features: Features, scan, header, types: MessageTypes) -> None:
        """Look for the dock in the scan; publish its pose once the tracker confirms it."""
        stamp_s = header.stamp.sec + 1e-9 * header.stamp.nanosec
        returns = dock_returns(scan.ranges, scan.angle_min, scan.angle_increment, self._config,
                               features.range_sigma_m, scan.range_min, scan.range_max)
        candidates = find_docks(features.segments, features.corners, self._dock.shape, returns)
        self._dock_track, dock = track_dock(self._dock_track, candidates, stamp_s,
                                            self._dock.tracking)
        if dock is None:
            return
        for publisher, message in zip(self._dock_publishers,
                                      dock_pose_messages(dock, header, types)):
            publisher.publish(types.serialize(message))
        if self._publish_markers and self._markers.get_subscription_count():
            self._markers.publish(types.serialize(dock_marker(dock, header, types)))
        self._docks_published += 1

    def _publish_diagnostics(self):
        recent, self._recent = self._recent, ScanCounters()
        level, message = DiagnosticStatus.OK, 'extracting features'
        if recent.skipped or recent.malformed or recent.work_limited or recent.implausible_noise:
            level = DiagnosticStatus.WARN
            message = ', '.join(f'{count} scans {what}' for count, what in (
                (recent.skipped, 'skipped (busy or lost)'),
                (recent.malformed, 'dropped (malformed)'),
                (recent.implausible_noise, 'dropped (implausible noise)'),
                (recent.work_limited, 'over the work bound')) if count)
        elif self._scans is None:
            message = ('inactive: not subscribed to scans' if self._configured
                       else 'unconfigured: not subscribed to scans')
        elif not recent.processed:
            message = 'no scans'
        seconds = recent.seconds or [0.0]
        core = core_status()
        values = {
            # 'no' while the numpy pipeline serves until the compiled one is ready (a load of
            # about a second, or a compile on a machine's first start).
            'feature pipeline': core.name if core else 'none',
            'feature pipeline settled': 'no' if core is None or core.pending else 'yes',
            'scan topic': self.resolve_topic_name('scan'),
            'method': self._config.method if self._configured else 'none',
            'scans processed (last period)': recent.processed,
            'scans processed': self._total.processed,
            'scans skipped (busy or lost)': self._total.skipped,
            'scans lost (DDS message-lost events)': self._total.lost,
            # Sequence gaps say nothing with several publishers on the topic (see above).
            'scan publishers': self._scans.get_publisher_count() if self._scans else 0,
            'scans dropped (malformed)': self._total.malformed,
            'scans over the work bound': self._total.work_limited,
            'scans dropped (implausible noise)': self._total.implausible_noise,
            'features dropped (implausible covariance)': self._total.implausible_features,
            'processing time median (ms)': f'{1e3 * statistics.median(seconds):.2f}',
            'dock detection': ('not configured' if self._dock is None
                               else 'on' if self._detecting else 'off'),
            'dock poses published': self._docks_published,
            'processing time max (ms)': f'{1e3 * max(seconds):.2f}',
        }
        status = DiagnosticStatus(
            level=level, name=f'{self.get_fully_qualified_name()}: features',
            message=message, hardware_id=self._frame_id,
            values=[KeyValue(key=key, value=str(value)) for key, value in values.items()])
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(array)


def main(args=None) -> int:
    """Run the node until Ctrl-C or shutdown; exit 1 on an invalid configuration."""
    return run_node('feature_node', FeatureNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
