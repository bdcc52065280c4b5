"""
The corners of every scan, per method, with the covariances the analysis compares.

For each scan and method the core's pipeline gives the segments and corners with their
propagated (full) covariance. On top of that this module computes, from the same segments:

- the covariance the paper's tables would show if the off-diagonal terms of each line's 3x3
  covariance were dropped before propagating to the corner (``--propagation diagonal``, an
  analysis of the paper's gap, never what the node does);
- the shift of each corner per metre of a range offset common to all beams of a scan
  (a term real sensors show and the core's independent-noise model leaves out), by central
  differences of the same line fits.
"""

from dataclasses import dataclass
import math

import numpy as np

from ..core import (extract_features, FeatureConfig, fit_lines, intersect, scan_to_points,
                    segment_returns)

PAPER_METHODS = ('utls', 'wtls', 'wctls')
# Range offset used for the central differences of the common-mode Jacobian, m.
_OFFSET_STEP_M = 1e-4


@dataclass(frozen=True)
class NoiseParameters:
    """
    The sensor noise model the corner covariances are computed with.

    :ivar range_sigma_m: independent per-beam range noise std, m
    :ivar bearing_sigma_rad: independent per-beam bearing noise std, rad
    :ivar common_range_sigma_m: std of a range offset shared by all beams of one scan, m
    """

    range_sigma_m: float
    bearing_sigma_rad: float
    common_range_sigma_m: float = 0.0

    def describe(self) -> str:
        """
        Return the parameters in readable units.

        :return: e.g. 'range 50.0 mm, bearing 0.391 deg, common-mode 0.0 mm'
        """
        return (f'range {1e3 * self.range_sigma_m:.2f} mm, bearing '
                f'{math.degrees(self.bearing_sigma_rad):.3f} deg, common-mode range offset '
                f'{1e3 * self.common_range_sigma_m:.2f} mm')


@dataclass(frozen=True)
class ScanCorners:
    """
    The corners one method found in one scan.

    :ivar xy: positions, shape (C, 2), m
    :ivar covariance: propagated covariance of the position with the full line covariances and
        the common-mode term, shape (C, 2, 2), m^2
    :ivar diagonal_covariance: the same with each line covariance reduced to its diagonal,
        shape (C, 2, 2), m^2
    :ivar common: corner shift per metre of common range offset, shape (C, 2)
    :ivar segments: (first, second) segment index of each corner, shape (C, 2)
    """

    xy: np.ndarray
    covariance: np.ndarray
    diagonal_covariance: np.ndarray
    common: np.ndarray
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


def feature_config(noise: NoiseParameters, method: str, base: FeatureConfig = None
                   ) -> FeatureConfig:
    """
    Return the pipeline configuration of one method under a noise model.

    :param noise: the noise model (its independent part configures the pipeline)
    :param method: 'utls', 'wtls', 'wctls' or 'ml'
    :param base: other settings (defaults: the paper's)
    :return: the configuration
    """
    base = FeatureConfig() if base is None else base
    return base.replace(method=method, range_sigma_m=max(noise.range_sigma_m, 1e-6),
                        bearing_sigma_rad=noise.bearing_sigma_rad)


def scan_corners(ranges: np.ndarray, angle_min: float, angle_increment: float,
                 range_min: float, range_max: float, config: FeatureConfig,
                 common_range_sigma_m: float = 0.0):
    """
    Extract one scan's features with one method and the corners' covariance variants.

    :param ranges: the scan's ranges, shape (N,), m
    :param angle_min: bearing of beam 0, rad
    :param angle_increment: bearing step, rad
    :param range_min: the scan's range_min, m
    :param range_max: the scan's range_max, m
    :param config: the pipeline configuration (method and independent noise)
    :param common_range_sigma_m: std of the per-scan common range offset, m
    :return: (the core's Features, ScanCorners)
    """
    features = extract_features(ranges, angle_min, angle_increment, config, range_min,
                                range_max)
    corners = features.corners
    count = len(corners)
    empty = np.zeros((0, 2, 2))
    if not count:
        return features, ScanCorners(np.zeros((0, 2)), empty, empty, np.zeros((0, 2)),
                                     np.zeros((0, 2), np.intp))
    segments = features.segments
    first, second = corners.first_segment, corners.second_segment
    line, line_cov = segments.line, segments.line_covariance
    diagonal = line_cov * np.eye(3)
    _, diagonal_cov, _, _ = intersect(line[first], diagonal[first], line[second],
                                      diagonal[second])
    common = _common_mode_jacobian(ranges, angle_min, angle_increment, range_min, range_max,
                                   config, segments, first, second)
    extra = common_range_sigma_m ** 2 * common[:, :, None] * common[:, None, :]
    return features, ScanCorners(
        corners.xy_m.copy(), corners.covariance[:, :2, :2] + extra, diagonal_cov + extra,
        common, np.column_stack([first, second]))


def segment_returns_of(ranges, angle_min, angle_increment, range_min, range_max, config,
                       segments):
    """
    Rebuild the returns each segment was fitted from (its valid beams in scan order).

    :param ranges: the scan's ranges, shape (N,), m
    :param angle_min: bearing of beam 0, rad
    :param angle_increment: bearing step, rad
    :param range_min: the scan's range_min, m
    :param range_max: the scan's range_max, m
    :param config: the pipeline configuration the segments came from
    :param segments: the core's SegmentSet
    :return: (rho (P,), theta (P,), offsets (S,), counts (S,))
    :raises ValueError: when a segment's returns cannot be found again
    """
    points = scan_to_points(ranges, angle_min, angle_increment,
                            max(range_min, config.range_min_m),
                            min(range_max, config.range_max_m))
    index = points.index
    rho, theta, counts = [], [], []
    for first, last, expected in zip(segments.first_index, segments.last_index,
                                     segments.num_points):
        inside = ((index >= first) & (index <= last) if first <= last
                  else (index >= first) | (index <= last))
        order = np.flatnonzero(inside)
        if first > last:                        # across the seam: the end of the turn first
            order = np.concatenate([order[index[order] >= first], order[index[order] <= last]])
        if len(order) != expected:
            raise ValueError(f'segment of beams {first}-{last}: found {len(order)} returns, '
                             f'the pipeline fitted {expected}')
        rho.append(points.range_m[order])
        theta.append(points.bearing_rad[order])
        counts.append(len(order))
    counts = np.array(counts, dtype=np.intp)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
    return np.concatenate(rho), np.concatenate(theta), offsets, counts


def _common_mode_jacobian(ranges, angle_min, angle_increment, range_min, range_max, config,
                          segments, first, second) -> np.ndarray:
    """Return d(corner)/d(common range offset) by central differences of the fits, (C, 2)."""
    rho, theta, offsets, counts = segment_returns_of(ranges, angle_min, angle_increment,
                                                     range_min, range_max, config, segments)
    shifted = []
    for step in (_OFFSET_STEP_M, -_OFFSET_STEP_M):
        fits = fit_lines(config.method, segment_returns(rho + step, theta, offsets, counts),
                         config.range_sigma_m, config.bearing_sigma_rad)
        xy, _, _, _ = intersect(fits.line[first], fits.line_covariance[first],
                                fits.line[second], fits.line_covariance[second])
        shifted.append(xy)
    return (shifted[0] - shifted[1]) / (2.0 * _OFFSET_STEP_M)
