# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The per-scan pipeline of the paper's Algorithm 1: returns -> segments -> lines -> corners.

One compiled function (:func:`_features_of_scan`) runs every step on a scan, as loops over its
returns (numba); :func:`extract_features` checks the scan's geometry and packs the arrays it
returns into the frozen result dataclasses.
"""

import functools
import math
from typing import NamedTuple

import numba
from numba import types
import numpy as np

from ._jit import jit, jit_inline
from ._order import wrapped
from .corners import corner_candidates, walls_end_at
from .lines import fit_segments, residual_chi2_dof
from .model_error import with_model_error
from .noise import range_sigma_of_returns
from .scan import valid_returns
from .segmentation import (breakpoints_of, chains_of, merge_segments, pass_budget, split_iepf,
                           trim_ambiguous, trim_offset)
from ..config import FeatureConfig, METHODS
from ..features import CornerSet, Features, SegmentSet
from ..scan import beam_density, scan_geometry, ScanError

_DEFAULT_CONFIG = FeatureConfig()
# A corner may sit one beam without a return beyond a wall's last return (a dropout there),
# reported with that wall's end not seen; farther, it is an extrapolation, not a corner.
_CORNER_MISSING_BEAMS = 1


class _Settings(NamedTuple):
    """The FeatureConfig fields the compiled pipeline reads, as plain typed values."""

    method_code: int
    range_sigma_m: float
    bearing_sigma_rad: float
    range_sigma_from_scan: bool
    common_range_sigma_m: float
    breakpoint_lambda_rad: float
    iepf_threshold_m: float
    iepf_noise_sigmas: float
    merge_chi2: float
    merge_max_missing_beams: int
    end_offset_sigmas: float
    residual_scaling: bool
    model_error_sigma_m: float
    wall_flatness_sigma_m: float
    min_segment_points: int
    min_segment_length_m: float
    min_corner_angle_rad: float
    min_wall_beam_angle_rad: float
    corner_end_sigmas: float
    corner_end_floor_m: float


class _AtDensity(NamedTuple):
    """The rules that count returns at one scan's beam spacing (:func:`..scan.beam_density`)."""

    breakpoint_sigmas: float
    iepf_noise_sigmas: float
    corner_end_sigmas: float
    end_window: int
    corner_window: int


@functools.lru_cache(maxsize=64)
def _at_density(angle_increment_rad: float, beam_count: int,
                config: FeatureConfig) -> _AtDensity:
    """Return the rules that count returns for a scan (one per spacing, size and config)."""
    density = beam_density(angle_increment_rad, beam_count)
    return _AtDensity(density.breakpoint_sigmas, density.rarer(config.iepf_noise_sigmas),
                      density.rarer(config.corner_end_sigmas), density.end_window,
                      density.corner_window)


@functools.lru_cache(maxsize=64)
def _settings(config: FeatureConfig) -> _Settings:
    """Return the compiled pipeline's view of a configuration (one per distinct config)."""
    values = {name: getattr(config, name) for name in _Settings._fields if name != 'method_code'}
    return _Settings(method_code=METHODS.index(config.method), **{
        name: _Settings.__annotations__[name](value) for name, value in values.items()})


def extract_features(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                     config: FeatureConfig = _DEFAULT_CONFIG, range_min_m: float = 0.0,
                     range_max_m: float = math.inf) -> Features:
    """
    Extract segments and corners from one scan, in compiled loops.

    :func:`wctls_ros.core.extract_features` states the arguments, the result and the errors.
    """
    if np.size(ranges_m) > config.max_beams:
        raise ScanError(f'{np.size(ranges_m)} beams are more than max_beams '
                        f'({config.max_beams})')
    ranges, full_turn, cos, sin = scan_geometry(ranges_m, angle_min_rad, angle_increment_rad)
    found = _features_of_scan(
        ranges, cos, sin, float(angle_min_rad), float(angle_increment_rad),
        float(max(range_min_m, config.range_min_m)), float(min(range_max_m, config.range_max_m)),
        full_turn, _settings(config),
        _at_density(float(angle_increment_rad), ranges.size, config))
    segments, corners, work_limited = SegmentSet(*found[:12]), CornerSet(*found[12:19]), found[19]
    return Features(config.method, segments, corners, bool(work_limited))


