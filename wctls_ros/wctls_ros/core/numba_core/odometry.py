# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The odometry's hypotheses, search and fit compiled: the pairs' steps, scoring, refinements.

The compiled twin of the steps of the landmark pairs (``corner_hypotheses``,
``line_hypotheses``, ``corner_line_hypotheses``), of ``_search`` and of ``fit`` of
:mod:`wctls_ros.frontend.odometry`, whose numpy steps stay the specification
(docs/odometry.md#hypotheses, #the-fit). :func:`hypotheses` is one call per pair of scans;
:func:`search` one call per hypothesis set: the chi-squares of every corner and line pair
under every hypothesis in the search's gate (a line pair's segments tested for overlap where
inside the gate), the scores, and the refinements of the best few, each associated (one to
one, nearest first), fitted and associated again, twice, and ranked. :func:`fit` is the fit of
one association. The numpy steps pay numpy's cost per call thousands of times per scan; here
each step is a loop, and a loop over pairs visits only those an angle can bring inside a gate
(the lines sorted by angle; a chi-square outside the gate is inf, its only use being whether
a pair lies inside).

The hypotheses and the chi-squares take the numpy twin's operations in its order (the same
hypotheses in the same order, the same gate decisions, the same scores). The fit's sums are
taken in the order of the pairs, and its 3x3 systems solved by elimination with partial
pivoting (numpy's matrix products and LAPACK's solve round otherwise): a fit of a single line
pair, a singular system whose outcome is rounding noise, may then end elsewhere; the tests
hold both to the same statuses, counts and trajectories within a stated tolerance.

