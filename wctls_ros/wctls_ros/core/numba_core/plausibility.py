# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Compiled twin of :mod:`wctls_ros.core.plausibility`: the bounds on a scan's features, in loops.

The pipeline's compiled function tells which of its features pass them
(docs/derivation.md#plausibility); on the rare scan with features beyond them (none of the
benchmark's), :func:`..plausibility.kept` drops the others, as in the numpy pipeline.
"""

import math

import numpy as np

from ._jit import jit
from ..plausibility import MAX_SIGMA_RATIO


@jit
def _return_noise_m(range_m, range_sigma_m, settings):
    """Compiled twin of :func:`..plausibility.return_noise_m` for one range, m."""
    return math.sqrt(range_sigma_m ** 2 + settings.model_error_sigma_m ** 2
                     + settings.wall_flatness_sigma_m ** 2
                     + (range_m * settings.bearing_sigma_rad) ** 2)


@jit
def plausible(segments, corners, range_sigma_m, settings):
    """
    Compiled twin of the bounds of :func:`..plausibility.plausible`: which features pass.

    A corner's worst std is the square root of the larger eigenvalue of its (x, y) covariance
    [[a, b], [b, c]], (a + c) / 2 + sqrt(((a - c) / 2)^2 + b^2), in closed form.

    :param segments: the walls, :data:`~.records.SegmentArrays`
    :param corners: the corners between them, :data:`~.records.CornerArrays`
    :param range_sigma_m: the range noise the scan was processed with, m
    :param settings: the configuration (:class:`~.records.Settings`)
    :return: (which segments pass (S,), which corners pass (C,); a corner of a segment that does
        not, does not), or (None, None) when all do
    """
    segment_count, corner_count = segments.angle_rad.size, corners.yaw_rad.size
    keep_segment = np.empty(segment_count, np.bool_)
    for s in range(segment_count):
        middle_x = 0.5 * (segments.start_xy_m[s, 0] + segments.end_xy_m[s, 0])
        middle_y = 0.5 * (segments.start_xy_m[s, 1] + segments.end_xy_m[s, 1])
        angle, cov = segments.angle_rad[s], segments.covariance[s]
        lever = -middle_x * math.sin(angle) + middle_y * math.cos(angle)
        variance = cov[1, 1] - 2.0 * lever * cov[0, 1] + lever * lever * cov[0, 0]
        keep_segment[s] = math.sqrt(max(variance, 0.0)) <= MAX_SIGMA_RATIO * _return_noise_m(
            math.hypot(middle_x, middle_y), range_sigma_m, settings)
    keep_corner = np.empty(corner_count, np.bool_)
    for c in range(corner_count):
        cov = corners.covariance[c]
        half_sum, half_difference = 0.5 * (cov[0, 0] + cov[1, 1]), 0.5 * (cov[0, 0] - cov[1, 1])
        largest = half_sum + math.sqrt(half_difference ** 2 + cov[0, 1] ** 2)
        keep_corner[c] = (keep_segment[corners.first_segment[c]]
                          and keep_segment[corners.second_segment[c]]
                          and math.sqrt(max(largest, 0.0)) <= MAX_SIGMA_RATIO * _return_noise_m(
                              math.hypot(corners.xy_m[c, 0], corners.xy_m[c, 1]), range_sigma_m,
                              settings))
    if keep_segment.all() and keep_corner.all():
        return None, None
    return keep_segment, keep_corner