def kernels_last_first():
    """
    Return the kernels the pipeline calls, last step first, with the types it passes them.

    The reverse of :func:`_features_of_scan`'s calls, for compiling them in other processes
    while this one compiles the pipeline (:mod:`.precompile`). numba compiles a kernel once for
    each tuple of argument types, so these must be exactly the pipeline's, down to the constants
    it passes as literals; a test holds them to the signatures of a compiled pipeline.

    :return: tuples (kernel, tuple of numba argument types)
    """
    real, integer, flag = types.float64, types.intp, types.boolean
    values, indices, flags = real[::1], integer[::1], flag[::1]
    read_only_values = types.Array(real, 1, 'C', readonly=True)
    rows, stacks = real[:, ::1], real[:, :, ::1]         # (K, m) and (K, m, m) float arrays
    settings = numba.typeof(_settings(_DEFAULT_CONFIG))
    return (
        (with_model_error, (rows, values, stacks, stacks, rows, rows, rows, values, indices,
                            flag, real, real)),
        (walls_end_at, (rows, stacks, indices, indices, values, values, rows, values, values,
                        indices, indices, real, real, real, real, real, integer,
                        types.literal(_CORNER_MISSING_BEAMS), real)),
        (corner_candidates, (rows, stacks, rows, rows, indices, indices, real, rows, real)),
        (_usable, (values, rows, real, real, rows)),
        (_feet, (values, values, indices, values, values)),
        (residual_chi2_dof, (values, values, values, indices, indices, values, values, real,
                             real)),
        (fit_segments, (integer, values, values, values, values, indices, indices, real, real)),
        (_in_scan_order, (indices, integer, indices, indices)),
        (trim_offset, (indices, indices, indices, values, values, values, values, real, real,
                       integer, real, integer)),
        (trim_ambiguous, (indices, indices, indices, flag, values, values, values, values, real,
                          real, integer, integer)),
        (_large_enough, (values, values, indices, indices, settings)),
        (merge_segments, (values, values, indices, indices, indices, flag, flags, real, real,
                          real, integer)),
        (split_iepf, (values, values, indices, indices, indices, values, integer)),
        (_split_threshold, (values, real, real, real, real)),
        (pass_budget, (integer,)),
        (chains_of, (values, values, values, flags)),
        (breakpoints_of, (indices, values, values, values, integer, real, flag, real, real, real,
                          integer, real)),
        (range_sigma_of_returns, (indices, values)),
        (valid_returns, (values, read_only_values, read_only_values, real, real, real, real)),
        (_nothing, ()),
    )