A scan's landmarks are given as their arrays (corner xy (C, 2), covariances (C, 2, 2), lines
(L, 2), covariances (L, 2, 2), ends (L, 2, 2)); pairs as (previous index, current index) rows
of an (K, 2) integer array.
"""
import math

import numpy as np

from ._jit import jit
from ._order import sorted_copy, stable_order

# The numpy twin's constants (wctls_ros.frontend.odometry), which the compiled code cannot
# import (the frontend imports no compiled code); the tests hold both to the same results.
CHI2_1DOF_99 = 6.635
CHI2_2DOF_99 = 9.210
MIN_PAIR_DISTANCE_M = 0.3
MIN_PAIR_ANGLE_RAD = math.radians(20.0)
SEARCH_SLACK_M = 0.05
SEARCH_SLACK_RAD = math.radians(2.0)
FIT_ITERATIONS = 6
REFINED_HYPOTHESES = 6
ENOUGH_SHARE = 0.9
PRIOR_PAIR_CHI2 = 16.27
# A pair whose first error alone lies this far beyond the gate (e0^2 / S00 bounds e^T S^-1 e
# from below) is outside it: inf, without the quadratic form. The margin covers rounding.
_OUTSIDE = CHI2_2DOF_99 * (1.0 + 1e-9)


@jit
def _wrap(angle):
    """
    Compiled twin of ``frames.wrap_angle``: an angle into (-pi, pi], rad.

    pi - mod(pi - angle, 2 pi), the modulo skipped where it is the identity (pi - angle
    already in [0, 2 pi)): the same rounding, without a division for most angles.
    """
    turned = np.pi - angle
    if 0.0 <= turned < 2 * np.pi:
        return np.pi - turned
    return np.pi - np.mod(turned, 2 * np.pi)


@jit
def _grown(out, count):
    """Return ``out`` (N, 3) with room for one more row after ``count`` (doubled when full)."""
    if count < out.shape[0]:
        return out
    grown = np.empty((2 * out.shape[0], 3))
    grown[:count] = out[:count]
    return grown


@jit
def _pair_spread(xy, cov, a, b):
    """Return the vector a -> b between two corners, its length, and its variance along it."""
    dx, dy = xy[b, 0] - xy[a, 0], xy[b, 1] - xy[a, 1]
    length = np.hypot(dx, dy)
    ux, uy = dx / max(length, 1e-12), dy / max(length, 1e-12)
    s = cov[a] + cov[b]
    var = ux * s[0, 0] * ux + ux * s[0, 1] * uy + uy * s[1, 0] * ux + uy * s[1, 1] * uy
    return dx, dy, length, var


@jit
def corner_hypotheses(prev_xy, prev_cov, cur_xy, cur_cov):
    """
    Compiled twin of ``corner_hypotheses``: the steps of two corners seen in both scans.

    The pairs i < j of the previous scan against the ordered pairs k != l of the current one,
    in numpy's order (row-major), gated on their distances.

    :return: steps (dx m, dy m, dyaw rad), shape (H, 3)
    """
    previous, current = prev_xy.shape[0], cur_xy.shape[0]
    if previous < 2 or current < 2:
        return np.zeros((0, 3))
    spread_cur = np.empty((current * (current - 1), 6))
    k = 0
    for a in range(current):
        for b in range(current):
            if a != b:
                dx, dy, length, var = _pair_spread(cur_xy, cur_cov, a, b)
                spread_cur[k, 0], spread_cur[k, 1], spread_cur[k, 2] = dx, dy, length
                spread_cur[k, 3], spread_cur[k, 4], spread_cur[k, 5] = var, a, b
                k += 1
    out = np.empty((16, 3))
    count = 0
    for i in range(previous):
        for j in range(i + 1, previous):
            dx, dy, length, var = _pair_spread(prev_xy, prev_cov, i, j)
            if not length >= MIN_PAIR_DISTANCE_M:
                continue
            for k in range(spread_cur.shape[0]):
                other = spread_cur[k]
                if not (other[2] >= MIN_PAIR_DISTANCE_M and (length - other[2]) ** 2
                        <= CHI2_1DOF_99 * (var + other[3])):
                    continue
                out = _grown(out, count)
                yaw = _wrap(np.arctan2(dy, dx) - np.arctan2(other[1], other[0]))
                c, m = int(other[4]), int(other[5])
                mid_x = 0.5 * (cur_xy[c, 0] + cur_xy[m, 0])
                mid_y = 0.5 * (cur_xy[c, 1] + cur_xy[m, 1])
                cos, sin = np.cos(yaw), np.sin(yaw)
                out[count, 0] = 0.5 * (prev_xy[i, 0] + prev_xy[j, 0]) - (cos * mid_x - sin * mid_y)
                out[count, 1] = 0.5 * (prev_xy[i, 1] + prev_xy[j, 1]) - (sin * mid_x + cos * mid_y)
                out[count, 2] = yaw
                count += 1
    return out[:count].copy()


@jit
def _within(ordered, order, angle, reach, out):
    """
    Write into ``out`` the indices (unordered) of the angles within ``reach`` of ``angle``, rad.

    :param ordered: the angles sorted, in (-pi, pi]
    :param order: their indices (ordered = angles[order])
    :return: how many were written
    """
    if reach >= np.pi:
        for k in range(order.size):
            out[k] = order[k]
        return order.size
    count = 0
    for low, high, needed in ((angle - reach, angle + reach, True),
                              (angle - reach + 2 * np.pi, np.inf, angle - reach < -np.pi),
                              (-np.inf, angle + reach - 2 * np.pi, angle + reach > np.pi)):
        if not needed:
            continue
        for k in range(np.searchsorted(ordered, low, side='left'),
                       np.searchsorted(ordered, high, side='right')):
            out[count] = order[k]
            count += 1
    return count


@jit
def line_hypotheses(prev_line, prev_line_cov, cur_line, cur_line_cov):
    """
    Compiled twin of ``line_hypotheses``: the steps of two lines seen in both scans.

    The pairs i < j of the previous scan against the ordered pairs k != l of the current one,
    in numpy's order, gated on the angles between their normals (never flipped).

    :return: steps (dx m, dy m, dyaw rad), shape (H, 3), the finite ones
    """
    previous, current = prev_line.shape[0], cur_line.shape[0]
    if previous < 2 or current < 2:
        return np.zeros((0, 3))
    least = np.sin(MIN_PAIR_ANGLE_RAD)
    # The current scan's pairs not close to parallel, in order: the only ones a pair can take.
    between_cur = np.empty((current * (current - 1), 4))
    k = 0
    for a in range(current):
        for b in range(current):
            angle = _wrap(cur_line[b, 0] - cur_line[a, 0])
            if a != b and abs(np.sin(angle)) >= least:
                between_cur[k, 0] = angle
                between_cur[k, 1] = cur_line_cov[a, 0, 0] + cur_line_cov[b, 0, 0]
                between_cur[k, 2], between_cur[k, 3] = a, b
                k += 1
    between_cur = between_cur[:k]
    # Sorted by angle, so that a previous pair visits only those within its widest gate.
    order = stable_order(between_cur[:, 0])
    ordered = between_cur[:, 0][order]
    widest = between_cur[:, 1].max() if k else 0.0
    candidates = np.empty(k)
    out = np.empty((16, 3))
    count = 0
    for i in range(previous):
        for j in range(i + 1, previous):
            angle = _wrap(prev_line[j, 0] - prev_line[i, 0])
            var = prev_line_cov[i, 0, 0] + prev_line_cov[j, 0, 0]
            if not abs(np.sin(angle)) >= least:
                continue
            a1, b1 = np.cos(prev_line[i, 0]), np.sin(prev_line[i, 0])
            a2, b2 = np.cos(prev_line[j, 0]), np.sin(prev_line[j, 0])
            det = a1 * b2 - a2 * b1
            found = _within(ordered, order, angle,
                            np.sqrt(CHI2_1DOF_99 * (var + widest)) * (1.0 + 1e-9) + 1e-12,
                            candidates)
            for k in sorted_copy(candidates[:found]):
                other = between_cur[int(k)]
                if not _wrap(angle - other[0]) ** 2 <= CHI2_1DOF_99 * (var + other[1]):
                    continue
                c, m = int(other[2]), int(other[3])
                r1 = prev_line[i, 1] - cur_line[c, 1]
                r2 = prev_line[j, 1] - cur_line[m, 1]
                dx, dy = (r1 * b2 - r2 * b1) / det, (a1 * r2 - a2 * r1) / det
                yaw = _wrap(prev_line[i, 0] - cur_line[c, 0])
                if np.isfinite(dx) and np.isfinite(dy) and np.isfinite(yaw):
                    out = _grown(out, count)
                    out[count, 0], out[count, 1], out[count, 2] = dx, dy, yaw
                    count += 1
    return out[:count].copy()


@jit
def _corner_line_distances(xy, cov, line, line_cov):
    """Return every corner's signed distance from every line and its variance, (C L, 2)."""
    out = np.empty((xy.shape[0] * line.shape[0], 2))
    for c in range(xy.shape[0]):
        for m in range(line.shape[0]):
            nx, ny = np.cos(line[m, 0]), np.sin(line[m, 0])
            lever = -xy[c, 0] * ny + xy[c, 1] * nx
            s, q = cov[c], line_cov[m]
            out[c * line.shape[0] + m, 0] = xy[c, 0] * nx + xy[c, 1] * ny - line[m, 1]
            out[c * line.shape[0] + m, 1] = (
                nx * s[0, 0] * nx + nx * s[0, 1] * ny + ny * s[1, 0] * nx + ny * s[1, 1] * ny
                + lever ** 2 * q[0, 0] - 2.0 * lever * q[0, 1] + q[1, 1])
    return out


