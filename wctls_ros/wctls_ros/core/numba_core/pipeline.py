# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The per-scan pipeline of the paper's Algorithm 1: returns -> segments -> lines -> corners.

One compiled function (:func:`_features_of_scan`) runs every step on a scan, as loops over its
returns (numba), the plausibility bounds included; :func:`extract_features` checks the scan's
geometry, hands it the configuration prepared once per configuration and beam layout (its
compiled version for their types with it: no dispatcher per scan), and wraps the arrays it
returns in the frozen result dataclasses: no other Python runs per scan (but on the rare scan
whose features the plausibility bounds drop, :func:`..plausibility.kept`).
"""

import functools
import math
from typing import Callable, NamedTuple

from numba import typeof
from numba.core.dispatcher import Dispatcher
import numpy as np

from ._jit import jit, jit_inline, use_disk_cache
from ._order import wrapped
from .corners import corner_candidates, corner_covariance, walls_end_at
from .lines import fit_segments, residual_chi2_dof
from .model_error import with_model_error
from .noise import range_sigma_of_returns
from .plausibility import plausible
from .scan import valid_returns
from .segmentation import (breakpoints_of, chains_of, merge_segments, pass_budget, split_iepf,
                           trim_ambiguous, trim_offset)
from ..config import FeatureConfig, METHODS
from ..features import CornerSet, Features, SegmentSet
from ..plausibility import kept
from ..prepared import LatestPrepared
from ..records import (BeamGrid, CornerArrays, CornerEndRule, Lines, Noise, Returns,
                       SegmentArrays, Segments, Settings)
from ..scan import beam_density, scan_geometry, ScanError

_DEFAULT_CONFIG = FeatureConfig()


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
    """
    Return the rules that count returns for a scan (one per spacing, size and config).

    As floats and ints whatever the configuration holds (an int sigma, kept as it is at the
    tuned spacing, would be a record of another type: another compile of the pipeline).
    """
    density = beam_density(angle_increment_rad, beam_count)
    return _AtDensity(float(density.breakpoint_sigmas),
                      float(density.rarer(config.iepf_noise_sigmas)),
                      float(density.rarer(config.corner_end_sigmas)), int(density.end_window),
                      int(density.corner_window))


@functools.lru_cache(maxsize=64)
def _settings(config: FeatureConfig) -> Settings:
    """Return the compiled pipeline's view of a configuration (one per distinct config)."""
    values = {name: getattr(config, name) for name in Settings._fields if name != 'method_code'}
    return Settings(method_code=METHODS.index(config.method), **{
        name: Settings.__annotations__[name](value) for name, value in values.items()})


class _Prepared(NamedTuple):
    """
    The compiled pipeline's arguments that depend on the configuration and beam layout.

    :ivar compiled: the version of :func:`_features_of_scan` compiled for the types of these
        arguments and of a scan's (:func:`_compiled_version`)
    """

    config: FeatureConfig
    angle_increment_rad: float
    beam_count: int
    settings: Settings
    density: _AtDensity
    compiled: Callable


def _compiled_version(settings: Settings, density: _AtDensity) -> Callable:
    """
    Return :func:`_features_of_scan` compiled for a configuration's records, past the dispatcher.

    numba's dispatcher works out the type of every argument on every call, 2.5-2.8 us a scan
    (docs/performance.md): here that is done once per configuration and beam layout, and the
    compiled version for those types (compiled, or loaded from the cache, now if need be) is
    called directly. Its arguments' types are the same on every scan: those of the results of
    :func:`..scan.scan_geometry` (of any scan: the types of a sample's), Python floats, and the
    prepared records. Whatever stands in its place and is no dispatcher (a benchmark's clock)
    is called as it is.
    """
    compiled = _features_of_scan
    if not isinstance(compiled, Dispatcher):
        return compiled
    ranges, full_turn, cos, sin = scan_geometry(np.zeros(1), 0.0, 1.0)
    return compiled.compile(tuple(typeof(argument) for argument in (
        ranges, cos, sin, 0.0, 0.0, 0.0, 0.0, full_turn, settings, density)))


