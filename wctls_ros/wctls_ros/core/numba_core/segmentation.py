# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Split a scan into straight segments: breakpoints, IEPF, statistical merging, trimmed ends.

Positions here index the scan's valid returns in *circular order*: for a full turn the order is
rotated to start at a breakpoint (or, on a closed contour without any, at the farthest return),
so a wall crossing the +-pi seam is an ordinary run of positions. SegmentRanges are half-open
position ranges [start, stop) into that order; on a full turn a segment may run past its end
(positions count modulo the number of returns).

Every step is a compiled loop (numba) over arrays, called by the pipeline's compiled function.
"""

import math

import numpy as np

from ._jit import jit
from ._order import stable_order, wrapped
from ..records import Lines, Segments
from ..rules import (BUDGET_EXTRA_PASSES, BUDGET_LEVELS_PER_DOUBLING, JOINABLE_SIGMAS, MIN_CHORD_M,
                     MIN_FIT_RETURNS)


@jit
def pass_budget(count: int) -> int:
    """
    Compiled twin of :func:`..numpy_core.segmentation.pass_budget`.

    :param count: number of returns in the scan
    :return: the number of passes, 2 ceil(log2 count) + 8
    """
    return (BUDGET_LEVELS_PER_DOUBLING * math.ceil(math.log2(max(count, 2)))
            + BUDGET_EXTRA_PASSES)


@jit
def _reach_factor(beams, step_rad, lambda_rad):
    """
    Return sin(dphi) / sin(lambda - dphi) for returns ``beams`` steps apart, -1 if dphi >= lambda.

    The distance neighbours on one surface may lie apart is r times this factor (Borges and
    Aldon); no surface is seen at a bearing difference of lambda or more.
    """
    dphi = beams * step_rad
    return math.sin(dphi) / math.sin(lambda_rad - dphi) if dphi < lambda_rad else -1.0


@jit
def breakpoints_of(returns, grid, noise, lambda_rad, max_missing_beams, noise_sigmas):
    """
    Compiled twin of :func:`..numpy_core.segmentation.breakpoints`, one pair of neighbours at once.

    :param returns: the scan's valid returns in beam order
    :param grid: the scan's beams
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param lambda_rad: worst incidence angle still treated as one surface, rad
    :param max_missing_beams: most invalid beams between two returns of one chain
    :param noise_sigmas: k, the allowance for noise in sigmas of a return's position noise
    :return: (separated (n,), joinable (n,)): return i against return i - 1 (entry 0 against
        the last return, across the seam)
    """
    index, x_m, y_m, range_m = returns.beam_index, returns.x_m, returns.y_m, returns.range_m
    beam_count, step_rad = grid.beam_count, grid.step_rad
    range_sigma_m, bearing_sigma_rad = noise.deciding_sigma_m, noise.bearing_sigma_rad
    n = index.size
    separated = np.zeros(n, np.bool_)
    joinable = np.zeros(n, np.bool_)
    if n == 0:
        return separated, joinable
    # The factor for returns 1, 2, ... beams apart, computed once (in the loop, LLVM computed both
    # sines for every return, 5 % of a scan). Only returns at most max_missing_beams + 1 beams
    # apart can be one surface (farther apart is a gap), and none lambda or more apart.
    # (The minimum is taken in floats: a step of 1e-20 rad makes lambda / step exceed the
    # largest int64, which int() turns into a negative size.)
    factors = np.empty(int(min(max_missing_beams + 2.0, lambda_rad / step_rad + 2.0)))
    for beams in range(1, factors.size):
        factors[beams] = _reach_factor(float(beams), step_rad, lambda_rad)
    # Across the seam: the rest of the turn, in increments (about 1).
    seam_beams = (index[0] + (2.0 * math.pi - (beam_count - 1) * step_rad) / step_rad
                  + (beam_count - 1 - index[n - 1]))
    seam_reach = _reach_factor(seam_beams, step_rad, lambda_rad)
    for i in range(n):
        before = i - 1 if i > 0 else n - 1
        if i > 0:
            apart = index[i] - index[i - 1]
            beams, reach = float(apart), factors[apart] if apart < factors.size else -1.0
        else:
            beams, reach = seam_beams, seam_reach
        r = min(range_m[i], range_m[before])
        dx, dy = x_m[i] - x_m[before], y_m[i] - y_m[before]
        surface = r * reach
        sigma = math.sqrt(range_sigma_m ** 2 + (r * bearing_sigma_rad) ** 2)
        distance = math.sqrt(dx * dx + dy * dy)
        gap = beams - 1.0 >= max_missing_beams + 0.5
        separated[i] = reach < 0.0 or gap or distance > surface + noise_sigmas * sigma
        joinable[i] = (separated[i] and reach >= 0.0 and not gap
                       and distance <= surface + JOINABLE_SIGMAS * sigma)
    if not grid.full_turn or n == 1:
        separated[0], joinable[0] = True, False
    return separated, joinable


@jit
def chains_of(returns, separated):
    """
    Compiled twin of :func:`..numpy_core.segmentation.chains`.

    :param returns: the scan's valid returns in beam order
    :param separated: where returns start a new chain (from :func:`breakpoints_of`), shape (n,)
    :return: (the returns' indices in circular order (n,); the runs between breakpoints, as
        :class:`~.records.Segments`: the two arcs of a closed contour are one chain)
    """
    range_m, x_m, y_m = returns.range_m, returns.x_m, returns.y_m
    n = range_m.size
    breaks = np.nonzero(separated)[0]
    if n and breaks.size == 0:
        first = int(np.argmax(range_m))
        farthest, opposite = -1.0, 0
        for i in range(n):
            dx, dy = x_m[i] - x_m[first], y_m[i] - y_m[first]
            if dx * dx + dy * dy > farthest:
                farthest, opposite = dx * dx + dy * dy, i
        opposite = (opposite - first) % n
        start = np.array([1, opposite + 1])
        stop = np.array([opposite, n])
        chain = np.zeros(2, np.intp)
    else:
        first = breaks[0] if n else 0
        start = breaks - first
        stop = np.empty_like(start)
        for k in range(start.size):   # a loop, not stop[:-1] = start[1:] (see _jit.py)
            stop[k] = start[k + 1] if k + 1 < start.size else n
        chain = np.arange(start.size)
    order = np.empty(n, np.intp)
    for position in range(n):
        order[position] = wrapped(first + position, n)
    return order, Segments(start, stop, chain)


@jit
def split_iepf(x_m, y_m, runs, threshold_m, max_levels):
    """
    Compiled twin of :func:`..numpy_core.segmentation.iterative_end_point_fit`, depth first.

    A piece at a time, where the twin splits every piece of a level in one pass: a piece's depth
    stands for the twin's pass, and the right part of every split waits on a stack while the left
    one is split.

    :param x_m: x of the returns in circular order, shape (n,), m
    :param y_m: y of the returns in circular order, shape (n,), m
    :param runs: the runs between breakpoints
    :param threshold_m: split distance of every return, shape (n,), m
    :param max_levels: the most split passes
    :return: (the straight pieces with at least MIN_FIT_RETURNS returns; whether pieces were
        left out because the passes ran out)
    """
    start, stop, chain = runs.start, runs.stop, runs.chain
    n = x_m.size
    out_start = np.empty(n + 1, np.intp)
    out_stop = np.empty(n + 1, np.intp)
    out_chain = np.empty(n + 1, np.intp)
    found = 0
    unsplit = False
    # 1 / threshold of each return, once: the pieces measure most returns several times.
    per_threshold = np.empty(n)
    for i in range(n):
        per_threshold[i] = 1.0 / threshold_m[i]
    # Pending pieces (first, stop, depth): the right part of every split waits on the stack.
    stack = np.empty((max_levels + 2, 3), np.intp)
    for run in range(start.size):
        stack[0, 0], stack[0, 1], stack[0, 2] = start[run], stop[run], 0
        pending = 1
        while pending:
            pending -= 1
            first, end, depth = stack[pending, 0], stack[pending, 1], stack[pending, 2]
            if end - first < MIN_FIT_RETURNS:     # can be neither fitted nor split
                continue
            last = end - 1
            x0, y0, x1, y1 = x_m[first], y_m[first], x_m[last], y_m[last]
            dx, dy = x1 - x0, y1 - y0
            offset = x0 * y1 - y0 * x1
            farthest, cut, undefined = -1.0, first, False
            for i in range(first, end):
                # |chord x (return - chord start)| over the return's threshold.
                cross = dx * y_m[i]
                cross -= dy * x_m[i]
                cross += offset
                cross = abs(cross) * per_threshold[i]
                if cross > farthest:
                    farthest, cut = cross, i
                elif cross != cross:
                    undefined = True
            chord2 = dx * dx + dy * dy
            if (not undefined and farthest * farthest > chord2
                    and chord2 > MIN_CHORD_M ** 2):
                if depth == max_levels:          # out of passes: not straight, left out
                    unsplit = True
                    continue
                stack[pending, 0], stack[pending, 1], stack[pending, 2] = cut + 1, end, depth + 1
                stack[pending + 1, 0], stack[pending + 1, 1] = first, cut
                stack[pending + 1, 2] = depth + 1
                pending += 2
            else:
                out_start[found], out_stop[found], out_chain[found] = first, end, chain[run]
                found += 1
    return Segments(out_start[:found], out_stop[:found], out_chain[:found]), unsplit


@jit
def moment_line(x_m, y_m, first, stop, range_sigma_m, bearing_sigma_rad):
    """
    Compiled twin of :func:`..numpy_core.segmentation.moment_fit` for one segment.

    Sums the returns at positions [first, stop) (modulo n) itself, where the twin takes the sums.

    :param x_m: x of the returns in circular order, shape (n,), m
    :param y_m: y of the returns in circular order, shape (n,), m
    :param first: first position
    :param stop: one past the last position (up to first + n)
    :param range_sigma_m: range noise std, m
    :param bearing_sigma_rad: bearing noise std, rad
    :return: (angle rad in (-pi, pi], radius m >= 0, Var(angle), Cov(angle, radius),
        Var(radius)); inf variances for returns all in one spot
    """
    n = x_m.size
    count = float(stop - first)
    sx = sy = sxx = syy = sxy = 0.0
    for k in range(first, stop):
        i = wrapped(k, n)
        x, y = x_m[i], y_m[i]
        sx += x
        sy += y
        sxx += x * x
        syy += y * y
        sxy += x * y
    mx, my, mxx, myy, mxy = sx / count, sy / count, sxx / count, syy / count, sxy / count
    cxx, cyy, cxy = mxx - mx * mx, myy - my * my, mxy - mx * my
    normal = 0.5 * math.atan2(-2.0 * cxy, cyy - cxx)          # the minor axis
    c, s = math.cos(normal), math.sin(normal)
    radius = mx * c + my * s
    flip = math.copysign(1.0, radius)                         # the normal points to the line
    c *= flip
    s *= flip
    along = cxx * s * s + cyy * c * c - 2.0 * cxy * s * c     # variance along the line
    offset = my * c - mx * s
    scatter = range_sigma_m ** 2 + bearing_sigma_rad ** 2 * (mxx + myy)
    var_angle = scatter / (count * along)
    return (math.atan2(s, c), abs(radius), var_angle, offset * var_angle,
            scatter / count + offset * offset * var_angle)


@jit
def merge_segments(x_m, y_m, segments, circular, joinable, noise, chi2_threshold, max_passes):
    """
    Compiled twin of :func:`..numpy_core.segmentation.merge_collinear`.

    Each pass refits every segment from its returns with :func:`moment_line`.

    :param x_m: x of the returns in circular order, shape (n,), m
    :param y_m: y of the returns in circular order, shape (n,), m
    :param segments: the segments, sorted by start
    :param circular: whether the returns cover a full turn
    :param joinable: per position, whether a merge may cross the break before it, shape (n,)
    :param noise: the noise (merging decides with its deciding_sigma_m)
    :param chi2_threshold: merge below this squared Mahalanobis distance (0: never)
    :param max_passes: the most merging passes
    :return: (the merged segments, their fits' :class:`~.records.Lines`, whether the passes
        ran out)
    """
    n = x_m.size
    start, stop, chain = segments.start.copy(), segments.stop.copy(), segments.chain.copy()
    angle, radius = np.empty(start.size), np.empty(start.size)
    for passes in range(max_passes + 1):
        angle, radius, covariance = _merge_fits(x_m, y_m, start, stop, noise)
        if start.size < 2 or chi2_threshold <= 0.0:
            break
        distance, merged_stop, candidates = _merge_distances(
            angle, radius, covariance, start, stop, chain, n, circular, joinable, chi2_threshold)
        if candidates == 0:
            break
        if passes == max_passes:
            return Segments(start, stop, chain), Lines(angle, radius), True
        start, stop, chain = _merge_lowest_first(start, stop, chain, distance, merged_stop,
                                                 candidates)
    return Segments(start, stop, chain), Lines(angle, radius), False


@jit
def _merge_fits(x_m, y_m, start, stop, noise):
    """
    Return the moment fit of every segment: angle (S,) rad, radius (S,) m, covariance (S, 3).

    The covariance's columns are Var(angle), Cov(angle, radius), Var(radius); the fits decide
    with the deciding noise.
    """
    count = start.size
    angle, radius = np.empty(count), np.empty(count)
    covariance = np.empty((count, 3))
    for s in range(count):
        fit = moment_line(x_m, y_m, start[s], stop[s], noise.deciding_sigma_m,
                          noise.bearing_sigma_rad)
        angle[s], radius[s] = fit[0], fit[1]
        covariance[s, 0], covariance[s, 1], covariance[s, 2] = fit[2], fit[3], fit[4]
    return angle, radius, covariance


@jit
def _merge_distances(angle, radius, covariance, start, stop, chain, n, circular, joinable,
                     chi2_threshold):
    """
    Compiled twin of :func:`..numpy_core.segmentation._merge_distances`, one pair at a time.

    :return: (the squared Mahalanobis distance of each pair that may merge and passes, inf for
        the others, shape (S,); the stop of each pair merged, shape (S,); how many pass)
    """
    count = start.size
    distance = np.full(count, np.inf)
    merged_stop = np.empty(count, np.intp)
    candidates = 0
    for k in range(count):
        j = k + 1 if k + 1 < count else 0
        merged_stop[k] = stop[j] + (n if j == 0 else 0)
        touching = stop[k] % n == start[j] and joinable[start[j]]
        ok = (chain[k] == chain[j] or touching) and merged_stop[k] - start[k] <= n
        if j == 0 and (not circular or count < 3):
            ok = False                        # the last segment has no successor
        if not ok:
            continue
        # The squared Mahalanobis distance of the difference of the two lines.
        turn = (angle[k] - angle[j] + np.pi) % (2.0 * np.pi) - np.pi
        shift = radius[k] - radius[j]
        a = covariance[k, 0] + covariance[j, 0]
        b = covariance[k, 1] + covariance[j, 1]
        d = covariance[k, 2] + covariance[j, 2]
        chi2 = (d * turn * turn - 2.0 * b * turn * shift + a * shift * shift) / (a * d - b * b)
        if chi2 < chi2_threshold:
            distance[k] = chi2
            candidates += 1
    return distance, merged_stop, candidates


@jit
def _root(parent, label):
    """Compiled twin of :func:`..numpy_core.segmentation._root`, over an array of parents."""
    while parent[label] != label:
        label = parent[label]
    return label


@jit
def _merge_lowest_first(start, stop, chain, distance, merged_stop, candidates):
    """
    Compiled twin of :func:`..numpy_core.segmentation._merge_lowest_first`.

    :return: the merged segments' start, stop and chain, shape (S',) each
    """
    count = start.size
    start, stop = start.copy(), stop.copy()
    used = np.zeros(count, np.bool_)
    labels = 1
    for s in range(count):
        labels = max(labels, chain[s] + 1)
    parent = np.arange(labels)
    kept = count
    lowest_first = stable_order(distance)
    for rank in range(candidates):
        k = lowest_first[rank]
        j = k + 1 if k + 1 < count else 0
        if used[k] or used[j]:
            continue
        used[k] = used[j] = True
        stop[k] = merged_stop[k]
        start[j] = -1                         # absorbed into k
        kept -= 1
        into, other = _root(parent, chain[k]), _root(parent, chain[j])
        if into != other:
            parent[other] = into
    new_start, new_stop = np.empty(kept, np.intp), np.empty(kept, np.intp)
    new_chain = np.empty(kept, np.intp)
    out = 0
    for s in range(count):
        if start[s] >= 0:
            new_start[out], new_stop[out] = start[s], stop[s]
            new_chain[out] = _root(parent, chain[s])
            out += 1
    return new_start, new_stop, new_chain


@jit
def _within(start, stop, n):
    """Bring segments that start past the contour's end back into [0, n) (in place)."""
    for s in range(start.size):
        if start[s] >= n:
            start[s] -= n
            stop[s] -= n