@jit
def corner_line_hypotheses(prev_xy, prev_cov, prev_line, prev_line_cov, cur_xy, cur_cov,
                           cur_line, cur_line_cov):
    """
    Compiled twin of ``corner_line_hypotheses``: the steps of a corner and a line in both scans.

    Every (corner, line) of the previous scan against every one of the current scan, in numpy's
    order, gated on the corner's signed distance from the line.

    :return: steps (dx m, dy m, dyaw rad), shape (H, 3)
    """
    if not (prev_xy.shape[0] and prev_line.shape[0] and cur_xy.shape[0]
            and cur_line.shape[0]):
        return np.zeros((0, 3))
    before = _corner_line_distances(prev_xy, prev_cov, prev_line, prev_line_cov)
    after = _corner_line_distances(cur_xy, cur_cov, cur_line, cur_line_cov)
    out = np.empty((16, 3))
    count = 0
    for p in range(before.shape[0]):
        for c in range(after.shape[0]):
            if not ((before[p, 0] - after[c, 0]) ** 2
                    <= CHI2_1DOF_99 * (before[p, 1] + after[c, 1])):
                continue
            corner_p, line_p = p // prev_line.shape[0], p % prev_line.shape[0]
            corner_c, line_c = c // cur_line.shape[0], c % cur_line.shape[0]
            yaw = _wrap(prev_line[line_p, 0] - cur_line[line_c, 0])
            cos, sin = np.cos(yaw), np.sin(yaw)
            qx, qy = cur_xy[corner_c, 0], cur_xy[corner_c, 1]
            out = _grown(out, count)
            out[count, 0] = prev_xy[corner_p, 0] - (cos * qx - sin * qy)
            out[count, 1] = prev_xy[corner_p, 1] - (sin * qx + cos * qy)
            out[count, 2] = yaw
            count += 1
    return out[:count].copy()


