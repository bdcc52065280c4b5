# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
feature_node: LaserScan in; corners, line segments and RViz markers out, once per scan.

Subscribes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS, so reliable and best-effort
publishers both reach it) and publishes ``corners`` (wctls_msgs/CornerArray), ``lines``
(wctls_msgs/LineSegmentArray) and ``markers`` (visualization_msgs/MarkerArray), each with the
scan's header. Topic names are relative, so they follow the node's namespace and remappings.
"""

from dataclasses import dataclass
import math
import sys
from typing import Optional

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import MarkerArray
from wctls_msgs.msg import CornerArray, LineSegmentArray

from .conversions import corner_array, line_segment_array, marker_array, MarkerStyle, scan_features
from .core import CornerSet, FeatureConfig, Features, METHODS, SegmentSet
from .node_main import run_node

# A throttled warning repeats at most this often, s.
WARN_PERIOD_S = 5.0


@dataclass(frozen=True)
class ParameterSpec:
    """
    One parameter of the node: its default, meaning and allowed values.

    :ivar name: ROS parameter name
    :ivar default: default value (its type is the parameter's type)
    :ivar description: what it means, with its unit
    :ivar limits: (low, high) for numbers, inclusive; None for strings and booleans
    :ivar field: the FeatureConfig / MarkerStyle field it sets (None: node option)
    :ivar to_field: converts the parameter value to the field's unit
    """

    name: str
    default: object
    description: str
    limits: Optional[tuple] = None
    field: Optional[str] = None
    to_field: object = None

    def descriptor(self) -> ParameterDescriptor:
        """
        Return the ROS descriptor with the description and the range.

        :return: the descriptor
        """
        descriptor = ParameterDescriptor(name=self.name, description=self.description)
        if isinstance(self.default, bool) or self.limits is None:
            return descriptor
        low, high = self.limits
        if isinstance(self.default, int):
            descriptor.integer_range = [IntegerRange(from_value=low, to_value=high, step=1)]
        else:
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
        return descriptor


_DEFAULTS = FeatureConfig()
_STYLE = MarkerStyle()
FEATURE_PARAMETERS = (
    ParameterSpec('method', _DEFAULTS.method,
                  'Line fit whose covariance is propagated: ' + ' | '.join(METHODS),
                  field='method'),
    ParameterSpec('range_sigma_m', _DEFAULTS.range_sigma_m,
                  'Std of the range noise, m (RPLIDAR S1 datasheet: 0.05)', (1e-4, 10.0),
                  'range_sigma_m'),
    ParameterSpec('bearing_sigma_deg', round(math.degrees(_DEFAULTS.bearing_sigma_rad), 6),
                  'Std of the bearing noise, deg (RPLIDAR S1 datasheet: 0.391)', (0.0, 10.0),
                  'bearing_sigma_rad', math.radians),
    ParameterSpec('common_range_sigma_m', _DEFAULTS.common_range_sigma_m,
                  'Std of a range offset shared by all beams of a scan, m (calibrate prints it)',
                  (0.0, 1.0), 'common_range_sigma_m'),
    ParameterSpec('range_min_m', _DEFAULTS.range_min_m,
                  'Ignore returns closer than this (besides the scan range_min), m', (0.0, 1e3),
                  'range_min_m'),
    ParameterSpec('range_max_m', 1e3,
                  'Ignore returns farther than this (besides the scan range_max), m', (0.0, 1e3),
                  'range_max_m'),
    ParameterSpec('breakpoint_lambda_deg', round(math.degrees(_DEFAULTS.breakpoint_lambda_rad), 6),
                  'Adaptive breakpoint rule: worst incidence angle of one surface, deg',
                  (0.5, 89.0), 'breakpoint_lambda_rad', math.radians),
    ParameterSpec('iepf_threshold_m', _DEFAULTS.iepf_threshold_m,
                  'Iterative End Point Fit split distance, m (paper: 0.04)', (1e-4, 10.0),
                  'iepf_threshold_m'),
    ParameterSpec('merge_chi2', _DEFAULTS.merge_chi2,
                  'Merge neighbouring segments below this chi2 (2 dof) of their line '
                  'difference; 0 disables merging', (0.0, 1e6), 'merge_chi2'),
    ParameterSpec('end_offset_sigmas', _DEFAULTS.end_offset_sigmas,
                  'Cut the last k returns of a segment end when their residuals sum to more '
                  'than this many sigmas times sqrt(k) (another surface); 0 disables',
                  (0.0, 1e3), 'end_offset_sigmas'),
    ParameterSpec('min_segment_points', _DEFAULTS.min_segment_points,
                  'Drop segments with fewer returns', (3, 100000), 'min_segment_points'),
    ParameterSpec('min_segment_length_m', _DEFAULTS.min_segment_length_m,
                  'Drop segments shorter than this, m', (0.0, 100.0), 'min_segment_length_m'),
    ParameterSpec('min_corner_angle_deg', round(math.degrees(_DEFAULTS.min_corner_angle_rad), 6),
                  'No corner between walls closer to parallel than this, deg', (0.1, 90.0),
                  'min_corner_angle_rad', math.radians),
    ParameterSpec('max_corner_gap_m', _DEFAULTS.max_corner_gap_m,
                  'No corner farther than this from either wall end (virtual intersection), m',
                  (1e-3, 100.0), 'max_corner_gap_m'),
)
MARKER_PARAMETERS = (
    ParameterSpec('publish_markers', True, 'Publish visualization_msgs/MarkerArray on markers'),
    ParameterSpec('marker_ellipse_sigma', _STYLE.ellipse_sigma,
                  'Draw the k-sigma covariance ellipse of each corner', (0.1, 10.0),
                  'ellipse_sigma'),
    ParameterSpec('marker_ellipse_scale', _STYLE.ellipse_scale,
                  'Extra magnification of the drawn ellipses (the paper draws them x10)',
                  (0.1, 1000.0), 'ellipse_scale'),
    ParameterSpec('marker_line_width_m', _STYLE.line_width_m,
                  'Width of the segment lines, m', (1e-4, 1.0), 'line_width_m'),
)
PARAMETERS = FEATURE_PARAMETERS + MARKER_PARAMETERS


def _fields(specs, values: dict) -> dict:
    return {spec.field: (spec.to_field or (lambda v: v))(values[spec.name])
            for spec in specs if spec.field}


def settings_from_parameters(values: dict):
    """
    Build the validated pipeline configuration and marker style from parameter values.

    :param values: parameter name -> value, for every name in PARAMETERS
    :return: (FeatureConfig, MarkerStyle, publish_markers)
    :raises ValueError: with every reason when the values do not make a valid configuration
    """
    return (FeatureConfig(**_fields(FEATURE_PARAMETERS, values)),
            MarkerStyle(**_fields(MARKER_PARAMETERS, values)), bool(values['publish_markers']))


class FeatureNode(Node):
    """Extract corners and segments with covariances from every LaserScan."""

    def __init__(self, **kwargs):
        super().__init__('feature_node', **kwargs)
        for spec in PARAMETERS:
            self.declare_parameter(spec.name, spec.default, spec.descriptor())
        self._config, self._style, self._publish_markers = settings_from_parameters(
            {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS})
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._corners = self.create_publisher(CornerArray, 'corners', 10)
        self._lines = self.create_publisher(LineSegmentArray, 'lines', 10)
        self._markers = self.create_publisher(MarkerArray, 'markers', 10)
        self.create_subscription(LaserScan, 'scan', self._on_scan, qos_profile_sensor_data)
        self.get_logger().info(f'extracting features with {self._config.method} from '
                               f'{self.resolve_topic_name("scan")}')

    def _on_set_parameters(self, changes) -> SetParametersResult:
        values = {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS}
        values.update({p.name: p.value for p in changes if p.name in values})
        try:
            settings = settings_from_parameters(values)
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
