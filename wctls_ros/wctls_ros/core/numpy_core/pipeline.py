# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The per-scan pipeline of the paper's Algorithm 1 in numpy: returns -> segments -> corners."""

from dataclasses import dataclass
import functools
import math
from typing import NamedTuple, TypeVar

import numpy as np

from .corners import corner_candidates, corner_covariance, walls_end_at
from .lines import fit_lines, normal_jacobian
from .model_error import flatness_covariance, line_covariance_added, residual_factor
from .noise import scan_range_sigma
from .segmentation import (breakpoints, Breaks, Chains, chains, iterative_end_point_fit,
                           merge_collinear, moment_fit, moment_terms, pass_budget, piece_sums,
                           SegmentRanges, trim_ambiguous, trim_offset)
from ..config import FeatureConfig
from ..features import (CornerSet, Features, LineFits, segment_returns, SegmentReturns,
                        SegmentSet)
from ..plausibility import implausible_scan, noise_is_plausible, plausible
from ..prepared import LatestPrepared
from ..records import CornerEndRule, Lines, Noise, Returns
from ..scan import beam_density, BeamDensity, scan_to_points, ScanError, ScanPoints

_DEFAULT_CONFIG = FeatureConfig()


class _Prepared(NamedTuple):
    """
    What a configuration's rules become at one beam layout: worked out once, not per scan.

    :ivar config: the configuration
    :ivar angle_increment_rad: the layout's bearing step, rad
    :ivar beam_count: the layout's number of beams
    :ivar density: the rules that count returns, at this spacing (docs/derivation.md#density)
    :ivar iepf_noise_sigmas: the IEPF split distance's sigmas, at this spacing
    :ivar corner_rule: the corner end rule's tolerances, at this spacing
    :ivar min_wall_beam_sine: sin(min_wall_beam_angle)
    """

    config: FeatureConfig
    angle_increment_rad: float
    beam_count: int
    density: BeamDensity
    iepf_noise_sigmas: float
    corner_rule: CornerEndRule
    min_wall_beam_sine: float


@functools.lru_cache(maxsize=64)
def _prepare(config: FeatureConfig, angle_increment_rad: float, beam_count: int) -> _Prepared:
    """Return a configuration's rules at a beam layout (one per distinct pair)."""
    density = beam_density(angle_increment_rad, beam_count)
    return _Prepared(config, angle_increment_rad, beam_count, density,
                     density.rarer(config.iepf_noise_sigmas),
                     CornerEndRule(density.rarer(config.corner_end_sigmas),
                                   config.corner_end_floor_m, density.corner_window,
                                   config.end_offset_sigmas),
                     math.sin(config.min_wall_beam_angle_rad))


# The rules of the latest configuration and layout, compared by identity (see
# :class:`..prepared.LatestPrepared`) before the cache of :func:`_prepare` is asked.
_LATEST = LatestPrepared(_prepare)


def extract_features(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                     config: FeatureConfig = _DEFAULT_CONFIG, range_min_m: float = 0.0,
                     range_max_m: float = math.inf) -> Features:
    """
    Extract segments and corners from one scan, in batched numpy.

    :func:`wctls_ros.core.extract_features` states the arguments, the result and the errors.
    """
    # Degenerate pieces (parallel lines, returns in one spot) give inf or NaN along the way;
    # every such segment or corner is dropped before it reaches the result.
    with np.errstate(divide='ignore', invalid='ignore'):
        return _extract_features(ranges_m, angle_min_rad, angle_increment_rad, config,
                                 range_min_m, range_max_m)


def _extract_features(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                      config: FeatureConfig, range_min_m: float, range_max_m: float) -> Features:
    """
    Run :func:`extract_features` with floating-point warnings already silenced.

    The steps of the paper's Algorithm 1; each comment names the section of
    docs/derivation.md that states the step's rule or formulas.
    """
    if np.size(ranges_m) > config.max_beams:
        raise ScanError(f'{np.size(ranges_m)} beams are more than max_beams '
                        f'({config.max_beams})')
    points = scan_to_points(ranges_m, angle_min_rad, angle_increment_rad,
                            max(range_min_m, config.range_min_m),
                            min(range_max_m, config.range_max_m))
    if len(points) < config.min_segment_points:
        return _nothing(config)
    # #range-noise-from-the-scan, and #plausibility: nothing published that says "unknown".
    range_sigma = _range_sigma_of_the_scan(config, points)
    if not noise_is_plausible(range_sigma, config):
        return implausible_scan(config.method, range_sigma)
    # #decision-noise: every decision tolerates the model error on top of the sensor noise;
    # the fits weigh the returns by the sensor noise alone.
    noise = Noise(range_sigma, config.bearing_sigma_rad,
                  math.hypot(range_sigma, config.model_error_sigma_m))
    prepared = _LATEST.get(config, float(angle_increment_rad), points.beam_count)
    return plausible(_features_of(points, noise, prepared), config, range_sigma)