@jit
def hypotheses(prev_xy, prev_cov, prev_line, prev_line_cov, cur_xy, cur_cov, cur_line,
               cur_line_cov):
    """Return the steps of the corner pairs, the line pairs and the corner-line pairs, (H, 3)."""
    corners = corner_hypotheses(prev_xy, prev_cov, cur_xy, cur_cov)
    lines = line_hypotheses(prev_line, prev_line_cov, cur_line, cur_line_cov)
    mixed = corner_line_hypotheses(prev_xy, prev_cov, prev_line, prev_line_cov, cur_xy,
                                   cur_cov, cur_line, cur_line_cov)
    out = np.empty((corners.shape[0] + lines.shape[0] + mixed.shape[0], 3))
    out[:corners.shape[0]] = corners
    out[corners.shape[0]:corners.shape[0] + lines.shape[0]] = lines
    out[corners.shape[0] + lines.shape[0]:] = mixed
    return out


@jit
def _quadratic(error_0, error_1, s00, s01, s10, s11):
    """Compiled twin of ``_quadratic_2x2``: e^T S^-1 e, inf where S is not positive definite."""
    det = s00 * s11 - s01 * s10
    form = s11 * error_0 * error_0 - (s01 + s10) * error_0 * error_1 + s00 * error_1 * error_1
    return form / det if det > 0.0 else np.inf


@jit
def _keep(chi2, h, p, c, best, value):
    """Store a pair's chi2 in ``chi2``, or with ``best`` the least over the previous ones."""
    if best:
        chi2[h, 0, c] = min(chi2[h, 0, c], value)
    else:
        chi2[h, p, c] = value


@jit
def _corner_chi2(prev_xy, prev_cov, cur_xy, cur_cov, steps, slack, best):
    """
    Compiled twin of ``_corner_chi2``: every corner pair's chi2 under each step, (H, P, C).

    Those outside the gate are inf (its only use is whether a pair lies inside). With ``best``
    only the least over the previous corners, (H, 1, C): all the scores read.
    """
    count, previous, current = steps.shape[0], prev_xy.shape[0], cur_xy.shape[0]
    chi2 = np.full((count, min(previous, 1) if best else previous, current), np.inf)
    for h in range(count):
        cos, sin = np.cos(steps[h, 2]), np.sin(steps[h, 2])
        for c in range(current):
            x, y = cur_xy[c, 0], cur_xy[c, 1]
            moved_x = steps[h, 0] + cos * x - sin * y
            moved_y = steps[h, 1] + sin * x + cos * y
            cov = cur_cov[c]
            rc00, rc01 = cos * cov[0, 0] - sin * cov[1, 0], cos * cov[0, 1] - sin * cov[1, 1]
            rc10, rc11 = sin * cov[0, 0] + cos * cov[1, 0], sin * cov[0, 1] + cos * cov[1, 1]
            m00 = rc00 * cos - rc01 * sin + slack
            m01 = rc00 * sin + rc01 * cos
            m10 = rc10 * cos - rc11 * sin
            m11 = rc10 * sin + rc11 * cos + slack
            for p in range(previous):
                prev = prev_cov[p]
                error_x = prev_xy[p, 0] - moved_x
                s00 = prev[0, 0] + m00
                if error_x * error_x > _OUTSIDE * s00:
                    continue
                _keep(chi2, h, p, c, best,
                      _quadratic(error_x, prev_xy[p, 1] - moved_y, s00, prev[0, 1] + m01,
                                 prev[1, 0] + m10, prev[1, 1] + m11))
    return chi2


@jit
def _overlap(ax, ay, bx, by, other):
    """Compiled twin of ``frames.overlapping`` for one segment a-b and one stretch of wall."""
    dx, dy = bx - ax, by - ay
    norm = max(np.sqrt(dx * dx + dy * dy), 1e-12)
    dx, dy = dx / norm, dy / norm
    own_0, own_1 = ax * dx + ay * dy, bx * dx + by * dy
    other_0 = other[0, 0] * dx + other[0, 1] * dy
    other_1 = other[1, 0] * dx + other[1, 1] * dy
    return (min(max(own_0, own_1), max(other_0, other_1))
            > max(min(own_0, own_1), min(other_0, other_1)))