@jit
def _features_of_scan(ranges_m, cos, sin, angle_min_rad, angle_increment_rad, range_min_m,
                      range_max_m, full_turn, settings, density):
    """
    Run the steps of the paper's Algorithm 1 on one scan.

    Each step names the section of docs/derivation.md that states its rule or formulas.
    Degenerate pieces (parallel lines, returns in one spot) give inf or NaN along the way;
    every such segment or corner is dropped before it reaches the result.

    :param ranges_m: ranges, shape (N,), m
    :param cos: cos of every beam's bearing, shape (N,)
    :param sin: sin of every beam's bearing, shape (N,)
    :param angle_min_rad: bearing of the first beam, rad
    :param angle_increment_rad: bearing step, rad
    :param range_min_m: closest valid range, m
    :param range_max_m: farthest valid range, m
    :param full_turn: the beams cover a full turn (the first and last are neighbours)
    :param settings: the configuration
    :param density: the rules that count returns, at this scan's beam spacing
    :return: the twelve arrays of a SegmentSet, the seven of a CornerSet, and whether the work
        bound stopped splitting or merging
    """
    index, range_m, bearing_rad, x_m, y_m = valid_returns(
        ranges_m, cos, sin, angle_min_rad, angle_increment_rad, range_min_m, range_max_m)
    count = index.size
    if count < settings.min_segment_points:
        return _nothing() + (False,)
    # #range-noise-from-the-scan
    range_sigma = settings.range_sigma_m
    if settings.range_sigma_from_scan:
        range_sigma = max(range_sigma, range_sigma_of_returns(index, range_m))
    bearing_sigma = settings.bearing_sigma_rad
    # #decision-noise: every decision tolerates the model error on top of the sensor noise;
    # the fits weigh the returns by the sensor noise alone.
    deciding_sigma = math.hypot(range_sigma, settings.model_error_sigma_m)
    # #segmentation-statistics: breakpoints, chains in circular order, IEPF, merging, the size
    # rules, the end trims. From here on, positions index the returns in circular order.
    separated, joinable = breakpoints_of(
        index, x_m, y_m, range_m, ranges_m.size, abs(angle_increment_rad), full_turn,
        deciding_sigma, bearing_sigma, settings.breakpoint_lambda_rad,
        settings.merge_max_missing_beams, density.breakpoint_sigmas)
    order, run_start, run_stop, run_chain = chains_of(range_m, x_m, y_m, separated)
    rho, theta, x, y = range_m[order], bearing_rad[order], x_m[order], y_m[order]
    beam_order = index[order]
    budget = pass_budget(count)
    start, stop, chain, unsplit = split_iepf(
        x, y, run_start, run_stop, run_chain,
        _split_threshold(rho, deciding_sigma, bearing_sigma, settings.iepf_threshold_m,
                         density.iepf_noise_sigmas), budget)
    if start.size == 0:
        return _nothing() + (unsplit,)
    start, stop, chain, angle, radius, unmerged = merge_segments(
        x, y, start, stop, chain, full_turn, joinable[order], deciding_sigma, bearing_sigma,
        settings.merge_chi2, budget)
    work_limited = unsplit or unmerged
    keep = _large_enough(x, y, start, stop, settings)
    start, stop, chain, angle, radius = (start[keep], stop[keep], chain[keep], angle[keep],
                                         radius[keep])
    if start.size == 0:
        return _nothing() + (work_limited,)
    start, stop, chain = trim_ambiguous(start, stop, chain, full_turn, x, y, angle, radius,
                                        deciding_sigma, bearing_sigma,
                                        settings.min_segment_points, density.end_window)
    if settings.end_offset_sigmas > 0.0:
        start, stop, chain = trim_offset(start, stop, chain, x, y, angle, radius, deciding_sigma,
                                         bearing_sigma, settings.min_segment_points,
                                         settings.end_offset_sigmas, density.end_window)
    # #utls, #wtls, #wctls or #maximum-likelihood: the configured fit with its covariance, in
    # scan order of the walls' first returns.
    start, stop = _in_scan_order(beam_order, ranges_m.size, start, stop)
    walls = _fit_walls(rho, theta, x, y, start, stop, range_sigma, bearing_sigma, settings)
    (angle, radius, normal_covariance, line, line_covariance, line_offset, start_xy, end_xy,
     first, last, counts, chi2_dof) = walls
    if angle.size == 0:
        return _nothing() + (work_limited,)
    # #corners: which pairs are corners is decided with the decision noise; the published
    # covariances add the model error to the fits' (#model-error).
    first_wall, second_wall, corner_xy, corner_yaw, opening, end_seen = _corners(
        x, y, walls, first, last, full_turn, abs(angle_increment_rad), deciding_sigma,
        bearing_sigma, settings, density)
    # #model-error (D17), (D18), then #corners and #common-mode-range-offset, (D11)-(D16).
    normal_covariance, line_covariance = with_model_error(
        line, angle, normal_covariance, line_covariance, line_offset, start_xy, end_xy,
        chi2_dof, counts, settings.residual_scaling, settings.wall_flatness_sigma_m,
        settings.common_range_sigma_m)
    corner_covariance = corner_candidates(
        line, line_covariance, start_xy, end_xy, first_wall, second_wall, 0.0, line_offset,
        settings.common_range_sigma_m)[3]
    return (angle, radius, normal_covariance, line, line_covariance, line_offset, start_xy,
            end_xy, beam_order[first], beam_order[last], counts, chi2_dof, corner_xy, corner_yaw,
            corner_covariance, opening, first_wall, second_wall, end_seen, work_limited)