def _nothing(config: FeatureConfig, work_limited: bool = False) -> Features:
    """Return the features of a scan that has none."""
    return Features(config.method, SegmentSet.empty(), CornerSet.empty(), work_limited)


def _features_of(points: ScanPoints, noise: Noise, prepared: _Prepared) -> Features:
    """Find the features of a scan's returns with the scan's noise (Algorithm 1)."""
    config, density = prepared.config, prepared.density
    # #segmentation-statistics: breakpoints, IEPF, merging, the size rules, the end trims.
    contour = _Contour.of(points, noise, config, density)
    segments, unsplit = _split(contour, noise, config, prepared)
    if not len(segments):
        return _nothing(config, unsplit)
    segments, lines, unmerged = _merge(contour, segments, noise, config)
    segments, lines = _large_enough(contour, segments, lines, config)
    work_limited = unsplit or unmerged
    if not len(segments):
        return _nothing(config, work_limited)
    segments = _trim_ends(contour, segments, lines, noise, config, density)
    # #utls, #wtls, #wctls or #maximum-likelihood: the configured fit with its covariance.
    walls, positions = _fit_walls(contour, segments, noise, prepared)
    if not len(walls):
        return _nothing(config, work_limited)
    # #corners: which pairs are corners is decided with the decision noise; the published
    # covariances add the model error to the fits' (#model-error).
    corners = _corners(contour, walls, positions, noise, prepared)
    # #model-error (D17), (D18), then #corners and #common-mode-range-offset, (D11)-(D16).
    walls = _with_model_error(walls, config)
    return Features(config.method, walls, _corner_covariances(walls, corners, config),
                    work_limited)


def _range_sigma_of_the_scan(config: FeatureConfig, points: ScanPoints) -> float:
    """Return range_sigma_m, raised to the scan's own estimate when enabled, m."""
    if not config.range_sigma_from_scan:
        return config.range_sigma_m
    return max(config.range_sigma_m, scan_range_sigma(points))


@dataclass(frozen=True)
class _Contour:
    """
    The scan's valid returns in circular order (a full turn starts at a breakpoint).

    :ivar points: the returns in beam order
    :ivar breaks: where the breakpoint rule separates neighbours (beam order)
    :ivar chains: the runs between breakpoints, and the circular order
    :ivar index: beam indices in circular order
    :ivar rho: ranges in circular order, m
    :ivar theta: bearings in circular order, rad
    :ivar x: x in circular order, m
    :ivar y: y in circular order, m
    """

    points: ScanPoints
    breaks: Breaks
    chains: Chains
    index: np.ndarray
    rho: np.ndarray
    theta: np.ndarray
    x: np.ndarray
    y: np.ndarray

    @staticmethod
    def of(points: ScanPoints, noise: Noise, config: FeatureConfig,
           density: BeamDensity) -> '_Contour':
        """Cut the returns into chains at breakpoints (Borges and Aldon) and order them."""
        breaks = breakpoints(points, noise.deciding_sigma_m, noise.bearing_sigma_rad,
                             config.breakpoint_lambda_rad, config.merge_max_missing_beams,
                             density.breakpoint_sigmas)
        runs = chains(points, breaks.separated)
        order = runs.order
        return _Contour(points, breaks, runs, points.index[order], points.range_m[order],
                        points.bearing_rad[order], points.x_m[order], points.y_m[order])

    def __len__(self):
        return len(self.x)


def _split(contour: _Contour, noise: Noise, config: FeatureConfig, prepared: _Prepared):
    """
    Split the chains into straight segments by Iterative End Point Fit.

    The paper's split distance, but never within iepf_noise_sigmas of a return's noise (more on
    dense scans, :meth:`~wctls_ros.core.scan.BeamDensity.rarer`): a threshold of 2 sigma splits
    a straight wall at its noise in most scans. Every pass is O(n):
    a bounded number of them (:func:`~.segmentation.pass_budget`) bounds the work on any scan.

    :return: (the segments, positions in the contour; whether the work bound stopped splitting)
    """
    if config.iepf_noise_sigmas > 0.0:
        return_noise = np.sqrt(noise.deciding_sigma_m ** 2
                               + (contour.rho * noise.bearing_sigma_rad) ** 2)
        threshold = np.maximum(config.iepf_threshold_m, prepared.iepf_noise_sigmas * return_noise)
    else:
        threshold = np.full(len(contour), config.iepf_threshold_m)
    runs = contour.chains
    return iterative_end_point_fit(contour.x, contour.y, runs.start, runs.stop, runs.chain,
                                   threshold, pass_budget(len(contour)))