@jit
def _line_chi2(prev_line, prev_cov, prev_ends, cur_line, cur_cov, cur_ends, steps, slack_rad,
               slack_m, best):
    """
    Compiled twin of ``_line_chi2``: every line pair's chi2 under each step, (H, P, C).

    A pair inside the 99 % gate whose segments do not overlap along the line is inf; so are
    those outside the gate. With ``best`` only the least over the previous lines, (H, 1, C).
    Each moved line visits only the previous lines whose angle lies within the widest gate of
    its angle error (the previous lines sorted by angle).
    """
    count, previous, current = steps.shape[0], prev_line.shape[0], cur_line.shape[0]
    chi2 = np.full((count, min(previous, 1) if best else previous, current), np.inf)
    angles = np.empty(previous)
    for p in range(previous):
        angles[p] = _wrap(prev_line[p, 0])
    order = stable_order(angles)
    ordered = angles[order]
    widest = prev_cov[:, 0, 0].max() if previous else 0.0
    candidates = np.empty(previous)
    for h in range(count):
        cos_h, sin_h = np.cos(steps[h, 2]), np.sin(steps[h, 2])
        for c in range(current):
            angle = cur_line[c, 0] + steps[h, 2]
            cos, sin = np.cos(angle), np.sin(angle)
            lever = -steps[h, 0] * sin + steps[h, 1] * cos
            radius = cur_line[c, 1] + steps[h, 0] * cos + steps[h, 1] * sin
            cov = cur_cov[c]
            jc10 = lever * cov[0, 0] + cov[1, 0]
            jc11 = lever * cov[0, 1] + cov[1, 1]
            m00 = cov[0, 0] + slack_rad
            m01 = cov[0, 0] * lever + cov[0, 1]
            m11 = jc10 * lever + jc11 + slack_m
            ends = cur_ends[c]
            ax = steps[h, 0] + cos_h * ends[0, 0] - sin_h * ends[0, 1]
            ay = steps[h, 1] + sin_h * ends[0, 0] + cos_h * ends[0, 1]
            bx = steps[h, 0] + cos_h * ends[1, 0] - sin_h * ends[1, 1]
            by = steps[h, 1] + sin_h * ends[1, 0] + cos_h * ends[1, 1]
            found = _within(ordered, order, _wrap(angle),
                            np.sqrt(_OUTSIDE * (widest + m00)) * (1.0 + 1e-9) + 1e-12,
                            candidates)
            for k in range(found):
                p = int(candidates[k])
                prev = prev_cov[p]
                error_angle = _wrap(angle - prev_line[p, 0])
                s00 = prev[0, 0] + m00
                if error_angle * error_angle > _OUTSIDE * s00:
                    continue
                value = _quadratic(error_angle, radius - prev_line[p, 1], s00, prev[0, 1] + m01,
                                   prev[1, 0] + jc10, prev[1, 1] + m11)
                if value <= CHI2_2DOF_99 and not _overlap(ax, ay, bx, by, prev_ends[p]):
                    value = np.inf
                _keep(chi2, h, p, c, best, value)
    return chi2


@jit
def _pairwise_sum(values):
    """Return a row's sum as numpy's ``sum`` along a contiguous axis takes it (pairwise)."""
    n = values.size
    if n < 8:
        total = 0.0
        for k in range(n):
            total += values[k]
        return total
    if n <= 128:
        r = values[:8].copy()
        k = 8
        while k < n - n % 8:
            for j in range(8):
                r[j] += values[k + j]
            k += 8
        total = (r[0] + r[1] + (r[2] + r[3])) + (r[4] + r[5] + (r[6] + r[7]))
        while k < n:
            total += values[k]
            k += 1
        return total
    half = n // 2
    half -= half % 8
    return _pairwise_sum(values[:half]) + _pairwise_sum(values[half:])


@jit
def _scores(chi2, total):
    """Add to ``total`` (H,) ``score_hypotheses``'s part of one kind's chi2 (H, P, C)."""
    count, previous, current = chi2.shape
    if previous == 0 or current == 0:
        return
    taken = np.empty(current)
    for h in range(count):
        inside = 0
        for c in range(current):
            best = chi2[h, 0, c]
            for p in range(1, previous):
                best = min(best, chi2[h, p, c])
            taken[c] = best if best <= CHI2_2DOF_99 else 0.0
            inside += best <= CHI2_2DOF_99
        total[h] += inside - _pairwise_sum(taken) / (CHI2_2DOF_99 * (1.0 + inside))