@jit
def _nothing():
    """
    Return the arrays of a scan without segments, in :func:`_features_of_scan`'s shape.

    The caller appends whether the work bound stopped splitting or merging: as an argument, a
    literal False and a bool would compile this twice (0.5 s of the cold start).
    """
    no_index = np.zeros(0, np.intp)
    return (np.zeros(0), np.zeros(0), np.zeros((0, 2, 2)), np.zeros((0, 3)),
            np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros((0, 2)), no_index,
            no_index, no_index, np.zeros(0), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3, 3)),
            np.zeros(0), no_index, no_index, np.zeros((0, 2), np.bool_))


@jit
def _split_threshold(rho, range_sigma, bearing_sigma, threshold_m, noise_sigmas):
    """
    Return the IEPF split distance of every return, m.

    The paper's split distance, but never within iepf_noise_sigmas of a return's noise (more on
    dense scans, :meth:`~wctls_ros.core.scan.BeamDensity.rarer`): a threshold of 2 sigma splits
    a straight wall at its noise in most scans.
    """
    threshold = np.empty(rho.size)
    for i in range(rho.size):
        threshold[i] = threshold_m
        if noise_sigmas > 0.0:
            noise = math.sqrt(range_sigma ** 2 + (rho[i] * bearing_sigma) ** 2)
            threshold[i] = max(threshold[i], noise_sigmas * noise)
    return threshold


@jit
def _large_enough(x, y, start, stop, settings):
    """Return which segments have min_segment_points returns and min_segment_length."""
    count = x.size
    keep = np.empty(start.size, np.bool_)
    for s in range(start.size):
        last = (stop[s] - 1) % count
        dx, dy = x[last] - x[start[s]], y[last] - y[start[s]]
        keep[s] = (stop[s] - start[s] >= settings.min_segment_points
                   and dx * dx + dy * dy >= settings.min_segment_length_m ** 2)
    return keep


@jit
def _in_scan_order(beam_of_position, beam_count, start, stop):
    """
    Return the segments sorted by the beam index of their first return.

    Every segment starts at a different return, so each beam index holds at most one: placing
    them by beam index sorts them in O(beams).
    """
    segment_at_beam = np.full(beam_count, -1, np.intp)
    for s in range(start.size):
        segment_at_beam[beam_of_position[start[s]]] = s
    sorted_start, sorted_stop = np.empty_like(start), np.empty_like(stop)
    placed = 0
    for beam in range(beam_count):
        s = segment_at_beam[beam]
        if s >= 0:
            sorted_start[placed], sorted_stop[placed] = start[s], stop[s]
            placed += 1
    return sorted_start, sorted_stop