def _merge(contour: _Contour, segments: SegmentRanges, noise: Noise, config: FeatureConfig):
    """
    Merge statistically collinear neighbours, never across a discontinuity.

    Sums over the pieces between segment ends make the merge test's line fits
    (:func:`~.segmentation.moment_fit`) O(1) per segment, merged or not: merging works on
    piece ranges, with the same work bound as splitting.

    :return: (merged segments, their merge fits' lines, whether the work bound stopped merging)
    """
    sums = piece_sums(moment_terms(contour.x, contour.y), segments)

    def quick(pieces: SegmentRanges):
        return moment_fit(sums.over(pieces), noise.deciding_sigma_m, noise.bearing_sigma_rad)

    runs = contour.chains
    joinable = contour.breaks.joinable[runs.order[sums.edges[:-1]]]   # before each piece
    pieces, (angle, radius, _), unmerged = merge_collinear(
        sums.pieces(segments), contour.points.full_turn, sums.edges.size - 1, quick,
        config.merge_chi2, pass_budget(len(contour)), joinable)
    return sums.positions(pieces), Lines(angle, radius), unmerged


def _large_enough(contour: _Contour, segments: SegmentRanges, lines: Lines,
                  config: FeatureConfig):
    """Return the segments (and their lines) of min_segment_points and length."""
    x, y = contour.x, contour.y
    first, last = segments.start, (segments.stop - 1) % len(contour)
    dx, dy = x[last] - x[first], y[last] - y[first]
    keep = ((segments.stop - first >= config.min_segment_points)
            & (dx * dx + dy * dy >= config.min_segment_length_m ** 2))
    if np.count_nonzero(keep) == keep.size:
        return segments, lines
    return segments.select(keep), Lines(lines.angle_rad[keep], lines.radius_m[keep])


def _trim_ends(contour: _Contour, segments: SegmentRanges, lines: Lines, noise: Noise,
               config: FeatureConfig, density: BeamDensity) -> SegmentRanges:
    """
    Leave out the returns at segment ends that fit both walls, and runs off the line together.

    The lines are the merge fits'.
    """
    x, y = contour.x, contour.y
    segments = trim_ambiguous(segments, contour.points.full_turn, x, y, lines, noise,
                              config.min_segment_points, density.end_window)
    if config.end_offset_sigmas > 0.0:
        segments = trim_offset(segments, x, y, lines, noise, config.min_segment_points,
                               config.end_offset_sigmas, density.end_window)
    return segments


def _fit_walls(contour: _Contour, segments: SegmentRanges, noise: Noise, prepared: _Prepared):
    """
    Fit every segment with the configured method and keep the ones that are walls.

    A segment is left out when its fit is degenerate (non-finite, or a covariance that is not
    positive definite) or when it lies within min_wall_beam_angle of the beam to its middle:
    returns strung along the beams are mixed pixels or grazing veils, not a wall.

    :return: (the walls in scan order, their first and last positions in the contour (2, S))
    """
    n, config = len(contour), prepared.config
    if contour.points.full_turn:     # else the circular order is the beam order: sorted already
        segments = segments.select(np.argsort(contour.index[segments.start], kind='stable'))
    returns = _returns_of(contour, segments)
    counts = returns.counts
    fits = fit_lines(config.method, returns, noise.range_sigma_m, noise.bearing_sigma_rad)
    cos_sin_radius = np.array([np.cos(fits.angle_rad), np.sin(fits.angle_rad), fits.radius_m])
    chi2_dof = _residual_chi2_dof(returns, cos_sin_radius, noise)
    positions = np.array([segments.start, (segments.stop - 1) % n])
    start_xy, end_xy = _project(contour.x, contour.y, positions, cos_sin_radius)
    middle = 0.5 * (start_xy + end_xy)
    along_beam = np.abs(np.cos(np.arctan2(middle[:, 1], middle[:, 0]) - fits.angle_rad))
    usable = _finite_and_positive(fits) & (along_beam >= prepared.min_wall_beam_sine)
    if np.count_nonzero(usable) < usable.size:
        # take, not a boolean index: several times faster on arrays of more than one axis.
        kept = usable.nonzero()[0]
        fits = _rows(fits, kept)
        counts, chi2_dof = counts[kept], chi2_dof[kept]
        start_xy, end_xy = start_xy.take(kept, axis=0), end_xy.take(kept, axis=0)
        positions = positions.take(kept, axis=1)
    walls = SegmentSet(
        angle_rad=fits.angle_rad, radius_m=fits.radius_m, covariance=fits.normal_covariance,
        line=fits.line, line_covariance=fits.line_covariance,
        line_offset_jacobian=fits.line_offset_jacobian, start_xy_m=start_xy, end_xy_m=end_xy,
        first_index=contour.index[positions[0]], last_index=contour.index[positions[1]],
        num_points=counts, residual_chi2_dof=chi2_dof)
    return walls, positions


