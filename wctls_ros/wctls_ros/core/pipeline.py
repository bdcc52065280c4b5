# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The per-scan pipeline of the paper's Algorithm 1: returns -> segments -> lines -> corners."""

import math

import numpy as np

from .config import FeatureConfig
from .corners import find_corners
from .features import CornerSet, Features, SegmentSet
from .lines import fit_lines, LineFits, segment_returns
from .scan import scan_to_points
from .scan import ScanError
from .segmentation import (breakpoints, chains, iterative_end_point_fit, merge_collinear,
                           moment_fit, moment_terms, pass_budget, piece_sums, SegmentRanges,
                           trim_ambiguous_ends, trim_offset_ends)

_DEFAULT_CONFIG = FeatureConfig()


def extract_features(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                     config: FeatureConfig = _DEFAULT_CONFIG, range_min_m: float = 0.0,
                     range_max_m: float = math.inf) -> Features:
    """
    Extract straight segments and corners with covariances from one 2D scan.

    The scan is a LaserScan's geometry: beam i has bearing angle_min + i * angle_increment and
    range ``ranges_m[i]``; invalid returns (NaN, +-inf, outside the range limits) are skipped.
    Steps: adaptive breakpoints, Iterative End Point Fit, merging of collinear neighbours,
    trimming of the returns at segment ends that fit both walls of a corner or lie off the
    segment's line together, the configured line fit with its covariance, and the corners of
    adjacent segments (across the +-pi seam on a full turn) with their propagated (x, y, yaw)
    covariance.

    :param ranges_m: ranges, shape (N,), m
    :param angle_min_rad: bearing of the first beam, rad
    :param angle_increment_rad: bearing step, rad (non-zero, either sign)
    :param config: the pipeline's settings (noise model, thresholds, method)
    :param range_min_m: the scan's own range_min (LaserScan.range_min), m
    :param range_max_m: the scan's own range_max (LaserScan.range_max), m
    :return: the segments and corners, in scan order
    :raises wctls_ros.core.ScanError: when the scan geometry makes no sense, or the scan has
        more than ``config.max_beams`` beams (a ValueError)
    """
    # Degenerate pieces (parallel lines, returns in one spot) give inf or NaN along the way;
    # every such segment or corner is dropped before it reaches the result.
    with np.errstate(divide='ignore', invalid='ignore'):
        return _extract_features(ranges_m, angle_min_rad, angle_increment_rad, config,
                                 range_min_m, range_max_m)


