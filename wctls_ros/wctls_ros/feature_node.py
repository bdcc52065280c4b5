# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
feature_node: LaserScan in; corners, line segments and RViz markers out, once per scan.

Subscribes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS, so reliable and best-effort
publishers both reach it) and publishes ``corners`` (wctls_msgs/CornerArray), ``lines``
(wctls_msgs/LineSegmentArray) and ``markers`` (visualization_msgs/MarkerArray), each with the
scan's header. Topic names are relative, so they follow the node's namespace and remappings.
"""

import sys

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import MarkerArray
from wctls_msgs.msg import CornerArray, LineSegmentArray

from .conversions import corner_array, line_segment_array, marker_array, scan_features
from .core import CornerSet, Features, SegmentSet
from .node_main import declare_parameters, run_node
from .params import FEATURE_NODE, feature_settings

# A throttled warning repeats at most this often, s.
WARN_PERIOD_S = 5.0


class FeatureNode(Node):
    """Extract corners and segments with covariances from every LaserScan."""

    def __init__(self, **kwargs):
        super().__init__('feature_node', **kwargs)
        self._config, self._style, self._publish_markers = feature_settings(
            declare_parameters(self, FEATURE_NODE))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._corners = self.create_publisher(CornerArray, 'corners', 10)
        self._lines = self.create_publisher(LineSegmentArray, 'lines', 10)
        self._markers = self.create_publisher(MarkerArray, 'markers', 10)
        self.create_subscription(LaserScan, 'scan', self._on_scan, qos_profile_sensor_data)
        self.get_logger().info(f'extracting features with {self._config.method} from '
                               f'{self.resolve_topic_name("scan")}')

    def _on_set_parameters(self, changes) -> SetParametersResult:
        values = {spec.name: self.get_parameter(spec.name).value for spec in FEATURE_NODE}
        values.update({p.name: p.value for p in changes if p.name in values})
        try:
            settings = feature_settings(values)
        except (ValueError, TypeError) as error:
            return SetParametersResult(successful=False, reason=str(error))
        # Takes effect on the next scan (callbacks of this node never run concurrently).
        self._config, self._style, self._publish_markers = settings
        return SetParametersResult(successful=True)

    def _extract(self, scan: LaserScan) -> Features:
        features, problems = scan_features(scan, self._config)
        if problems:
            self.get_logger().warning(
                f'dropping a scan from {scan.header.frame_id!r}: ' + '; '.join(problems),
                throttle_duration_sec=WARN_PERIOD_S)
        return features

    def _on_scan(self, scan: LaserScan):
        try:
            features = self._extract(scan)
        except Exception as error:  # noqa: B902 - a bad scan must never stop the node
            self.get_logger().error(f'feature extraction failed: {error!r}',
                                    throttle_duration_sec=WARN_PERIOD_S)
            features = Features(self._config.method, SegmentSet.empty(), CornerSet.empty())
        try:
            self._corners.publish(corner_array(features, scan.header))
            self._lines.publish(line_segment_array(features, scan.header))
            # Markers are costly to build (a Marker per corner label and ellipse): only for a
            # listener such as RViz.
            if self._publish_markers and self._markers.get_subscription_count():
                self._markers.publish(marker_array(features, scan.header, self._style))
        except Exception:  # noqa: B902 - only a shutdown (Ctrl-C mid-callback) is expected here
            if self.context.ok():
                raise


def main(args=None) -> int:
    """Run the node until Ctrl-C or shutdown; exit 1 on an invalid configuration."""
    return run_node('feature_node', FeatureNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