def _returns_of(contour: _Contour, segments: SegmentRanges) -> SegmentReturns:
    """Return the segments' returns laid end to end (across the seam on a full turn)."""
    counts = segments.stop - segments.start
    offsets = np.add.accumulate(counts) - counts
    position = np.arange(offsets[-1] + counts[-1]) + (segments.start - offsets).repeat(counts)
    return segment_returns(contour.rho.take(position, mode='wrap'),
                           contour.theta.take(position, mode='wrap'), offsets, counts,
                           contour.x.take(position, mode='wrap'),
                           contour.y.take(position, mode='wrap'))


def _with_model_error(walls: SegmentSet, config: FeatureConfig) -> SegmentSet:
    """
    Return the walls with the model error in their covariances (docs/derivation.md#model-error).

    The (angle, radius) covariance N becomes f N (f of (D17), when ``residual_scaling``) plus
    the flatness term of (D18) (:mod:`.model_error`). The line's own (a, b, c) covariance gets
    the same addition through d(a, b, c) / d(angle, radius)
    (:func:`~.model_error.line_covariance_added`). The published (angle, radius) covariance
    also gets the common-mode range offset, o o^T with o = sigma_c d(angle, radius) / d(a, b, c)
    d(a, b, c) / d offset; the (a, b, c) covariance does not, since corners propagate that offset
    with its correlation between the two walls ((D15)-(D16)).
    """
    normal = walls.covariance
    if config.residual_scaling:
        normal = normal * residual_factor(walls.residual_chi2_dof, walls.num_points)[:, None, None]
    if config.wall_flatness_sigma_m > 0.0:
        normal = normal + flatness_covariance(walls.angle_rad, walls.start_xy_m, walls.end_xy_m,
                                              config.wall_flatness_sigma_m)
    line_covariance = walls.line_covariance + line_covariance_added(
        walls.line, walls.angle_rad, normal - walls.covariance)
    published = normal
    if config.common_range_sigma_m > 0.0:
        offset = config.common_range_sigma_m * (
            normal_jacobian(walls.line) * walls.line_offset_jacobian[:, None, :]).sum(axis=2)
        published = normal + offset[:, :, None] * offset[:, None, :]
    return _replaced(walls, covariance=published, line_covariance=line_covariance)


def _corner_covariances(walls: SegmentSet, corners: CornerSet,
                        config: FeatureConfig) -> CornerSet:
    """Return the corners with covariances propagated from the walls' (model error included)."""
    if not len(corners):
        return corners
    return _replaced(corners, covariance=corner_covariance(
        walls, corners.first_segment, corners.second_segment, config.common_range_sigma_m))


def _residual_chi2_dof(returns: SegmentReturns, cos_sin_radius: np.ndarray,
                       noise: Noise) -> np.ndarray:
    """
    Return each fit's residual chi2 per degree of freedom.

    The residual of return i from the line (angle, radius) is d_i = rho_i cos(theta_i - angle)
    - radius, whose variance under the noise model is range_sigma^2 cos^2(theta_i - angle) +
    bearing_sigma^2 rho_i^2 sin^2(theta_i - angle) (docs/derivation.md#maximum-likelihood).
    With x_i = rho_i cos theta_i and y_i = rho_i sin theta_i, rho_i cos(theta_i - angle) =
    x_i cos angle + y_i sin angle and rho_i sin(theta_i - angle) = y_i cos angle - x_i sin
    angle: no sine or cosine per return (as in the compiled core).

    :param returns: the segments' returns
    :param cos_sin_radius: cos(angle), sin(angle) and radius of each fit, shape (3, S)
    :param noise: the noise model (its range_sigma_m and bearing_sigma_rad)
    :return: shape (S,)
    """
    counts, x, y = returns.counts, returns.x, returns.y
    cos, sin, radius = cos_sin_radius.repeat(counts, axis=1)
    along = x * cos
    along += y * sin
    residual = along - radius
    scaled = noise.range_sigma_m * along / returns.rho
    variance = scaled * scaled
    if noise.bearing_sigma_rad != 0.0:            # else the term is 0
        across = (y * cos - x * sin) * noise.bearing_sigma_rad
        variance += across * across
    chi2 = np.add.reduceat(residual * residual / variance, returns.offsets)
    return chi2 / np.maximum(counts - 2, 1)