def _extract_features(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                      config: FeatureConfig, range_min_m: float, range_max_m: float) -> Features:
    """Run :func:`extract_features` with floating-point warnings already silenced."""
    if np.size(ranges_m) > config.max_beams:
        raise ScanError(f'{np.size(ranges_m)} beams are more than max_beams '
                        f'({config.max_beams})')
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
    x, y = points.x_m[order], points.y_m[order]

    # Every pass of IEPF and of merging is O(n): a bounded number of them bounds the work.
    budget = pass_budget(n)
    segments, unsplit = iterative_end_point_fit(x, y, contour.start, contour.stop,
                                                contour.chain, config.iepf_threshold_m, budget)
    if not len(segments):
        return Features(config.method, SegmentSet.empty(), CornerSet.empty(), unsplit)
    # Sums over the pieces between segment ends make the segmentation's line fits O(1) per
    # segment, merged or not: merging works on piece ranges.
    sums = piece_sums(moment_terms(x, y), segments)

    def quick(pieces: SegmentRanges):
        return moment_fit(sums.over(pieces), config.range_sigma_m, config.bearing_sigma_rad)

    pieces, (angle, radius, _), unmerged = merge_collinear(
        sums.pieces(segments), points.full_turn, sums.edges.size - 1, quick, config.merge_chi2,
        budget)
    work_limited = unsplit or unmerged
    segments = sums.positions(pieces)

    # Keep segments with enough returns and end returns far enough apart; then leave out the
    # returns where two kept segments meet that fit both lines, and runs at the ends that lie
    # off the line together; then put them in scan order.
    first, last = segments.start, (segments.stop - 1) % n
    dx, dy = x[last] - x[first], y[last] - y[first]
    keep = ((segments.stop - first >= config.min_segment_points)
            & (dx * dx + dy * dy >= config.min_segment_length_m ** 2))
    if not keep.any():
        return Features(config.method, SegmentSet.empty(), CornerSet.empty(), work_limited)
    segments, angle, radius = segments.select(keep), angle[keep], radius[keep]
    segments = trim_ambiguous_ends(segments, points.full_turn, n, x, y, angle, radius,
                                   config.range_sigma_m, config.bearing_sigma_rad,
                                   config.min_segment_points)
    if config.end_offset_sigmas > 0.0:
        segments = trim_offset_ends(segments, n, x, y, angle, radius, config.range_sigma_m,
                                    config.bearing_sigma_rad, config.min_segment_points,
                                    config.end_offset_sigmas)
    first_index = points.index[order[segments.start]]
    by_scan = np.argsort(first_index, kind='stable')
    segments, first_index = segments.select(by_scan), first_index[by_scan]
    counts = segments.stop - segments.start
    offsets = np.cumsum(counts) - counts
    position = np.arange(offsets[-1] + counts[-1]) + np.repeat(segments.start - offsets, counts)
    fits = fit_lines(config.method,
                     segment_returns(rho.take(position, mode='wrap'),
                                     theta.take(position, mode='wrap'), offsets, counts,
                                     x.take(position, mode='wrap'),
                                     y.take(position, mode='wrap')),
                     config.range_sigma_m, config.bearing_sigma_rad)
    usable = _finite_and_positive(fits)
    if not usable.any():
        return Features(config.method, SegmentSet.empty(), CornerSet.empty(), work_limited)
    if not usable.all():
        segments, counts, fits = segments.select(usable), counts[usable], fits.select(usable)
        first_index = first_index[usable]
    last = (segments.stop - 1) % n
    start_xy, end_xy = _project(x, y, segments.start, last, fits)
    common = config.common_range_sigma_m * fits.normal_offset_jacobian
    segment_set = SegmentSet(
        fits.angle_rad, fits.radius_m,
        fits.normal_covariance + common[:, :, None] * common[:, None, :], fits.line,
        fits.line_covariance, fits.line_offset_jacobian, start_xy, end_xy,
        first_index, points.index[order[last]], counts)

    count = len(segment_set)
    first = np.arange(count - 1)
    if points.full_turn and count >= 3:
        first = np.arange(count)               # the last segment meets the first at the seam
    corners = find_corners(fits.line, fits.line_covariance, segment_set.start_xy_m,
                           segment_set.end_xy_m, first, (first + 1) % max(count, 1),
                           config.min_corner_angle_rad, config.max_corner_gap_m,
                           fits.line_offset_jacobian, config.common_range_sigma_m)
    return Features(config.method, segment_set, corners, work_limited)


def _project(x_m: np.ndarray, y_m: np.ndarray, first: np.ndarray, last: np.ndarray,
             fits: LineFits):
    """
    Return the feet of the perpendiculars from each segment's end returns to its line.

    :param x_m: x of the returns in position order, shape (n,), m
    :param y_m: y of the returns in position order, shape (n,), m
    :param first: position of each segment's first return, shape (S,)
    :param last: position of each segment's last return, shape (S,)
    :param fits: the S lines
    :return: (first returns projected (S, 2), last returns projected (S, 2)), m
    """
    c, s = np.cos(fits.angle_rad), np.sin(fits.angle_rad)
    feet = []
    for position in (first, last):
        x, y = x_m[position], y_m[position]
        offset = x * c + y * s - fits.radius_m
        foot = np.empty((position.size, 2))
        foot[:, 0], foot[:, 1] = x - offset * c, y - offset * s
        feet.append(foot)
    return feet


def _finite_and_positive(fits: LineFits) -> np.ndarray:
    """Return which fits are usable: finite everywhere, positive-definite normal covariance."""
    cov = fits.normal_covariance
    # A NaN or inf anywhere makes the row's total non-finite.
    finite = np.isfinite(fits.line.sum(axis=1) + fits.line_covariance.sum(axis=(1, 2))
                         + fits.angle_rad + fits.radius_m + cov.sum(axis=(1, 2)))
    return finite & (cov[:, 0, 0] > 0.0) & (cov[:, 0, 0] * cov[:, 1, 1] > cov[:, 0, 1] ** 2)
