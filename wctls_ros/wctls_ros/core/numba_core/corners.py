# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Corners: intersections of adjacent lines with their jointly propagated (x, y, yaw) covariance.

Derived in docs/derivation.md#corners ((D11)-(D14)) and #common-mode-range-offset ((D15)-(D16)).

For lines L_k = (a_k, b_k, c_k) with covariances C_k (from disjoint returns, so independent), the
corner z = -A^-1 (c_1, c_2), A = [[a_1, b_1], [a_2, b_2]] (the paper's eqs. (24)-(25)), has
dz/dL_k = -A^-1 e_k h^T with h = (x, y, 1). The yaw of the bisector moves with each wall's
direction by half its normal angle: d yaw / dL_k = g_k = (-b_k, a_k, 0) / (2 (a_k^2 + b_k^2)).
The joint covariance is sum_k J_k C_k J_k^T with J_k stacking both (3 x 3), so only three
quadratic forms of each C_k enter it: h^T C_k h, g_k^T C_k h and g_k^T C_k g_k. Since h . L_k = 0
and (-b_k, a_k, 0) . L_k = 0, it is exactly invariant to any rescaling of a line's (a, b, c).

Compiled loops (numba), one pair of walls at a time.
"""

import math

import numpy as np

from ._jit import jit, jit_inline
from ._order import wrapped
from ..records import AlongWall, CornerCandidates, EndWindow, WallAtCorner
from ..rules import CORNER_DARK_WALL_M, CORNER_MISSING_BEAMS

# The upper triangle of the symmetric (x, y, yaw) covariance, row by row: (row, column) of each
# of its six entries.
_UPPER_ROWS = (0, 0, 0, 1, 1, 2)
_UPPER_COLUMNS = (0, 1, 2, 1, 2, 2)


@jit
def corner_candidates(walls, first_wall, second_wall, min_angle_rad, common_range_sigma_m):
    """
    Compiled twin of :func:`..numpy_core.corners.corner_candidates`, one pair at a time.

    :param walls: the walls (their line, line_covariance, line_offset_jacobian, start_xy_m and
        end_xy_m are read)
    :param first_wall: earlier wall of each pair, shape (k,)
    :param second_wall: later wall of each pair, shape (k,)
    :param min_angle_rad: smallest angle between the two walls, rad
    :param common_range_sigma_m: std of the range offset common to the scan, m
    :return: the :class:`~.records.CornerCandidates` of the pairs that passed
    """
    line, start_xy_m, end_xy_m = walls.line, walls.start_xy_m, walls.end_xy_m
    pairs = first_wall.size
    first_kept, second_kept = np.empty(pairs, np.intp), np.empty(pairs, np.intp)
    xy, yaw, opening = np.empty((pairs, 2)), np.empty(pairs), np.empty(pairs)
    found = 0
    min_sine = math.sin(min_angle_rad)
    pair = np.empty(2, np.intp)
    normal_x, normal_y = np.empty(2), np.empty(2)
    direction_x, direction_y = np.empty(2), np.empty(2)
    for p in range(pairs):
        pair[0], pair[1] = first_wall[p], second_wall[p]
        x, y, _ = _intersection(line[pair[0]], line[pair[1]])
        for k in range(2):
            normal_x[k], normal_y[k], _ = _unit_normal(line[pair[k]])
        if not abs(normal_x[0] * normal_y[1] - normal_y[0] * normal_x[1]) >= min_sine:
            continue
        # Unit vectors from the corner along each wall, towards the middle of its returns,
        # held as (-x, y).
        for k in range(2):
            wall = pair[k]
            middle_x = (x - start_xy_m[wall, 0]) + (x - end_xy_m[wall, 0])
            middle_y = (y - start_xy_m[wall, 1]) + (y - end_xy_m[wall, 1])
            side = math.copysign(1.0, normal_y[k] * middle_x - normal_x[k] * middle_y)
            direction_x[k], direction_y[k] = normal_y[k] * side, normal_x[k] * side
        between = math.acos(min(max(direction_x[0] * direction_x[1]
                                    + direction_y[0] * direction_y[1], -1.0), 1.0))
        bisector_x, bisector_y = direction_x[0] + direction_x[1], direction_y[0] + direction_y[1]
        # The sensor (origin) sees the open side: inside a concave corner it lies along
        # +bisector.
        concave = bisector_y * y - bisector_x * x < 0.0
        toward_sensor = 1.0 if concave else -1.0
        first_kept[found], second_kept[found] = pair[0], pair[1]
        xy[found, 0], xy[found, 1] = x, y
        yaw[found] = math.atan2(bisector_y * toward_sensor, bisector_x * -toward_sensor)
        opening[found] = between if concave else 2.0 * np.pi - between
        found += 1
    first_kept, second_kept = first_kept[:found], second_kept[:found]
    return CornerCandidates(xy[:found], yaw[:found],
                            corner_covariance(walls, first_kept, second_kept,
                                              common_range_sigma_m),
                            opening[:found], first_kept, second_kept)


@jit
def corner_covariance(walls, first_wall, second_wall, common_range_sigma_m):
    """
    Compiled twin of :func:`..numpy_core.corners.corner_covariance`, one pair at a time.

    Each wall adds its three quadratic forms (and its share of the common offset's j) to the
    upper triangle, which is mirrored at the end.

    :param walls: the walls (their line, line_covariance and line_offset_jacobian are read)
    :param first_wall: earlier wall of each corner, shape (C,)
    :param second_wall: later wall of each corner, shape (C,)
    :param common_range_sigma_m: std of the range offset common to the scan, m (0: none)
    :return: shape (C, 3, 3)
    """
    line, line_covariance = walls.line, walls.line_covariance
    line_offset_jacobian = walls.line_offset_jacobian
    covariance = np.empty((first_wall.size, 3, 3))
    pair = np.empty(2, np.intp)
    u, w = np.empty(2), np.empty(2)
    upper, common = np.empty(6), np.empty(3)
    for p in range(first_wall.size):
        pair[0], pair[1] = first_wall[p], second_wall[p]
        one, two = line[pair[0]], line[pair[1]]
        x, y, inv_det = _intersection(one, two)
        # A^-1 e_k = (u_k, -w_k): the partner's b and a over the determinant of the row whose
        # own line is k (the second row's is -det).
        u[0], w[0] = two[1] * inv_det, two[0] * inv_det
        u[1], w[1] = one[1] * -inv_det, one[0] * -inv_det
        upper[:] = 0.0
        common[:] = 0.0
        for k in range(2):
            c = line_covariance[pair[k]]
            normal_x, normal_y, norm = _unit_normal(line[pair[k]])
            half_inv_norm = 0.5 / norm
            gradient_x, gradient_y = normal_y * half_inv_norm, normal_x * half_inv_norm
            moved_a = c[0, 0] * x + c[0, 1] * y + c[0, 2]
            moved_b = c[1, 0] * x + c[1, 1] * y + c[1, 2]
            along_h = x * (moved_a + c[2, 0]) + y * (moved_b + c[2, 1]) + c[2, 2]
            cross = gradient_x * moved_a - gradient_y * moved_b                # -g^T C h
            upper[0] += u[k] * (u[k] * along_h)
            upper[1] += u[k] * (w[k] * along_h)
            upper[2] += u[k] * cross
            upper[3] += w[k] * (w[k] * along_h)
            upper[4] += w[k] * cross
            upper[5] += (gradient_x * (gradient_x * c[0, 0] - gradient_y * c[0, 1])
                         + gradient_y * (gradient_y * c[1, 1] - gradient_x * c[1, 0]))
            if common_range_sigma_m > 0.0:
                offset = line_offset_jacobian[pair[k]]
                offset_along_h = x * offset[0] + y * offset[1] + offset[2]
                common[0] += u[k] * offset_along_h
                common[1] += -(w[k] * offset_along_h)
                common[2] += gradient_x * offset[0] - gradient_y * offset[1]
        upper[1] = -upper[1]
        upper[4] = -upper[4]
        for entry in range(6):
            row, column = _UPPER_ROWS[entry], _UPPER_COLUMNS[entry]
            if common_range_sigma_m > 0.0:
                upper[entry] += (common_range_sigma_m * common[row]
                                 * (common_range_sigma_m * common[column]))
            covariance[p, row, column] = covariance[p, column, row] = upper[entry]
    return covariance


@jit
def _intersection(one, two):
    """
    Return where two lines (a, b, c) meet, by Cramer's rule, and 1 / det A.

    :return: (x m, y m, 1 / (a_1 b_2 - a_2 b_1)); inf or NaN for parallel lines
    """
    inv_det = 1.0 / (one[0] * two[1] - two[0] * one[1])
    return ((one[1] * two[2] - two[1] * one[2]) * inv_det,
            (two[0] * one[2] - one[0] * two[2]) * inv_det, inv_det)


@jit
def _unit_normal(line):
    """Return the unit normal (x, y) of a line (a, b, c) and the norm of its (a, b)."""
    norm = math.hypot(line[0], line[1])
    return line[0] / norm, line[1] / norm, norm


@jit
def end_window(contour, after_first, before_second, noise, rule):
    """
    Compiled twin of :func:`..numpy_core.corners.end_window`, one corner at a time.

    :param contour: the returns in circular order
    :param after_first: position of the first wall's last return
    :param before_second: position of the second wall's first return
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param rule: the rule's tolerances
    :return: the :class:`~.records.EndWindow`
    """
    width = rule.window + 2
    window = EndWindow(np.empty(width), np.empty(width), np.empty(width), np.empty(width),
                       np.empty(width, np.bool_), 0)
    return _fill_end_window(contour, after_first, before_second, noise, rule, window)


@jit
def _fill_end_window(contour, after_first, before_second, noise, rule, window):
    """
    Write :func:`end_window` into the arrays of ``window`` (W = rule.window + 2 wide).

    :return: the window of those arrays, with its ``between``
    """
    count, width = contour.x_m.size, window.x_m.size
    between = (before_second - after_first - 1) % count
    x, y, sigma = window.x_m, window.y_m, window.sigma_m
    line_tolerance, in_window = window.line_tolerance_m, window.in_window
    for s in range(width):
        position = wrapped(before_second if s == width - 1 else after_first + s, count)
        in_window[s] = s <= between or s == width - 1
        x[s], y[s] = contour.x_m[position], contour.y_m[position]
        sigma[s] = math.sqrt(noise.deciding_sigma_m ** 2 + (x[s] * x[s] + y[s] * y[s])
                             * noise.bearing_sigma_rad ** 2)
        line_tolerance[s] = rule.sigmas * sigma[s] + rule.floor_m
    return EndWindow(x, y, sigma, line_tolerance, in_window, between)


@jit
def wall_at_corner(walls, wall, corner_x_m, corner_y_m, corner_covariance, step_rad, rule):
    """
    Compiled twin of :func:`..numpy_core.corners.wall_at_corner`, one corner at a time.

    :param walls: the walls
    :param wall: which wall
    :param corner_x_m: x of the corner, m
    :param corner_y_m: y of the corner, m
    :param corner_covariance: the corner's (x, y, yaw) covariance, shape (3, 3)
    :param step_rad: bearing step between beams, rad
    :param rule: the rule's tolerances
    :return: the :class:`~.records.WallAtCorner`
    """
    normal_x, normal_y = math.cos(walls.angle_rad[wall]), math.sin(walls.angle_rad[wall])
    middle_x = 0.5 * (walls.start_xy_m[wall, 0] + walls.end_xy_m[wall, 0])
    middle_y = 0.5 * (walls.start_xy_m[wall, 1] + walls.end_xy_m[wall, 1])
    side = math.copysign(1.0, (middle_x - corner_x_m) * -normal_y
                         + (middle_y - corner_y_m) * normal_x)
    inward_x, inward_y = -normal_y * side, normal_x * side
    # inward^T C inward, term by term in the order of the double sum over (i, j).
    variance = 0.0
    variance += inward_x * corner_covariance[0, 0] * inward_x
    variance += inward_x * corner_covariance[0, 1] * inward_y
    variance += inward_y * corner_covariance[1, 0] * inward_x
    variance += inward_y * corner_covariance[1, 1] * inward_y
    along_sigma = math.sqrt(variance)
    corner_range = math.hypot(corner_x_m, corner_y_m)
    incidence = abs(normal_x * corner_x_m + normal_y * corner_y_m) / corner_range
    return WallAtCorner(normal_x, normal_y, walls.radius_m[wall], inward_x, inward_y,
                        along_sigma, corner_range * step_rad / max(incidence, 1e-3),
                        rule.sigmas * along_sigma + rule.floor_m)


@jit
def along_wall(window, wall, corner_x_m, corner_y_m):
    """
    Compiled twin of :func:`..numpy_core.corners.along_wall`, one corner at a time.

    :param window: the end window
    :param wall: the wall at the corner
    :param corner_x_m: x of the corner, m
    :param corner_y_m: y of the corner, m
    :return: the :class:`~.records.AlongWall`
    """
    width = window.x_m.size
    placed = AlongWall(np.empty(width), np.empty(width), np.empty(width, np.bool_))
    _place_along_wall(window, wall, corner_x_m, corner_y_m, placed)
    return placed


@jit
def _place_along_wall(window, wall, corner_x_m, corner_y_m, placed):
    """Write :func:`along_wall` into the arrays of ``placed``."""
    in_front, along, on_line = placed.in_front_m, placed.along_m, placed.on_line
    for s in range(in_front.size):
        x, y = window.x_m[s], window.y_m[s]
        in_front[s] = wall.radius_m - (x * wall.normal_x + y * wall.normal_y)
        along[s] = (x - corner_x_m) * wall.inward_x + (y - corner_y_m) * wall.inward_y
        on_line[s] = window.in_window[s] and abs(in_front[s]) <= window.line_tolerance_m[s]


@jit
def corner_zone(window, corner_x_m, corner_y_m, first, second, noise, rule):
    """
    Compiled twin of :func:`..numpy_core.corners.corner_zone`, one corner at a time.

    :param window: the end window
    :param corner_x_m: x of the corner, m
    :param corner_y_m: y of the corner, m
    :param first: the first wall at the corner
    :param second: the second wall
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param rule: the rule's tolerances
    :return: whether each return lies in the zone, shape (W,)
    """
    at_corner = np.empty(window.x_m.size, np.bool_)
    _mark_corner_zone(window, corner_x_m, corner_y_m, first, second, noise, rule, at_corner)
    return at_corner


@jit
def _mark_corner_zone(window, corner_x_m, corner_y_m, first, second, noise, rule, at_corner):
    """Write :func:`corner_zone` into ``at_corner``, shape (W,)."""
    sine = abs(first.normal_x * second.normal_y - first.normal_y * second.normal_x)
    corner_noise = math.sqrt(noise.deciding_sigma_m ** 2
                             + (math.hypot(corner_x_m, corner_y_m) * noise.bearing_sigma_rad) ** 2)
    zone = (rule.sigmas * math.hypot(corner_noise, max(first.along_sigma_m, second.along_sigma_m))
            / sine + rule.floor_m + min(first.spacing_m, second.spacing_m))
    for s in range(at_corner.size):
        at_corner[s] = window.in_window[s] and math.hypot(window.x_m[s] - corner_x_m,
                                                          window.y_m[s] - corner_y_m) <= zone


@jit
def without_object_in_front(window, wall, placed, at_corner, rule):
    """
    Compiled twin of :func:`..numpy_core.corners.without_object_in_front`, one corner at a time.

    :param window: the end window
    :param wall: the wall at the corner
    :param placed: the window's returns with respect to the wall
    :param at_corner: which returns lie in the corner zone, shape (W,)
    :param rule: the rule's tolerances (``run_sigmas`` 0: no such test)
    :return: on the wall's line, shape (W,)
    """
    on_line = np.empty(at_corner.size, np.bool_)
    _clear_object_in_front(window, wall, placed, at_corner, rule, on_line)
    return on_line


@jit
def _clear_object_in_front(window, wall, placed, at_corner, rule, on_line):
    """Write :func:`without_object_in_front` into ``on_line``, shape (W,)."""
    width = at_corner.size
    for s in range(width):        # a loop, not on_line[:] = ... (see _jit.py)
        on_line[s] = placed.on_line[s]
    run, together = 0, 0.0
    for s in range(1, width - 1):
        if on_line[s] and placed.along_m[s] >= -wall.tolerance_m and not at_corner[s]:
            run += 1
            together += placed.in_front_m[s] / window.sigma_m[s]
    together /= math.sqrt(max(run, 1))
    if rule.run_sigmas > 0.0 and together > rule.run_sigmas:
        for s in range(1, width - 1):
            if on_line[s] and placed.along_m[s] >= -wall.tolerance_m and not at_corner[s]:
                on_line[s] = False


@jit
def reaches(wall, placed, on_line, at_corner):
    """
    Compiled twin of :func:`..numpy_core.corners.reaches`, one corner at a time.

    :param wall: the wall at the corner
    :param placed: the window's returns with respect to the wall
    :param on_line: which lie on its line (:func:`without_object_in_front`), shape (W,)
    :param at_corner: which lie in the corner zone, shape (W,)
    :return: shape (W,)
    """
    here = np.empty(at_corner.size, np.bool_)
    _mark_reaches(wall, placed, on_line, at_corner, here)
    return here


@jit
def _mark_reaches(wall, placed, on_line, at_corner, here):
    """Write :func:`reaches` into ``here``, shape (W,)."""
    for s in range(here.size):
        here[s] = at_corner[s] or (on_line[s] and placed.along_m[s] >= -wall.tolerance_m)


@jit
def goes_on(first, second, first_placed, second_placed, first_on_line, second_on_line,
            at_corner):
    """
    Compiled twin of :func:`..numpy_core.corners.goes_on`, one corner at a time.

    :param first: the first wall at the corner
    :param second: the second wall
    :param first_placed: the window's returns with respect to the first wall
    :param second_placed: ... to the second
    :param first_on_line: which lie on the first wall's line, shape (W,)
    :param second_on_line: ... on the second's
    :param at_corner: which lie in the corner zone, shape (W,)
    :return: whether one does
    """
    for s in range(at_corner.size):
        if at_corner[s]:
            continue
        if (first_on_line[s] and not second_on_line[s]
                and first_placed.along_m[s] < -first.tolerance_m):
            return True
        if (second_on_line[s] and not first_on_line[s]
                and second_placed.along_m[s] < -second.tolerance_m):
            return True
    return False


@jit
def blocked(window, first, second, first_placed, second_placed, first_here, second_here,
            at_corner):
    """
    Compiled twin of :func:`..numpy_core.corners.blocked`, one corner at a time.

    :param window: the end window
    :param first: the first wall at the corner
    :param second: the second wall
    :param first_placed: the window's returns with respect to the first wall
    :param second_placed: ... to the second
    :param first_here: which the first wall reaches (:func:`reaches`), shape (W,)
    :param second_here: ... the second
    :param at_corner: which lie in the corner zone, shape (W,)
    :return: whether the view between the reaches is blocked
    """
    width = at_corner.size
    first_anchor, second_anchor = 0, width - 1
    for s in range(width):
        if first_here[s] and not at_corner[s]:
            first_anchor = max(first_anchor, s)
        if second_here[s] and not at_corner[s]:
            second_anchor = min(second_anchor, s)
    for s in range(width):
        occluder = (window.in_window[s] and first_placed.in_front_m[s] > window.line_tolerance_m[s]
                    and second_placed.in_front_m[s] > window.line_tolerance_m[s])
        interrupts = window.in_window[s] and not first_here[s] and not second_here[s]
        outside = s < first_anchor or s > second_anchor
        if interrupts and (not occluder or not outside):
            return True
    return False


@jit
def short_of_corner(wall, placed, on_line, here):
    """
    Compiled twin of :func:`..numpy_core.corners.short_of_corner`, one corner at a time.

    :param wall: the wall at the corner
    :param placed: the window's returns with respect to the wall
    :param on_line: which lie on its line, shape (W,)
    :param here: which it reaches, shape (W,)
    :return: beams (inf: none of its returns reaches the corner)
    """
    gap = np.inf
    for s in range(here.size):
        if on_line[s] and here[s]:
            gap = min(gap, max(placed.along_m[s], 0.0))
    return max(gap - wall.tolerance_m, 0.0) / wall.spacing_m


@jit
def seen_through(corner_x_m, corner_y_m, wall, other, contour, start, stop, noise, rule):
    """
    Compiled twin of :func:`..numpy_core.corners.seen_through`, one test at a time.

    :param corner_x_m: x of the corner, m
    :param corner_y_m: y of the corner, m
    :param wall: the wall at the corner (radius >= 0)
    :param other: the other wall
    :param contour: the returns in circular order
    :param start: position of the first return to test (taken modulo n)
    :param stop: position of the last return to test (taken modulo n, after ``start``)
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param rule: the rule's tolerances
    :return: whether the wall is seen through
    """
    count = contour.x_m.size
    run, behind = 0, 0.0
    for step in range((stop - start) % count + 1):
        position = wrapped(start + step, count)
        x, y = contour.x_m[position], contour.y_m[position]
        sigma = math.sqrt(noise.deciding_sigma_m ** 2
                          + (x * x + y * y) * noise.bearing_sigma_rad ** 2)
        line_tolerance = rule.sigmas * sigma + rule.floor_m
        offset = x * wall.normal_x + y * wall.normal_y
        if (abs(other.radius_m - x * other.normal_x - y * other.normal_y) > line_tolerance
                or offset <= 0.0 or wall.radius_m - offset > line_tolerance):
            continue
        # Where the line of sight crosses the wall's line: the return scaled by radius/offset.
        scale = wall.radius_m / offset
        along = ((scale * x - corner_x_m) * wall.inward_x + (scale * y - corner_y_m)
                 * wall.inward_y)
        if along > wall.tolerance_m:
            run += 1
            behind += (offset - wall.radius_m) / sigma
    return run > 0 and behind / math.sqrt(run) > rule.run_sigmas


@jit
def dark_wall(corner_x_m, corner_y_m, first, second, contour, after_first, before_second,
              step_rad):
    """
    Compiled twin of :func:`..numpy_core.corners.dark_wall`, one corner at a time.

    :param corner_x_m: x of the corner, m
    :param corner_y_m: y of the corner, m
    :param first: the first wall at the corner
    :param second: the second wall
    :param contour: the returns in circular order
    :param after_first: position of the first wall's last return
    :param before_second: position of the second wall's first return
    :param step_rad: bearing step between beams, rad
    :return: whether a dark run crosses the walls' reach
    """
    count = contour.bearing_rad.size
    apex = math.atan2(corner_y_m, corner_x_m)
    low = 0.5 * step_rad
    for step in range((before_second - after_first - 1) % count + 1):
        here = contour.bearing_rad[wrapped(after_first + step, count)]
        gap = _wrap(contour.bearing_rad[wrapped(after_first + step + 1, count)] - here)
        width = abs(gap)
        if np.rint(width / step_rad) - 1.0 <= 1.0 + CORNER_MISSING_BEAMS:
            continue
        sense = math.copysign(1.0, gap)
        to_apex = _wrap(apex - here) * sense
        high = width - low                        # the missing beams' own widths
        unseen = (_along_line(first, here, sense, low, min(high, to_apex))
                  + _along_line(second, here, sense, max(low, to_apex), high))
        if unseen > CORNER_DARK_WALL_M:
            return True
    return False


@jit
def _wrap(angle_rad):
    """Return an angle taken into [-pi, pi), rad."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


@jit
def _along_line(wall, bearing, sense, start, stop):
    """
    Compiled twin of :func:`..numpy_core.corners._along_line`, for one gap.

    :return: m
    """
    if stop <= start:
        return 0.0
    near, far = bearing + sense * start, bearing + sense * stop
    near_along = ((math.sin(near) * wall.normal_x - math.cos(near) * wall.normal_y)
                  / (math.cos(near) * wall.normal_x + math.sin(near) * wall.normal_y))
    far_along = ((math.sin(far) * wall.normal_x - math.cos(far) * wall.normal_y)
                 / (math.cos(far) * wall.normal_x + math.sin(far) * wall.normal_y))
    return wall.radius_m * abs(far_along - near_along)


@jit_inline
def walls_end_at(candidates, walls, positions, contour, step_rad, noise, rule):
    """
    Compiled twin of :func:`..numpy_core.corners.walls_end_at`, one corner at a time.

    :param candidates: the candidate corners
    :param walls: the walls
    :param positions: positions of every wall's first and last return, shape (2, S)
    :param contour: the returns in circular order
    :param step_rad: bearing step between beams, rad
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param rule: the rule's tolerances
    :return: (corners both walls end at (C,), whether each wall's end was seen (C, 2), column 0
        the first wall)
    """
    first_position, last_position = positions[0], positions[1]
    corners = candidates.xy_m.shape[0]
    keep = np.zeros(corners, np.bool_)
    seen = np.zeros((corners, 2), np.bool_)
    # Every corner's window, placements and flags are written into the same arrays, made once
    # per scan (a dozen arrays per corner otherwise): the columns of (F, W) or (B, W) arrays,
    # F = 8 numbers and B = 8 flags per column.
    widest, count = rule.window + 2, contour.x_m.size
    numbers, flags = np.empty((8, widest)), np.empty((8, widest), np.bool_)
    for c in range(corners):
        one, two = candidates.first_wall[c], candidates.second_wall[c]
        after_first, before_second = last_position[one], first_position[two]
        corner_x, corner_y = candidates.xy_m[c, 0], candidates.xy_m[c, 1]
        # The columns past the returns between the walls are outside the window, where every
        # step's flags are False: they change nothing, and a window of the facing ends and the
        # returns between them (rule.window at most) gives the same result.
        width = min((before_second - after_first - 1) % count, rule.window) + 2
        window = _fill_end_window(contour, after_first, before_second, noise, rule, EndWindow(
            numbers[0, :width], numbers[1, :width], numbers[2, :width], numbers[3, :width],
            flags[0, :width], 0))
        first = wall_at_corner(walls, one, corner_x, corner_y, candidates.covariance[c],
                               step_rad, rule)
        second = wall_at_corner(walls, two, corner_x, corner_y, candidates.covariance[c],
                                step_rad, rule)
        first_placed = AlongWall(numbers[4, :width], numbers[5, :width], flags[1, :width])
        second_placed = AlongWall(numbers[6, :width], numbers[7, :width], flags[2, :width])
        _place_along_wall(window, first, corner_x, corner_y, first_placed)
        _place_along_wall(window, second, corner_x, corner_y, second_placed)
        at_corner = flags[3, :width]
        _mark_corner_zone(window, corner_x, corner_y, first, second, noise, rule, at_corner)
        first_on_line, second_on_line = flags[4, :width], flags[5, :width]
        _clear_object_in_front(window, first, first_placed, at_corner, rule, first_on_line)
        _clear_object_in_front(window, second, second_placed, at_corner, rule, second_on_line)
        first_here, second_here = flags[6, :width], flags[7, :width]
        _mark_reaches(first, first_placed, first_on_line, at_corner, first_here)
        _mark_reaches(second, second_placed, second_on_line, at_corner, second_here)
        first_short = short_of_corner(first, first_placed, first_on_line, first_here)
        second_short = short_of_corner(second, second_placed, second_on_line, second_here)
        seen[c, 0], seen[c, 1] = first_short <= 1.0, second_short <= 1.0
        keep[c] = (window.between <= rule.window and first_here[0] and second_here[-1]
                   and not goes_on(first, second, first_placed, second_placed, first_on_line,
                                   second_on_line, at_corner)
                   and not blocked(window, first, second, first_placed, second_placed,
                                   first_here, second_here, at_corner)
                   and first_short <= 1.0 + CORNER_MISSING_BEAMS
                   and second_short <= 1.0 + CORNER_MISSING_BEAMS
                   and not dark_wall(corner_x, corner_y, first, second, contour, after_first,
                                     before_second, step_rad))
        if keep[c] and rule.run_sigmas > 0.0:
            # The first wall's stretch is crossed by the sight lines after its last return, up
            # to the second wall's last; the second's by those from the first wall's first
            # return up to its own first.
            keep[c] = not (
                seen_through(corner_x, corner_y, first, second, contour, after_first + 1,
                             last_position[two], noise, rule)
                or seen_through(corner_x, corner_y, second, first, contour,
                                first_position[one], before_second - 1, noise, rule))
    return keep, seen