def _prepare(config: FeatureConfig, angle_increment_rad: float, beam_count: int) -> _Prepared:
    """Return the compiled pipeline's arguments for a configuration and beam layout."""
    settings = _settings(config)
    density = _at_density(angle_increment_rad, beam_count, config)
    return _Prepared(config, angle_increment_rad, beam_count, settings, density,
                     _compiled_version(settings, density))


# The arguments of the latest configuration and layout, compared by identity (see
# :class:`..prepared.LatestPrepared`) before the caches above are asked.
_LATEST = LatestPrepared(_prepare)


def extract_features(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                     config: FeatureConfig = _DEFAULT_CONFIG, range_min_m: float = 0.0,
                     range_max_m: float = math.inf) -> Features:
    """
    Compiled twin of :func:`..numpy_core.pipeline.extract_features`.

    :func:`wctls_ros.core.extract_features` states the arguments, the result and the errors.
    """
    use_disk_cache()
    if np.size(ranges_m) > config.max_beams:
        raise ScanError(f'{np.size(ranges_m)} beams are more than max_beams '
                        f'({config.max_beams})')
    ranges, full_turn, cos, sin = scan_geometry(ranges_m, angle_min_rad, angle_increment_rad)
    prepared = _LATEST.get(config, float(angle_increment_rad), ranges.size)
    # Arguments of the types the version was compiled for (:func:`_compiled_version`).
    (segments, corners, keep_segment, keep_corner, work_limited, range_sigma_m,
     noise_implausible) = prepared.compiled(
        ranges, cos, sin, float(angle_min_rad), prepared.angle_increment_rad,
        float(max(range_min_m, config.range_min_m)), float(min(range_max_m, config.range_max_m)),
        full_turn, prepared.settings, prepared.density)
    if segments is None:
        return Features(config.method, SegmentSet.empty(), CornerSet.empty(), work_limited,
                        range_sigma_m, noise_implausible)
    features = Features.of_scan(config.method, SegmentSet.of_fields(segments),
                                CornerSet.of_fields(corners), work_limited, range_sigma_m)
    return features if keep_segment is None else kept(features, keep_segment, keep_corner)


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
    :return: (the fields of the walls, :data:`~.records.SegmentArrays`, and of the corners
        between them, :data:`~.records.CornerArrays`, as tuples: None when the scan has none;
        which walls and which corners pass the plausibility bounds: None when all do; whether
        the work bound stopped splitting or merging; the range noise the scan was processed
        with, m (NaN: too few returns); whether it exceeded ``max_range_sigma_m``, and the scan
        gives no features)
    """
    returns = valid_returns(ranges_m, cos, sin, angle_min_rad, angle_increment_rad,
                            range_min_m, range_max_m)
    count = returns.beam_index.size
    if count < settings.min_segment_points:
        return None, None, None, None, False, math.nan, False
    # #range-noise-from-the-scan
    range_sigma = settings.range_sigma_m
    if settings.range_sigma_from_scan:
        range_sigma = max(range_sigma, range_sigma_of_returns(returns.beam_index, returns.range_m))
    # #plausibility: a scan whose own noise is beyond the bound is no scan of surfaces.
    if not range_sigma <= settings.max_range_sigma_m:
        return None, None, None, None, False, range_sigma, True
    # #decision-noise: every decision tolerates the model error on top of the sensor noise;
    # the fits weigh the returns by the sensor noise alone.
    noise = Noise(range_sigma, settings.bearing_sigma_rad,
                  math.hypot(range_sigma, settings.model_error_sigma_m))
    grid = BeamGrid(ranges_m.size, abs(angle_increment_rad), full_turn)
    # #segmentation-statistics: breakpoints, chains in circular order, IEPF, merging, the size
    # rules, the end trims. From here on, positions index the returns in circular order.
    separated, joinable = breakpoints_of(returns, grid, noise, settings.breakpoint_lambda_rad,
                                         settings.merge_max_missing_beams,
                                         density.breakpoint_sigmas)
    order, runs = chains_of(returns, separated)
    contour, joinable = _in_circular_order(returns, joinable, order)
    x, y = contour.x_m, contour.y_m
    budget = pass_budget(count)
    segments, unsplit = split_iepf(
        x, y, runs, _split_threshold(contour.range_m, noise, settings.iepf_threshold_m,
                                     density.iepf_noise_sigmas), budget)
    if segments.start.size == 0:
        return None, None, None, None, unsplit, range_sigma, False
    segments, lines, unmerged = merge_segments(x, y, segments, full_turn, joinable, noise,
                                               settings.merge_chi2, budget)
    work_limited = unsplit or unmerged
    keep = _large_enough(x, y, segments, settings)
    every = keep.all()
    segments = Segments(_rows(segments.start, keep, every), _rows(segments.stop, keep, every),
                        _rows(segments.chain, keep, every))
    lines = Lines(_rows(lines.angle_rad, keep, every), _rows(lines.radius_m, keep, every))
    if segments.start.size == 0:
        return None, None, None, None, work_limited, range_sigma, False
    segments = trim_ambiguous(segments, full_turn, x, y, lines, noise,
                              settings.min_segment_points, density.end_window)
    if settings.end_offset_sigmas > 0.0:
        segments = trim_offset(segments, x, y, lines, noise, settings.min_segment_points,
                               settings.end_offset_sigmas, density.end_window)
    # #utls, #wtls, #wctls or #maximum-likelihood: the configured fit with its covariance, in
    # scan order of the walls' first returns.
    start, stop = _in_scan_order(contour.beam_index, segments.start, segments.stop)
    walls, positions = _fit_walls(contour, start, stop, noise, settings)
    if walls.angle_rad.size == 0:
        return None, None, None, None, work_limited, range_sigma, False
    # #corners: which pairs are corners is decided with the decision noise; the published
    # covariances add the model error to the fits' (#model-error).
    corners = _corners(contour, walls, positions, grid, noise, settings, density)
    # #model-error (D17), (D18), then #corners and #common-mode-range-offset, (D11)-(D16).
    covariance, line_covariance = with_model_error(
        walls, settings.residual_scaling, settings.wall_flatness_sigma_m,
        settings.common_range_sigma_m)
    published_walls = SegmentArrays(
        angle_rad=walls.angle_rad, radius_m=walls.radius_m, covariance=covariance,
        line=walls.line, line_covariance=line_covariance,
        line_offset_jacobian=walls.line_offset_jacobian, start_xy_m=walls.start_xy_m,
        end_xy_m=walls.end_xy_m, first_index=walls.first_index, last_index=walls.last_index,
        num_points=walls.num_points, residual_chi2_dof=walls.residual_chi2_dof)
    published_corners = CornerArrays(
        xy_m=corners.xy_m, yaw_rad=corners.yaw_rad,
        covariance=corner_covariance(published_walls, corners.first_segment,
                                     corners.second_segment, settings.common_range_sigma_m),
        opening_angle_rad=corners.opening_angle_rad, first_segment=corners.first_segment,
        second_segment=corners.second_segment, end_seen=corners.end_seen)
    # #plausibility: nothing published whose covariance gates nothing.
    keep_segment, keep_corner = plausible(published_walls, published_corners, range_sigma,
                                          settings)
    # Their fields as plain tuples: Python gets a named tuple by calling its class, a
    # microsecond per scan for the two.
    return (published_walls[:], published_corners[:], keep_segment, keep_corner, work_limited,
            range_sigma, False)


@jit
def _split_threshold(rho, noise, threshold_m, noise_sigmas):
    """
    Compiled twin of the IEPF split distance of :func:`..numpy_core.pipeline._split`.

    :return: the split distance of every return, shape (n,), m
    """
    threshold = np.empty(rho.size)
    for i in range(rho.size):
        threshold[i] = threshold_m
        if noise_sigmas > 0.0:
            sigma = math.sqrt(noise.deciding_sigma_m ** 2
                              + (rho[i] * noise.bearing_sigma_rad) ** 2)
            threshold[i] = max(threshold[i], noise_sigmas * sigma)
    return threshold


@jit
def _in_circular_order(returns, joinable, order):
    """
    Return the returns and their joinable flags in circular order (a rotation of beam order).

    None when the rotation is none (a scan short of a full turn, or one whose first return
    starts a chain): the returns themselves then. Else beam order from ``order[0]`` on, then
    up to it (:func:`.segmentation.chains_of`): each array in two runs of contiguous copies,
    which the compiler vectorises (an index array read per return it does not; 0.9 against 1.8
    us per array of 4320).
    """
    n = order.size
    if n == 0 or order[0] == 0:
        return returns, joinable
    first = order[0]
    return (Returns(_rotated(returns.beam_index, first), _rotated(returns.range_m, first),
                    _rotated(returns.bearing_rad, first), _rotated(returns.x_m, first),
                    _rotated(returns.y_m, first)),
            _rotated(joinable, first))


@jit
def _rotated(values, first):
    """Return ``values[first:]`` followed by ``values[:first]``, a new array."""
    rotated = np.empty_like(values)
    source, target = values[first:], rotated[:values.size - first]
    for k in range(source.size):
        target[k] = source[k]
    source, target = values[:first], rotated[values.size - first:]
    for k in range(source.size):
        target[k] = source[k]
    return rotated


@jit
def _large_enough(x, y, segments, settings):
    """Compiled twin of :func:`..numpy_core.pipeline._large_enough`: which to keep."""
    count, start, stop = x.size, segments.start, segments.stop
    keep = np.empty(start.size, np.bool_)
    for s in range(start.size):
        last = (stop[s] - 1) % count
        dx, dy = x[last] - x[start[s]], y[last] - y[start[s]]
        keep[s] = (stop[s] - start[s] >= settings.min_segment_points
                   and dx * dx + dy * dy >= settings.min_segment_length_m ** 2)
    return keep


@jit
def _in_scan_order(beam_of_position, start, stop):
    """
    Return the segments sorted by the beam index of their first return.

    Every segment starts at a different return, so no two have the same beam index: any sort
    gives the one order, and a sort of the S segments costs less than a pass over the beams.
    """
    order = np.argsort(beam_of_position[start])
    return start[order], stop[order]


@jit_inline
def _fit_walls(contour, start, stop, noise, settings):
    """
    Compiled twin of :func:`..numpy_core.pipeline._fit_walls`.

    A segment crossing the seam of a full turn runs past the last position (positions wrap).

    :return: (the walls kept, :data:`~.records.SegmentArrays` before the model error, in scan
        order; the positions of their first and last returns in the contour, shape (2, S))
    """
    rho, theta, x, y = contour.range_m, contour.bearing_rad, contour.x_m, contour.y_m
    count, segments = x.size, start.size
    counts = stop - start
    # The fits read each segment's returns as one run: the contour's own, unless one crosses
    # the seam; then the returns of every segment are laid end to end in new arrays.
    rho_w, theta_w, x_w, y_w, offsets = rho, theta, x, y, start
    if segments > 0 and stop.max() > count:
        offsets = np.empty(segments, np.intp)
        total = 0
        for s in range(segments):
            offsets[s] = total
            total += counts[s]
        rho_w, theta_w, x_w = np.empty(total), np.empty(total), np.empty(total)
        y_w = np.empty(total)
        for s in range(segments):
            for k in range(counts[s]):
                i = wrapped(start[s] + k, count)
                at = offsets[s] + k
                rho_w[at], theta_w[at], x_w[at], y_w[at] = rho[i], theta[i], x[i], y[i]
    (line, line_covariance, angle, radius, normal_covariance, line_offset,
     _) = fit_segments(settings.method_code, rho_w, theta_w, x_w, y_w, offsets, counts, noise)
    chi2_dof = residual_chi2_dof(rho_w, x_w, y_w, offsets, counts, Lines(angle, radius), noise)
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
    every = keep.all()
    first, last = _rows(start, keep, every), _rows(last, keep, every)
    positions = np.empty((2, first.size), np.intp)
    for s in range(first.size):
        positions[0, s], positions[1, s] = first[s], last[s]
    walls = SegmentArrays(
        angle_rad=_rows(angle, keep, every), radius_m=_rows(radius, keep, every),
        covariance=_rows(normal_covariance, keep, every), line=_rows(line, keep, every),
        line_covariance=_rows(line_covariance, keep, every),
        line_offset_jacobian=_rows(line_offset, keep, every),
        start_xy_m=_rows(start_xy, keep, every), end_xy_m=_rows(end_xy, keep, every),
        first_index=contour.beam_index[first], last_index=contour.beam_index[last],
        num_points=_rows(counts, keep, every), residual_chi2_dof=_rows(chi2_dof, keep, every))
    return walls, positions


@jit
def _feet(x, y, position, angle, radius):
    """Compiled twin of :func:`..numpy_core.pipeline._project`, the returns at ``position``."""
    foot = np.empty((position.size, 2))
    for s in range(position.size):
        c, s_ = math.cos(angle[s]), math.sin(angle[s])
        offset = x[position[s]] * c + y[position[s]] * s_ - radius[s]
        foot[s, 0], foot[s, 1] = x[position[s]] - offset * c, y[position[s]] - offset * s_
    return foot


@jit
def _usable(line, line_covariance, angle, radius, normal_covariance):
    """Compiled twin of :func:`..numpy_core.pipeline._finite_and_positive` for one fit."""
    total = line.sum() + line_covariance.sum() + angle + radius + normal_covariance.sum()
    return (np.isfinite(total) and normal_covariance[0, 0] > 0.0
            and normal_covariance[0, 0] * normal_covariance[1, 1] > normal_covariance[0, 1] ** 2)


@jit_inline
def _corners(contour, walls, positions, grid, noise, settings, density):
    """
    Compiled twin of :func:`..numpy_core.pipeline._corners`.

    :return: the corners, their covariance the walls' before the model error
        (:data:`~.records.CornerArrays`)
    """
    count = walls.angle_rad.size
    pairs = count if grid.full_turn and count >= 3 else count - 1   # the last meets the first
    first_wall = np.arange(max(pairs, 0))
    second_wall = (first_wall + 1) % max(count, 1)
    candidates = corner_candidates(walls, first_wall, second_wall, settings.min_corner_angle_rad,
                                   settings.common_range_sigma_m)
    keep, seen = walls_end_at(candidates, walls, positions, contour, grid.step_rad, noise,
                              CornerEndRule(density.corner_end_sigmas,
                                            settings.corner_end_floor_m, density.corner_window,
                                            settings.end_offset_sigmas))
    every = keep.all()
    return CornerArrays(xy_m=_rows(candidates.xy_m, keep, every),
                        yaw_rad=_rows(candidates.yaw_rad, keep, every),
                        covariance=_rows(candidates.covariance, keep, every),
                        opening_angle_rad=_rows(candidates.opening_angle_rad, keep, every),
                        first_segment=_rows(candidates.first_wall, keep, every),
                        second_segment=_rows(candidates.second_wall, keep, every),
                        end_seen=_rows(seen, keep, every))


@jit
def _rows(values, keep, every):
    """
    Return the rows of ``values`` that ``keep`` selects: ``values`` itself when it selects all.

    Nearly every scan keeps every wall and most keep every corner: no copy of them then.
    """
    return values if every else values[keep]
