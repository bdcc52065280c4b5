# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The estimation core of wctls_ros: numpy arrays in and out, loops compiled by numba, no ROS.

One entry point serves the nodes, the tools and users' scripts::

    from wctls_ros.core import extract_features, FeatureConfig

    features = extract_features(ranges, angle_min, angle_increment, FeatureConfig(method='wctls'))
    for corner in features.corners:
        print(corner.x_m, corner.y_m, corner.position_covariance)

Positions are in m, angles in rad, covariances in SI units, all in the scan's frame.
"""

from .config import FeatureConfig, METHODS, validation_errors
from .corners import find_corners, intersect
from .features import Corner, CornerSet, Features, Segment, SegmentSet
from .lines import fit_lines, LineFits, normal_form, segment_returns, SegmentReturns
from .pipeline import extract_features
from .precompile import warm_up
from .scan import scan_to_points, ScanError, ScanPoints
from .uncertainty import confidence_scale, Ellipse, ellipse, nees

__all__ = [
    'Corner', 'CornerSet', 'Ellipse', 'FeatureConfig', 'Features', 'LineFits', 'METHODS',
    'ScanError', 'ScanPoints', 'Segment', 'SegmentReturns', 'SegmentSet', 'confidence_scale',
    'ellipse', 'extract_features', 'find_corners', 'fit_lines', 'intersect', 'nees',
    'normal_form', 'scan_to_points', 'segment_returns', 'validation_errors', 'warm_up',
]