def _corners(contour: _Contour, walls: SegmentSet, positions: np.ndarray, noise: Noise,
             prepared: _Prepared) -> CornerSet:
    """
    Intersect neighbouring walls (across the seam on a full turn) and keep the real corners.

    A pair makes a corner when its walls are not close to parallel (min_corner_angle) and both
    end at the intersection (:func:`~.corners.walls_end_at`).
    """
    config, count = prepared.config, len(walls)
    first = np.arange(count - 1)
    if contour.points.full_turn and count >= 3:
        first = np.arange(count)               # the last wall meets the first at the seam
    candidates = corner_candidates(walls, first, (first + 1) % max(count, 1),
                                   config.min_corner_angle_rad, config.common_range_sigma_m)
    if not candidates.yaw_rad.size:
        return CornerSet.empty()
    returns = Returns(contour.index, contour.rho, contour.theta, contour.x, contour.y)
    keep, seen = walls_end_at(candidates, walls, positions, returns,
                              abs(contour.points.angle_increment_rad), noise,
                              prepared.corner_rule)
    corners = CornerSet(xy_m=candidates.xy_m, yaw_rad=candidates.yaw_rad,
                        covariance=candidates.covariance,
                        opening_angle_rad=candidates.opening_angle_rad,
                        first_segment=candidates.first_wall,
                        second_segment=candidates.second_wall, end_seen=seen)
    if np.count_nonzero(keep) == keep.size:
        return corners
    return _rows(corners, keep.nonzero()[0])


def _project(x_m: np.ndarray, y_m: np.ndarray, positions: np.ndarray,
             cos_sin_radius: np.ndarray):
    """
    Return the feet of the perpendiculars from each segment's end returns to its line.

    :param x_m: x of the returns in position order, shape (n,), m
    :param y_m: y of the returns in position order, shape (n,), m
    :param positions: position of each segment's first return (row 0) and last (row 1),
        shape (2, S)
    :param cos_sin_radius: cos(angle), sin(angle) and radius of the S lines, shape (3, S)
    :return: (first returns projected (S, 2), last returns projected (S, 2)), m
    """
    c, s, radius = cos_sin_radius
    x, y = x_m[positions], y_m[positions]               # both ends at once: rows 0 and 1
    offset = x * c + y * s - radius
    feet = np.empty(positions.shape + (2,))
    feet[..., 0], feet[..., 1] = x - offset * c, y - offset * s
    return feet[0], feet[1]


def _finite_and_positive(fits: LineFits) -> np.ndarray:
    """Return which fits are usable: finite everywhere, positive-definite normal covariance."""
    cov = fits.normal_covariance
    # A NaN or inf anywhere makes the row's total non-finite.
    finite = np.isfinite(np.add.reduce(fits.line, axis=1)
                         + np.add.reduce(fits.line_covariance, axis=(1, 2))
                         + fits.angle_rad + fits.radius_m + np.add.reduce(cov, axis=(1, 2)))
    return finite & (cov[:, 0, 0] > 0.0) & (cov[:, 0, 0] * cov[:, 1, 1] > cov[:, 0, 1] ** 2)


Table = TypeVar('Table', LineFits, SegmentSet, CornerSet)


def _rows(table: Table, rows: np.ndarray) -> Table:
    """
    Return some rows of a field table, by index.

    The table's own ``select`` indexes every field; take along the first axis is several
    times faster on the fields of more than one axis (a covariance's (n, 3, 3)).
    """
    return type(table)(*(getattr(table, name).take(rows, axis=0)
                         for name in table.__dataclass_fields__))


def _replaced(table: Table, **fields: np.ndarray) -> Table:
    """Return a field table with some fields replaced (dataclasses.replace, at half its cost)."""
    return type(table)(**{**vars(table), **fields})