@jit
def _one_to_one(chi2):
    """
    Compiled twin of ``_one_to_one``: pairs (K, 2) inside the gate, best first, each once.

    :return: (the pairs, the sum of their chi2)
    """
    previous, current = chi2.shape
    gated = 0
    for p in range(previous):
        for c in range(current):
            gated += chi2[p, c] <= CHI2_2DOF_99
    rows, values = np.empty((gated, 2), np.int64), np.empty(gated)
    k = 0
    for p in range(previous):
        for c in range(current):
            if chi2[p, c] <= CHI2_2DOF_99:
                rows[k, 0], rows[k, 1], values[k] = p, c, chi2[p, c]
                k += 1
    taken_p, taken_c = np.zeros(previous, np.bool_), np.zeros(current, np.bool_)
    out, total, count = np.empty((min(previous, current), 2), np.int64), 0.0, 0
    for k in stable_order(values):
        p, c = rows[k, 0], rows[k, 1]
        if not taken_p[p] and not taken_c[c]:
            taken_p[p] = taken_c[c] = True
            out[count, 0], out[count, 1] = p, c
            total += values[k]
            count += 1
    return out[:count].copy(), total


@jit
def _associate(prev_xy, prev_cov, prev_line, prev_line_cov, prev_ends, cur_xy, cur_cov,
               cur_line, cur_line_cov, cur_ends, step):
    """Compiled twin of ``_associate`` in the unwidened gate: corner, line pairs, chi2 sum."""
    steps = step.reshape(1, 3)
    corners, corner_chi2 = _one_to_one(_corner_chi2(prev_xy, prev_cov, cur_xy, cur_cov, steps,
                                                    0.0, False)[0])
    lines, line_chi2 = _one_to_one(_line_chi2(prev_line, prev_line_cov, prev_ends, cur_line,
                                              cur_line_cov, cur_ends, steps, 0.0, 0.0, False)[0])
    return corners, lines, corner_chi2 + line_chi2


@jit
def _normal_equations(prev_xy, prev_cov, prev_line, prev_line_cov, cur_xy, cur_cov, cur_line,
                      cur_line_cov, corners, lines, step):
    """
    Compiled twin of ``_normal_equations``: J^T S^-1 J (3, 3), J^T S^-1 e (3,), e^T S^-1 e.

    Corners: e = p - (R q + t), S = C_p + R C_q R^T; lines: the current line moved into the
    previous frame minus the previous line, S = C_p + J C_c J^T (docs/odometry.md#the-fit).
    """
    information, gradient, chi2 = np.zeros((3, 3)), np.zeros(3), 0.0
    cos, sin = math.cos(step[2]), math.sin(step[2])
    jac, error, cov = np.zeros((2, 3)), np.empty(2), np.empty((2, 2))
    for k in range(corners.shape[0] + lines.shape[0]):
        jac[:] = 0.0
        if k < corners.shape[0]:
            p, c = corners[k, 0], corners[k, 1]
            qx, qy = cur_xy[c, 0], cur_xy[c, 1]
            error[0] = prev_xy[p, 0] - (qx * cos - qy * sin + step[0])
            error[1] = prev_xy[p, 1] - (qx * sin + qy * cos + step[1])
            jac[0, 0] = jac[1, 1] = -1.0
            jac[0, 2] = sin * qx + cos * qy
            jac[1, 2] = -cos * qx + sin * qy
            # R C_q R^T.
            q = cur_cov[c]
            a00, a01 = cos * q[0, 0] - sin * q[1, 0], cos * q[0, 1] - sin * q[1, 1]
            a10, a11 = sin * q[0, 0] + cos * q[1, 0], sin * q[0, 1] + cos * q[1, 1]
            cov[0, 0] = prev_cov[p, 0, 0] + (a00 * cos - a01 * sin)
            cov[0, 1] = prev_cov[p, 0, 1] + (a00 * sin + a01 * cos)
            cov[1, 0] = prev_cov[p, 1, 0] + (a10 * cos - a11 * sin)
            cov[1, 1] = prev_cov[p, 1, 1] + (a10 * sin + a11 * cos)
        else:
            p, c = lines[k - corners.shape[0], 0], lines[k - corners.shape[0], 1]
            angle = cur_line[c, 0] + step[2]
            cos_n, sin_n = np.cos(angle), np.sin(angle)
            lever = -step[0] * sin_n + step[1] * cos_n
            error[0] = _wrap(angle - prev_line[p, 0])
            error[1] = cur_line[c, 1] + step[0] * cos_n + step[1] * sin_n - prev_line[p, 1]
            jac[0, 2] = 1.0
            jac[1, 0], jac[1, 1], jac[1, 2] = cos_n, sin_n, lever
            # J C_c J^T, J = [[1, 0], [lever, 1]].
            q = cur_line_cov[c]
            cov[0, 0] = prev_line_cov[p, 0, 0] + q[0, 0]
            cov[0, 1] = prev_line_cov[p, 0, 1] + (q[0, 0] * lever + q[0, 1])
            cov[1, 0] = prev_line_cov[p, 1, 0] + (lever * q[0, 0] + q[1, 0])
            cov[1, 1] = prev_line_cov[p, 1, 1] + (
                (lever * q[0, 0] + q[1, 0]) * lever + (lever * q[0, 1] + q[1, 1]))
        # S^-1 by the closed form (a singular S: inf, as ``_inverse_2x2``).
        det = cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[1, 0]
        w00, w01, w10, w11 = cov[1, 1] / det, -cov[0, 1] / det, -cov[1, 0] / det, cov[0, 0] / det
        w00 = w00 if np.isfinite(w00) else np.inf
        w01 = w01 if np.isfinite(w01) else np.inf
        w10 = w10 if np.isfinite(w10) else np.inf
        w11 = w11 if np.isfinite(w11) else np.inf
        we0 = w00 * error[0] + w01 * error[1]
        we1 = w10 * error[0] + w11 * error[1]
        chi2 += error[0] * we0 + error[1] * we1
        for a in range(3):
            wj0 = w00 * jac[0, a] + w10 * jac[1, a]
            wj1 = w01 * jac[0, a] + w11 * jac[1, a]
            gradient[a] += wj0 * error[0] + wj1 * error[1]
            for b in range(3):
                information[a, b] += wj0 * jac[0, b] + wj1 * jac[1, b]
    return information, gradient, chi2


