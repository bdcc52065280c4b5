# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Messages in and out of the core: LaserScan checks, Features to wctls_msgs and RViz markers.

Everything here is message plumbing shared by the feature node and the offline bag tools; the
estimation itself lives in :mod:`wctls_ros.core`.
"""

import math

from geometry_msgs.msg import Point, Pose, PoseWithCovariance, Quaternion, Vector3
import numpy as np
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray
from wctls_msgs.msg import Corner, CornerArray, LineSegment, LineSegmentArray

from .core import CornerSet, ellipse, extract_features, FeatureConfig, Features, SegmentSet
from .params import MarkerStyle

# Rows/columns of (x, y, yaw) in a geometry_msgs 6x6 pose covariance (x, y, z, roll, pitch, yaw).
_POSE_INDEX = np.array([0, 1, 5])
# Height of the flat cylinders that draw covariance ellipses, m.
_ELLIPSE_THICKNESS_M = 0.005


def scan_problems(scan) -> list:
    """
    List what makes a LaserScan unusable (empty when it is fine).

    NaN and +-inf ranges are not problems: REP-117 uses them for invalid returns.

    :param scan: a sensor_msgs/LaserScan (rclpy or rosbags)
    :return: human-readable problems
    """
    problems = []
    count = len(scan.ranges)
    if count == 0:
        problems.append('it has no beams')
    if len(scan.intensities) not in (0, count):
        problems.append(f'{len(scan.intensities)} intensities for {count} ranges')
    fields = ('angle_min', 'angle_max', 'angle_increment', 'range_min', 'range_max')
    bad = [f for f in fields if not math.isfinite(getattr(scan, f))]
    if bad:
        problems.append('non-finite ' + ', '.join(bad))
        return problems
    if scan.angle_increment == 0.0 and count > 1:
        problems.append('angle_increment is 0')
    elif count > 1:
        last = scan.angle_min + (count - 1) * scan.angle_increment
        if abs(last - scan.angle_max) > 0.5 * abs(scan.angle_increment) + 1e-6:
            problems.append(f'angle_max {scan.angle_max:.6f} disagrees with angle_min + '
                            f'(N - 1) * angle_increment = {last:.6f}')
    if not 0.0 <= scan.range_min < scan.range_max:
        problems.append(f'range limits [{scan.range_min}, {scan.range_max}] are not ordered')
    return problems


def scan_features(scan, config: FeatureConfig):
    """
    Extract the features of a LaserScan, or explain why it cannot be used.

    :param scan: a sensor_msgs/LaserScan (rclpy or rosbags)
    :param config: the pipeline configuration
    :return: (Features, problems): empty features and the reasons when the scan is unusable
    """
    problems = scan_problems(scan)
    if not problems:
        try:
            return extract_features(np.asarray(scan.ranges, dtype=float), scan.angle_min,
                                    scan.angle_increment, config, scan.range_min,
                                    scan.range_max), problems
        except ValueError as error:
            problems = [str(error)]
    return Features(config.method, SegmentSet.empty(), CornerSet.empty()), problems


def _quaternion_from_yaw(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))


def pose_covariances(covariance_xy_yaw: np.ndarray) -> np.ndarray:
    """
    Lay out (x, y, yaw) covariances as row-major 6x6 pose covariances.

    :param covariance_xy_yaw: shape (C, 3, 3)
    :return: shape (C, 36); the z, roll and pitch rows and columns are 0
    """
    full = np.zeros((len(covariance_xy_yaw), 6, 6))
    full[:, _POSE_INDEX[:, None], _POSE_INDEX[None, :]] = covariance_xy_yaw
    return full.reshape(-1, 36)


def corner_array(features: Features, header) -> CornerArray:
    """
    Convert the corners of one scan to a CornerArray.

    :param features: output of ``extract_features``
    :param header: the scan's header (copied)
    :return: the message
    """
    corners = features.corners
    covariances = pose_covariances(corners.covariance)
    messages = [
        Corner(pose=PoseWithCovariance(pose=Pose(position=Point(x=x, y=y, z=0.0),
                                                 orientation=_quaternion_from_yaw(yaw)),
                                       covariance=covariance),
               first_line=first, second_line=second, opening_angle=opening)
        for (x, y), yaw, covariance, opening, first, second in zip(
            corners.xy_m.tolist(), corners.yaw_rad.tolist(), covariances,
            corners.opening_angle_rad.tolist(), corners.first_segment.tolist(),
            corners.second_segment.tolist())]
    return CornerArray(header=header, method=features.method, corners=messages)


def line_segment_array(features: Features, header) -> LineSegmentArray:
    """
    Convert the segments of one scan to a LineSegmentArray.

    :param features: output of ``extract_features``
    :param header: the scan's header (copied)
    :return: the message
    """
    s = features.segments
    messages = [
        LineSegment(angle=angle, radius=radius, covariance=covariance,
                    start=Point(x=start[0], y=start[1], z=0.0),
                    end=Point(x=end[0], y=end[1], z=0.0),
                    first_index=first, last_index=last, num_points=count)
        for angle, radius, covariance, start, end, first, last, count in zip(
            s.angle_rad.tolist(), s.radius_m.tolist(), s.covariance.reshape(-1, 4),
            s.start_xy_m.tolist(), s.end_xy_m.tolist(), s.first_index.tolist(),
            s.last_index.tolist(), s.num_points.tolist())]
    return LineSegmentArray(header=header, method=features.method, segments=messages)


def _marker(header, namespace, marker_id, marker_type, color, scale, position=(0.0, 0.0, 0.0),
            **fields) -> Marker:
    pose = Pose(position=Point(x=position[0], y=position[1], z=position[2]),
                orientation=Quaternion(w=1.0))
    return Marker(header=header, ns=namespace, id=marker_id, type=marker_type,
                  action=Marker.ADD, pose=pose,
                  scale=Vector3(x=scale[0], y=scale[1], z=scale[2]),
                  color=ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3]), **fields)


def marker_array(features: Features, header, style: MarkerStyle = MarkerStyle()) -> MarkerArray:
    """
    Draw one scan's features: segments, corners with ids, and covariance ellipses.

    The array starts with a DELETEALL marker, so features of earlier scans never linger.

    :param features: output of ``extract_features``
    :param header: the scan's header (copied)
    :param style: sizes and the ellipse scale
    :return: the markers
    """
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    segments, corners = features.segments, features.corners
    if len(segments):
        ends = np.stack([segments.start_xy_m, segments.end_xy_m], 1).reshape(-1, 2).tolist()
        markers.append(_marker(header, 'segments', 0, Marker.LINE_LIST, (0.1, 0.5, 1.0, 1.0),
                               (style.line_width_m, 0.0, 0.0),
                               points=[Point(x=x, y=y, z=0.0) for x, y in ends]))
    if len(corners):
        size = style.corner_size_m
        markers.append(_marker(header, 'corners', 0, Marker.SPHERE_LIST, (1.0, 0.2, 0.2, 1.0),
                               (size, size, size),
                               points=[Point(x=x, y=y, z=0.0) for x, y in corners.xy_m.tolist()]))
        shape = ellipse(corners.covariance[:, :2, :2])
        scale = 2.0 * style.ellipse_sigma * style.ellipse_scale
        for i, ((x, y), major, minor, orientation) in enumerate(zip(
                corners.xy_m.tolist(), shape.semi_major.tolist(), shape.semi_minor.tolist(),
                shape.orientation_rad.tolist())):
            markers.append(_marker(header, 'corner_ids', i, Marker.TEXT_VIEW_FACING,
                                   (1.0, 1.0, 1.0, 1.0), (0.0, 0.0, 2.0 * size),
                                   (x, y, 2.0 * size), text=str(i)))
            # A flat elliptic cylinder: one marker per ellipse, no outline points to send.
            ellipse_marker = _marker(header, 'ellipses', i, Marker.CYLINDER, (1.0, 0.6, 0.0, 0.5),
                                     (scale * major, scale * minor, _ELLIPSE_THICKNESS_M),
                                     (x, y, 0.0))
            ellipse_marker.pose.orientation = _quaternion_from_yaw(orientation)
            markers.append(ellipse_marker)
    return MarkerArray(markers=markers)
