"""The per-scan pipeline of the paper's Algorithm 1: returns -> segments -> lines -> corners."""

import math

import numpy as np

from .config import FeatureConfig
from .corners import find_corners
from .features import CornerSet, Features, SegmentSet
from .lines import fit_lines, LineFits, moment_fit, moment_prefix_sums, segment_returns
from .scan import scan_to_points
from .segmentation import (breakpoints, chains, iterative_end_point_fit, merge_collinear,
                           MIN_FIT_RETURNS, SegmentRanges, trim_ambiguous_ends)

_DEFAULT_CONFIG = FeatureConfig()


def extract_features(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                     config: FeatureConfig = _DEFAULT_CONFIG, range_min_m: float = 0.0,
                     range_max_m: float = math.inf) -> Features:
    """
    Extract straight segments and corners with covariances from one 2D scan.

    The scan is a LaserScan's geometry: beam i has bearing angle_min + i * angle_increment and
    range ``ranges_m[i]``; invalid returns (NaN, +-inf, outside the range limits) are skipped.
    Steps: adaptive breakpoints, Iterative End Point Fit, merging of collinear neighbours,
    the configured line fit with its covariance, and the corners of adjacent segments
    (across the +-pi seam on a full turn) with their propagated (x, y, yaw) covariance.

    :param ranges_m: ranges, shape (N,), m
    :param angle_min_rad: bearing of the first beam, rad
    :param angle_increment_rad: bearing step, rad (non-zero, either sign)
    :param config: the pipeline's settings (noise model, thresholds, method)
    :param range_min_m: the scan's own range_min (LaserScan.range_min), m
    :param range_max_m: the scan's own range_max (LaserScan.range_max), m
    :return: the segments and corners, in scan order
    :raises wctls_ros.core.ScanError: when the scan geometry makes no sense (a ValueError)
    """
    points = scan_to_points(ranges_m, angle_min_rad, angle_increment_rad,
                            max(range_min_m, config.range_min_m),
                            min(range_max_m, config.range_max_m))
    n = len(points)
    if n < config.min_segment_points:
        return Features(config.method, SegmentSet.empty(), CornerSet.empty())
    separated = breakpoints(points, config.range_sigma_m, config.bearing_sigma_rad,
                            config.breakpoint_lambda_rad)
    contour = chains(points, separated)
    # Returns in circular order; a merged segment may run past position n on a full turn, so
    # gathers wrap around.
    order = contour.order
    rho, theta = points.range_m[order], points.bearing_rad[order]
    xy = points.xy_m[order]
    x, y = xy[:, 0].copy(), xy[:, 1].copy()

    # Prefix sums make the segmentation's line fits O(1) per segment, merged or not.
    prefix = moment_prefix_sums(x, y)
    prefix = np.concatenate([prefix, prefix[1:] + prefix[-1]])

    def quick(segments: SegmentRanges):
        return moment_fit(prefix[segments.stop] - prefix[segments.start], config.range_sigma_m,
                          config.bearing_sigma_rad)

    segments = iterative_end_point_fit(x, y, contour.start, contour.stop, contour.chain,
                                       config.iepf_threshold_m)
    segments = segments.select(segments.stop - segments.start >= MIN_FIT_RETURNS)
    if not len(segments):
        return Features(config.method, SegmentSet.empty(), CornerSet.empty())
    segments = merge_collinear(segments, points.full_turn, n, quick, config.merge_chi2)

    # Keep segments with enough returns and end returns far enough apart; then leave out the
    # returns where two kept segments meet that fit both lines; then put them in scan order.
    first, last = segments.start, (segments.stop - 1) % n
    counts = segments.stop - segments.start
    segments = segments.select(
        (counts >= config.min_segment_points)
        & (np.hypot(x[last] - x[first], y[last] - y[first]) >= config.min_segment_length_m))
    if not len(segments):
        return Features(config.method, SegmentSet.empty(), CornerSet.empty())
    angle, radius, _ = quick(segments)
    segments = trim_ambiguous_ends(segments, points.full_turn, n, x, y, angle, radius,
                                   config.range_sigma_m, config.bearing_sigma_rad,
                                   config.min_segment_points)
    segments = segments.select(np.argsort(points.index[order[segments.start]], kind='stable'))
    counts = segments.stop - segments.start
    position = (np.arange(counts.sum())
                + np.repeat(segments.start - (np.cumsum(counts) - counts), counts))
    fits = fit_lines(config.method,
                     segment_returns(rho.take(position, mode='wrap'),
                                     theta.take(position, mode='wrap'), np.cumsum(counts) - counts,
                                     counts, x.take(position, mode='wrap'),
                                     y.take(position, mode='wrap')),
                     config.range_sigma_m, config.bearing_sigma_rad)
    usable = _finite_and_positive(fits)
    if not usable.any():
        return Features(config.method, SegmentSet.empty(), CornerSet.empty())
    if not usable.all():
        segments, counts, fits = segments.select(usable), counts[usable], fits.select(usable)
    last = (segments.stop - 1) % n
    ends = _project(xy[np.concatenate([segments.start, last])], fits)
    common = config.common_range_sigma_m * fits.normal_offset_jacobian
    segment_set = SegmentSet(
        fits.angle_rad, fits.radius_m,
        fits.normal_covariance + common[:, :, None] * common[:, None, :], fits.line,
        fits.line_covariance, fits.line_offset_jacobian, ends[:len(counts)], ends[len(counts):],
        points.index[order[segments.start]], points.index[order[last]], counts)

    count = len(segment_set)
    first = np.arange(count - 1)
    if points.full_turn and count >= 3:
        first = np.arange(count)               # the last segment meets the first at the seam
    corners = find_corners(fits.line, fits.line_covariance, segment_set.start_xy_m,
                           segment_set.end_xy_m, first, (first + 1) % max(count, 1),
                           config.min_corner_angle_rad, config.max_corner_gap_m,
                           fits.line_offset_jacobian, config.common_range_sigma_m)
    return Features(config.method, segment_set, corners)


def _project(xy_m: np.ndarray, fits: LineFits) -> np.ndarray:
    """
    Return the foot of the perpendicular from points to the lines.

    :param xy_m: shape (k S, 2): k points per line, the lines' order repeated k times, m
    :param fits: the S lines
    :return: shape (k S, 2), m
    """
    repeat = len(xy_m) // len(fits.angle_rad)
    angle, radius = np.tile(fits.angle_rad, repeat), np.tile(fits.radius_m, repeat)
    normal = np.column_stack([np.cos(angle), np.sin(angle)])
    offset = np.einsum('si,si->s', xy_m, normal) - radius
    return xy_m - offset[:, None] * normal


def _finite_and_positive(fits: LineFits) -> np.ndarray:
    """Return which fits are usable: finite everywhere, positive-definite normal covariance."""
    cov = fits.normal_covariance
    # A NaN or inf anywhere makes the row's total non-finite.
    finite = np.isfinite(fits.line.sum(axis=1) + fits.line_covariance.sum(axis=(1, 2))
                         + fits.angle_rad + fits.radius_m + cov.sum(axis=(1, 2)))
    with np.errstate(invalid='ignore'):
        return finite & (cov[:, 0, 0] > 0.0) & (cov[:, 0, 0] * cov[:, 1, 1] > cov[:, 0, 1] ** 2)