@jit
def _times(matrix, vector):
    """Return matrix @ vector of a 3x3 matrix, summed in order (numba's @ would need BLAS)."""
    out = np.zeros(3)
    for row in range(3):
        for k in range(3):
            out[row] += matrix[row, k] * vector[k]
    return out


@jit
def _solve_3x3(matrix, vector):
    """
    Return matrix^-1 vector by elimination with partial pivoting, or NaN when singular.

    A zero pivot is where numpy's solve raises (LinAlgError); the caller stops there.
    """
    a, b = matrix.copy(), vector.copy()
    for col in range(3):
        pivot = col
        for row in range(col + 1, 3):
            if abs(a[row, col]) > abs(a[pivot, col]):
                pivot = row
        if a[pivot, col] == 0.0:
            return np.full(3, np.nan)
        for k in range(3):
            a[col, k], a[pivot, k] = a[pivot, k], a[col, k]
        b[col], b[pivot] = b[pivot], b[col]
        for row in range(col + 1, 3):
            factor = a[row, col] / a[col, col]
            for k in range(col, 3):
                a[row, k] -= factor * a[col, k]
            b[row] -= factor * b[col]
    out = np.empty(3)
    for row in range(2, -1, -1):
        value = b[row]
        for k in range(row + 1, 3):
            value -= a[row, k] * out[k]
        out[row] = value / a[row, row]
    return out


@jit
def fit(prev_xy, prev_cov, prev_line, prev_line_cov, cur_xy, cur_cov, cur_line, cur_line_cov,
        corners, lines, start, prior_step, prior_information, with_prior):
    """
    Compiled twin of ``odometry.fit``: the weighted least-squares step by Gauss-Newton.

    :param corners: corner pairs (Kc, 2), int
    :param lines: line pairs (Kl, 2), int
    :param start: the first step (dx m, dy m, dyaw rad)
    :param prior_step: the prior's step (read with ``with_prior``)
    :param prior_information: its inverse covariance (3, 3) (read with ``with_prior``)
    :param with_prior: whether the prior is one more measurement
    :return: (step, the landmarks' information (3, 3) without the prior, chi2 of the landmarks)
    """
    step = start.copy()
    joined = prior_information if with_prior else np.zeros((3, 3))
    for _ in range(FIT_ITERATIONS):
        information, gradient, _ = _normal_equations(
            prev_xy, prev_cov, prev_line, prev_line_cov, cur_xy, cur_cov, cur_line,
            cur_line_cov, corners, lines, step)
        if with_prior:
            difference = step - prior_step
            difference[2] = _wrap(difference[2])
            gradient = gradient + _times(joined, difference)
        update = -_solve_3x3(information + joined, gradient)
        if not np.isfinite(update).all():
            break
        step = step + update
        step[2] = _wrap(step[2])
        if np.abs(update).max() < 1e-6:
            break
    information, _, chi2 = _normal_equations(prev_xy, prev_cov, prev_line, prev_line_cov,
                                             cur_xy, cur_cov, cur_line, cur_line_cov, corners,
                                             lines, step)
    return step, information, chi2


