# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Which segments are line landmarks: those whose direction their own returns pin down.

A SLAM front end gates a re-observed line on its covariance. On the moving recordings of data/
(docs/results/score.md) the lines that fall outside their 95 % gate are short segments on
clutter and column faces whose angle follows the viewpoint: their angle is off by 4-28 deg,
beyond even their own, already large, covariance. A segment's angle std from its own
covariance (its returns, its length, its range, its residual chi2/dof when
``residual_scaling``) is what tells them apart: a segment known in direction to better than
``max_landmark_angle_sigma_rad`` is a line landmark. Every segment is still published (flagged
``landmark`` or not), serves the corners and is drawn among the markers; ``score`` re-observes
the landmarks only.

Pure numpy, outside the compiled kernels: applied to the pipeline's result.
"""

import math

import numpy as np

from .features import SegmentSet


def angle_sigma_rad(segments: SegmentSet) -> np.ndarray:
    """
    Return each segment's normal-angle std from its own covariance.

    :param segments: the segments
    :return: sqrt(var(angle)), shape (S,), rad
    """
    return np.sqrt(np.maximum(segments.covariance[:, 0, 0], 0.0))


def line_landmarks(segments: SegmentSet, max_angle_sigma_rad: float) -> np.ndarray:
    """
    Return which segments are line landmarks.

    :param segments: a scan's segments
    :param max_angle_sigma_rad: the largest angle std of a landmark (itself included), rad; pi
        (180 deg) or more makes every segment one
    :return: shape (S,), bool
    """
    if max_angle_sigma_rad >= math.pi:
        return np.ones(len(segments), dtype=bool)
    return angle_sigma_rad(segments) <= max_angle_sigma_rad
