# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The estimation core of wctls_ros: numpy arrays in and out, no ROS.

One entry point serves the nodes, the tools and users' scripts::

    from wctls_ros.core import extract_features, FeatureConfig

    features = extract_features(ranges, angle_min, angle_increment, FeatureConfig(method='wctls'))
    for corner in features.corners:
        print(corner.x_m, corner.y_m, corner.position_covariance)

Positions are in m, angles in rad, covariances in SI units, all in the scan's frame.

The pipeline has two implementations with the same results: compiled loops (numba,
:mod:`.numba_core`) and batched numpy (:mod:`.numpy_core`). :func:`extract_features` runs the
compiled one when numba gives it and the numpy one otherwise (:mod:`.runtime`, where the
environment variable ``WCTLS_ROS_CORE`` can force either); importing this package imports no
numba. The line fits and corner intersections offered on their own (:func:`fit_lines`,
:func:`find_corners`, :func:`corner_covariance`, ...) are the numpy implementation's.
"""

from .config import FeatureConfig, METHODS, validation_errors
from .features import (Corner, CornerSet, Features, LineFits, Segment, segment_returns,
                       SegmentReturns, SegmentSet)
from .landmarks import angle_sigma_rad, line_landmarks
from .numpy_core.corners import corner_covariance, find_corners, intersect
from .numpy_core.lines import fit_lines, normal_form
from .runtime import CoreStatus, CoreUnavailable, extract_features, start, status, warm_up
from .scan import scan_to_points, ScanError, ScanPoints
from .uncertainty import confidence_scale, Ellipse, ellipse, nees

__all__ = [
    'Corner', 'CoreStatus', 'CoreUnavailable', 'CornerSet', 'Ellipse', 'FeatureConfig',
    'Features', 'LineFits', 'METHODS', 'ScanError', 'ScanPoints', 'Segment', 'SegmentReturns',
    'SegmentSet', 'angle_sigma_rad', 'confidence_scale', 'corner_covariance', 'ellipse',
    'extract_features', 'find_corners', 'fit_lines', 'intersect', 'line_landmarks', 'nees',
    'normal_form', 'scan_to_points', 'segment_returns', 'start', 'status', 'validation_errors',
    'warm_up',
]