@jit
def search(prev_xy, prev_cov, prev_line, prev_line_cov, prev_ends, cur_xy, cur_cov, cur_line,
           cur_line_cov, cur_ends, steps, prior_term, prior_step, prior_information, fused,
           max_step_m, fewest):
    """
    Compiled twin of ``odometry._search``: the best association of the hypotheses.

    The scores take each current landmark's least chi2 over the previous ones, computed
    without keeping every pair's; a refined hypothesis's pairs are computed again, as the
    scores took them.

    :param steps: the hypotheses (H, 3)
    :param prior_term: each hypothesis's chi2 from the prior over PRIOR_PAIR_CHI2 (H,)
    :param prior_step: the prior's step
    :param prior_information: its inverse covariance (3, 3)
    :param fused: the refinements' fits take the prior as a measurement
    :param max_step_m: a refined step longer than this associates nothing, m
    :param fewest: the landmarks of the scan that has fewer
    :return: (the step, corner pairs (Kc, 2), line pairs (Kl, 2))
    """
    scores = np.zeros(steps.shape[0])
    _scores(_corner_chi2(prev_xy, prev_cov, cur_xy, cur_cov, steps, SEARCH_SLACK_M ** 2, True),
            scores)
    _scores(_line_chi2(prev_line, prev_line_cov, prev_ends, cur_line, cur_line_cov, cur_ends,
                       steps, SEARCH_SLACK_RAD ** 2, SEARCH_SLACK_M ** 2, True), scores)
    best_rank, best_chi2 = -np.inf, np.inf
    step = prior_step.copy()
    corners, lines = np.empty((0, 2), np.int64), np.empty((0, 2), np.int64)
    starts, taken = np.empty((REFINED_HYPOTHESES, 3)), 0
    for index in stable_order(-(scores - prior_term)):
        start = steps[index]
        if taken == REFINED_HYPOTHESES:
            break
        same = False
        for other in starts[:taken]:
            same = same or (abs(start[0] - other[0]) + abs(start[1] - other[1]) < SEARCH_SLACK_M
                            and abs(_wrap(start[2] - other[2])) < SEARCH_SLACK_RAD)
        if same:
            continue
        starts[taken] = start
        taken += 1
        # The refinement: the search's pairs (their chi2 as the scores took them), then fit and
        # associate again, twice.
        refined = start.copy()
        one = steps[index:index + 1].copy()
        refined_corners, _ = _one_to_one(_corner_chi2(prev_xy, prev_cov, cur_xy, cur_cov, one,
                                                      SEARCH_SLACK_M ** 2, False)[0])
        refined_lines, _ = _one_to_one(_line_chi2(
            prev_line, prev_line_cov, prev_ends, cur_line, cur_line_cov, cur_ends, one,
            SEARCH_SLACK_RAD ** 2, SEARCH_SLACK_M ** 2, False)[0])
        fit_chi2 = np.nan
        for _ in range(2):
            if refined_corners.shape[0] + refined_lines.shape[0] < 2:
                break
            refined, _, _ = fit(prev_xy, prev_cov, prev_line, prev_line_cov, cur_xy, cur_cov,
                                cur_line, cur_line_cov, refined_corners, refined_lines, refined,
                                prior_step, prior_information, fused)
            refined_corners, refined_lines, fit_chi2 = _associate(
                prev_xy, prev_cov, prev_line, prev_line_cov, prev_ends, cur_xy, cur_cov,
                cur_line, cur_line_cov, cur_ends, refined)
        if np.isnan(fit_chi2):
            _, _, fit_chi2 = _normal_equations(prev_xy, prev_cov, prev_line, prev_line_cov,
                                               cur_xy, cur_cov, cur_line, cur_line_cov,
                                               refined_corners, refined_lines, refined)
        count = refined_corners.shape[0] + refined_lines.shape[0]
        if math.hypot(refined[0], refined[1]) > max_step_m:
            count = 0
        away = refined - prior_step
        away[2] = _wrap(away[2])
        prior_chi2 = (away * _times(prior_information, away)).sum()
        chi2 = fit_chi2 + prior_chi2 if count else np.inf
        rank = count - prior_chi2 / PRIOR_PAIR_CHI2 if count else -1.0
        if rank > best_rank or (rank == best_rank and chi2 < best_chi2):
            best_rank, best_chi2 = rank, chi2
            step, corners, lines = refined, refined_corners, refined_lines
        if best_rank >= ENOUGH_SHARE * fewest:
            break
    return step, corners, lines
