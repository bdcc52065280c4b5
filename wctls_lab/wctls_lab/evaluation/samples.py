# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The corners of every scan, per method, with the covariances the analysis compares.

For each scan and method the core's pipeline gives the segments and corners with their
propagated (full) covariance, including a range offset common to all beams of a scan when the
noise model has one. On top of that this module computes, from the same segments, the
covariance the paper's tables would show if the off-diagonal terms of each line's 3x3 covariance
were dropped before propagating to the corner (``--propagation diagonal``, an analysis of the
paper's gap, never what the node does).
"""

from dataclasses import dataclass, replace

import numpy as np

from wctls_ros.core import corner_covariance, extract_features, FeatureConfig
from wctls_ros.process import check_stop

from ..simulation import NoiseModel

PAPER_METHODS = ('utls', 'wtls', 'wctls')


@dataclass(frozen=True)
class ScanCorners:
    """
    The corners one method found in one scan.

    :ivar xy: positions, shape (C, 2), m
    :ivar covariance: propagated covariance of the position with the full line covariances
        (and the common-mode term of the noise model), shape (C, 2, 2), m^2
    :ivar diagonal_covariance: the same with each line covariance reduced to its diagonal,
        shape (C, 2, 2), m^2
    :ivar segments: (first, second) segment index of each corner, shape (C, 2)
    """

    xy: np.ndarray
    covariance: np.ndarray
    diagonal_covariance: np.ndarray
    segments: np.ndarray

    def __len__(self):
        return len(self.xy)

    def covariances(self, propagation: str) -> np.ndarray:
        """
        Return the covariances of one propagation.

        :param propagation: 'full' or 'diagonal'
        :return: shape (C, 2, 2), m^2
        """
        return self.diagonal_covariance if propagation == 'diagonal' else self.covariance


def feature_config(noise: NoiseModel, method: str, base: FeatureConfig = None
                   ) -> FeatureConfig:
    """
    Return the pipeline configuration of one method under a noise model.

    :param noise: the noise model (its range, bearing and common-mode range noise)
    :param method: 'utls', 'wtls', 'wctls' or 'ml'
    :param base: other settings (defaults: the paper's)
    :return: the configuration
    """
    base = FeatureConfig() if base is None else base
    return base.replace(method=method, range_sigma_m=max(noise.range_sigma_m, 1e-6),
                        bearing_sigma_rad=noise.bearing_sigma_rad,
                        common_range_sigma_m=noise.common_range_sigma_m)


def scan_corners(ranges: np.ndarray, angle_min: float, angle_increment: float,
                 range_min: float, range_max: float, config: FeatureConfig):
    """
    Extract one scan's features with one method and the corners' covariance variants.

    :param ranges: the scan's ranges, shape (N,), m
    :param angle_min: bearing of beam 0, rad
    :param angle_increment: bearing step, rad
    :param range_min: the scan's range_min, m
    :param range_max: the scan's range_max, m
    :param config: the pipeline configuration (method and noise model)
    :return: (the core's Features, ScanCorners)
    :raises wctls_ros.process.Stopped: when a stop signal was noted (a tool's safe point)
    """
    check_stop()
    features = extract_features(ranges, angle_min, angle_increment, config, range_min,
                                range_max)
    corners, segments = features.corners, features.segments
    first, second = corners.first_segment, corners.second_segment
    # The covariance of the same corners from diagonal line covariances.
    diagonal = corner_covariance(
        replace(segments, line_covariance=segments.line_covariance * np.eye(3)), first, second,
        config.common_range_sigma_m)
    return features, ScanCorners(corners.xy_m.copy(), corners.covariance[:, :2, :2],
                                 diagonal[:, :2, :2], np.column_stack([first, second]))