@jit
def trim_ambiguous(segments, circular, x_m, y_m, lines, noise, min_returns, window):
    """
    Compiled twin of :func:`..numpy_core.segmentation.trim_ambiguous`, one meeting end at a time.

    :param segments: the segments, sorted by start (stop modulo n)
    :param circular: whether the returns cover a full turn (the last and first can meet)
    :param x_m: x of the returns in circular order, shape (n,), m
    :param y_m: y of the returns in circular order, shape (n,), m
    :param lines: each segment's line
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param min_returns: never trim a segment below this many returns
    :param window: most returns examined at each end
    :return: the trimmed segments
    """
    start, stop, chain = segments.start, segments.stop, segments.chain
    angle_rad, radius_m = lines.angle_rad, lines.radius_m
    range_sigma_m, bearing_sigma_rad = noise.deciding_sigma_m, noise.bearing_sigma_rad
    n, count = x_m.size, start.size
    if count < 2:
        return segments
    meets = np.empty(count, np.bool_)
    for k in range(count):
        j = k + 1 if k + 1 < count else 0
        meets[k] = (start[j] - stop[k]) % n <= 1
    meets[count - 1] = meets[count - 1] and circular and count > 2
    room = np.maximum(stop - start - min_returns, 0)
    cut_end = np.zeros(count, np.intp)
    cut_start = np.zeros(count, np.intp)
    for k in range(count):
        if not meets[k]:
            continue
        j = k + 1 if k + 1 < count else 0
        cos_k, sin_k = math.cos(angle_rad[k]), math.sin(angle_rad[k])
        cos_j, sin_j = math.cos(angle_rad[j]), math.sin(angle_rad[j])
        sine = sin_j * cos_k - cos_j * sin_k                  # sin(angle_j - angle_k)
        corner_x = (radius_m[k] * sin_j - radius_m[j] * sin_k) / sine
        corner_y = (radius_m[j] * cos_k - radius_m[k] * cos_j) / sine
        reach2 = 9.0 * (range_sigma_m ** 2 + (corner_x * corner_x + corner_y * corner_y)
                        * bearing_sigma_rad ** 2) / (sine * sine)
        for side in range(2):       # back from the end of k, then forward from the start of j
            run = 0
            while run < window:
                i = (stop[k] - 1 - run if side == 0 else start[j] + run) % n
                dx, dy = x_m[i] - corner_x, y_m[i] - corner_y
                if not dx * dx + dy * dy < reach2:
                    break
                run += 1
            if side == 0:
                cut_end[k] = run
            else:
                cut_start[j] = run
    new_start, new_stop = start.copy(), stop.copy()
    for k in range(count):
        both = meets[k] and meets[k - 1]          # meets[-1] is the last's, across the seam
        allowance = room[k] // 2 if both else room[k]
        new_stop[k] -= min(cut_end[k], allowance)
        new_start[k] += min(cut_start[k], allowance)
    _within(new_start, new_stop, n)
    return Segments(new_start, new_stop, chain)