@jit_inline
def _fit_walls(rho, theta, x, y, start, stop, range_sigma, bearing_sigma, settings):
    """
    Fit every segment with the configured method and keep the ones that are walls.

    A segment is left out when its fit is degenerate (non-finite, or a covariance that is not
    positive definite) or when it lies within min_wall_beam_angle of the beam to its middle:
    returns strung along the beams are mixed pixels or grazing veils, not a wall. A segment
    crossing the seam of a full turn runs past the last position (positions wrap).

    :return: (angle, radius, covariance of (angle, radius), line, its covariance, its offset
        Jacobian, start and end projected on the line, first and last position, returns,
        residual chi2 per degree of freedom), one row per kept wall
    """
    count, segments = x.size, start.size
    counts, offsets = np.empty(segments, np.intp), np.empty(segments, np.intp)
    total = 0
    for s in range(segments):
        counts[s], offsets[s] = stop[s] - start[s], total
        total += counts[s]
    rho_w, theta_w, x_w, y_w = np.empty(total), np.empty(total), np.empty(total), np.empty(total)
    for s in range(segments):
        for k in range(counts[s]):
            i = wrapped(start[s] + k, count)
            at = offsets[s] + k
            rho_w[at], theta_w[at], x_w[at], y_w[at] = rho[i], theta[i], x[i], y[i]
    (line, line_covariance, angle, radius, normal_covariance, line_offset,
     _) = fit_segments(settings.method_code, rho_w, theta_w, x_w, y_w, offsets, counts,
                       range_sigma, bearing_sigma)
    chi2_dof = residual_chi2_dof(rho_w, x_w, y_w, offsets, counts, angle, radius, range_sigma,
                                 bearing_sigma)
    last = (stop - 1) % count
    start_xy, end_xy = _feet(x, y, start, angle, radius), _feet(x, y, last, angle, radius)
    min_along_beam = math.sin(settings.min_wall_beam_angle_rad)
    keep = np.empty(start.size, np.bool_)
    for s in range(start.size):
        middle_x = 0.5 * (start_xy[s, 0] + end_xy[s, 0])
        middle_y = 0.5 * (start_xy[s, 1] + end_xy[s, 1])
        along_beam = abs(math.cos(math.atan2(middle_y, middle_x) - angle[s]))
        keep[s] = _usable(line[s], line_covariance[s], angle[s], radius[s],
                          normal_covariance[s]) and along_beam >= min_along_beam
    return (angle[keep], radius[keep], normal_covariance[keep], line[keep],
            line_covariance[keep], line_offset[keep], start_xy[keep], end_xy[keep],
            start[keep], last[keep], counts[keep], chi2_dof[keep])


@jit
def _feet(x, y, position, angle, radius):
    """Return the feet of the perpendiculars from the returns at ``position`` to the lines, m."""
    foot = np.empty((position.size, 2))
    for s in range(position.size):
        c, s_ = math.cos(angle[s]), math.sin(angle[s])
        offset = x[position[s]] * c + y[position[s]] * s_ - radius[s]
        foot[s, 0], foot[s, 1] = x[position[s]] - offset * c, y[position[s]] - offset * s_
    return foot


@jit
def _usable(line, line_covariance, angle, radius, normal_covariance):
    """Return whether a fit is finite everywhere with a positive-definite normal covariance."""
    total = line.sum() + line_covariance.sum() + angle + radius + normal_covariance.sum()
    return (np.isfinite(total) and normal_covariance[0, 0] > 0.0
            and normal_covariance[0, 0] * normal_covariance[1, 1] > normal_covariance[0, 1] ** 2)


@jit_inline
def _corners(x, y, walls, first, last, full_turn, step_rad, range_sigma, bearing_sigma,
             settings, density):
    """
    Intersect neighbouring walls (across the seam on a full turn) and keep the real corners.

    A pair makes a corner when its walls are not close to parallel (min_corner_angle) and both
    end at the intersection (:func:`~.corners.walls_end_at`).

    :return: (first wall, second wall, position (C, 2) m, yaw (C,) rad, opening angle (C,) rad,
        whether each wall's end was seen (C, 2)) of the corners
    """
    angle, radius, line, line_covariance, line_offset, start_xy, end_xy = (
        walls[0], walls[1], walls[3], walls[4], walls[5], walls[6], walls[7])
    count = angle.size
    pairs = count if full_turn and count >= 3 else count - 1   # the last meets the first
    first_wall = np.arange(max(pairs, 0))
    second_wall = (first_wall + 1) % max(count, 1)
    kept, xy, yaw, covariance, opening = corner_candidates(
        line, line_covariance, start_xy, end_xy, first_wall, second_wall,
        settings.min_corner_angle_rad, line_offset, settings.common_range_sigma_m)
    first_wall, second_wall = first_wall[kept], second_wall[kept]
    keep, seen = walls_end_at(
        xy, covariance, first_wall, second_wall, angle, radius, 0.5 * (start_xy + end_xy), x, y,
        last, first, step_rad, range_sigma, bearing_sigma, density.corner_end_sigmas,
        settings.corner_end_floor_m, density.corner_window, _CORNER_MISSING_BEAMS,
        settings.end_offset_sigmas)
    return (first_wall[keep], second_wall[keep], xy[keep], yaw[keep], opening[keep],
            seen[keep])