@jit
def trim_offset(segments, x_m, y_m, lines, noise, min_returns, threshold_sigmas, window):
    """
    Compiled twin of :func:`..numpy_core.segmentation.trim_offset`, one segment end at a time.

    :param segments: the segments, sorted by start (stop modulo n)
    :param x_m: x of the returns in circular order, shape (n,), m
    :param y_m: y of the returns in circular order, shape (n,), m
    :param lines: each segment's line (the frame)
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param min_returns: never trim a segment below this many returns
    :param threshold_sigmas: cut where max_k |Z_k| / sqrt(Var(Z_k)) exceeds this
    :param window: most returns examined at each end
    :return: the trimmed segments
    """
    start, stop, chain = segments.start, segments.stop, segments.chain
    angle_rad, radius_m = lines.angle_rad, lines.radius_m
    range_sigma_m, bearing_sigma_rad = noise.deciding_sigma_m, noise.bearing_sigma_rad
    n, count = x_m.size, start.size
    new_start, new_stop = start.copy(), stop.copy()
    limit = threshold_sigmas * threshold_sigmas
    for s in range(count):
        reach = min((stop[s] - start[s] - min_returns) // 2, window)
        if reach <= 0:
            continue
        c, sn = math.cos(angle_rad[s]), math.sin(angle_rad[s])
        # Sums over the whole segment of t, t^2, e, t e and rho^2.
        whole_t = whole_tt = whole_e = whole_te = whole_rr = 0.0
        for p in range(start[s], stop[s]):
            i = wrapped(p, n)
            x, y = x_m[i], y_m[i]
            t, e = y * c - x * sn, x * c + y * sn - radius_m[s]
            whole_t += t
            whole_tt += t * t
            whole_e += e
            whole_te += t * e
            whole_rr += x * x + y * y
        for side in range(2):             # back from the end, then forward from the start
            rest_t, rest_tt, rest_e, rest_te, rest_rr = (whole_t, whole_tt, whole_e, whole_te,
                                                         whole_rr)
            sum_z = sum_w = sum_tw = 0.0  # of e / sigma, 1 / sigma, t / sigma over the k
            best, cut = -1.0, 0
            for k in range(1, reach + 1):
                i = wrapped(stop[s] - k if side == 0 else start[s] + k - 1, n)
                x, y = x_m[i], y_m[i]
                t, e = y * c - x * sn, x * c + y * sn - radius_m[s]
                rest_t -= t
                rest_tt -= t * t
                rest_e -= e
                rest_te -= t * e
                rest_rr -= x * x + y * y
                weight = 1.0 / math.sqrt(range_sigma_m ** 2
                                         + (x * x + y * y) * bearing_sigma_rad ** 2)
                sum_z += e * weight
                sum_w += weight
                sum_tw += t * weight
                m = float(stop[s] - start[s] - k)
                mean_t, mean_e = rest_t / m, rest_e / m
                spread = rest_tt - m * mean_t * mean_t                      # S_tt
                if not spread > 0.0:          # the other returns at one point: no line
                    break
                slope = (rest_te - m * mean_t * mean_e) / spread
                lever = sum_tw - mean_t * sum_w                             # T - t_m W
                total = sum_z - mean_e * sum_w - slope * lever
                scatter = range_sigma_m ** 2 + bearing_sigma_rad ** 2 * rest_rr / m
                variance = k + scatter * (sum_w * sum_w / m + lever * lever / spread)
                score = total * total / variance
                if score > best:
                    best, cut = score, k
            if best > limit:                     # NaN (a NaN line) compares False: no cut
                if side == 0:
                    new_stop[s] -= cut
                else:
                    new_start[s] += cut
    _within(new_start, new_stop, n)
    return Segments(new_start, new_stop, chain)
