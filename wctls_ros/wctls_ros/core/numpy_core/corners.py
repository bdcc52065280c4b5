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

A scan has only tens of pairs, so the cost is the number of numpy calls, not their size: every
quantity of a wall is one (2, k) array, row 0 for the first wall of each pair and row 1 for the
second, written out entry by entry, and the rejected pairs are dropped in one step at the end.
"""

import math
from typing import Optional, Union

import numpy as np

from ..features import CornerSet, FloatArray, IndexArray, SegmentSet
from ..records import (AlongWall, CornerCandidates, CornerEndRule, EndWindow, Noise, Returns,
                       WallAtCorner)
from ..rules import CORNER_DARK_WALL_M, CORNER_MISSING_BEAMS

# The upper triangle of the symmetric (x, y, yaw) covariance, row by row: (row, column) of each
# of its six entries, and which of them each entry of the full matrix is.
_UPPER_ROW = np.array([0, 0, 0, 1, 1, 2])
_UPPER_COLUMN = np.array([0, 1, 2, 1, 2, 2])
_UPPER_TO_FULL = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])


def _solve(a: np.ndarray, b: np.ndarray, c: np.ndarray):
    """
    Intersect pairs of lines by Cramer's rule (the paper's eqs. (24)-(25)).

    Row 0 of the inputs holds the first line of every pair, row 1 the second and row 2 the first
    again, so that rows 1 and 2 are the partners of rows 0 and 1. Row 1 of the results swaps the
    two lines: its determinant is -det A and its intersection the same, bit for bit (up to the
    sign of a zero).

    :param a: a of the lines, shape (3, C)
    :param b: b of the lines, shape (3, C)
    :param c: c of the lines, shape (3, C)
    :return: (x, y) of the intersections and (u, w), the b and a of the partner line over the
        row's determinant: the column A^-1 e_k of line k is (u, -w); each shape (2, C), row k
        for line k
    """
    a_own, b_own, c_own = a[:2], b[:2], c[:2]
    a_partner, b_partner, c_partner = a[1:], b[1:], c[1:]
    det = a_own * b_partner - a_partner * b_own
    det[1] = -det[0]                     # exactly, zero too: parallel lines meet at the same inf
    inv_det = 1.0 / det
    x = (b_own * c_partner - b_partner * c_own) * inv_det
    y = (a_partner * c_own - a_own * c_partner) * inv_det
    return x, y, b_partner * inv_det, a_partner * inv_det


def _covariance_times_h(covariance: np.ndarray, x: np.ndarray, y: np.ndarray):
    """
    Return the first two entries of C h, and h^T C h, for h = (x, y, 1).

    :param covariance: the nine entries of each C, row by row, shape (9, ...)
    :param x: x of h, shape (...)
    :param y: y of h, shape (...)
    :return: ((C h)_a, (C h)_b, h^T C h), each shape (...)
    """
    moved_a = covariance[0] * x + covariance[1] * y + covariance[2]
    moved_b = covariance[3] * x + covariance[4] * y + covariance[5]
    return (moved_a, moved_b,
            x * (moved_a + covariance[6]) + y * (moved_b + covariance[7]) + covariance[8])


def _position_covariance(u: np.ndarray, w: np.ndarray, along_h: np.ndarray):
    """
    Return sum_k (A^-1 e_k) (A^-1 e_k)^T h^T C_k h, the covariance of the corners' position.

    :param u: x of A^-1 e_k, row k for line k, shape (2, C)
    :param w: -y of A^-1 e_k, shape (2, C)
    :param along_h: h^T C_k h, shape (2, C)
    :return: its (xx, xy, yy) entries, each shape (C,)
    """
    u_along, w_along = u * along_h, w * along_h
    xx, xy, yy = u * u_along, u * w_along, w * w_along
    return xx[0] + xx[1], -(xy[0] + xy[1]), yy[0] + yy[1]


def intersect(line_a: np.ndarray, cov_a: np.ndarray, line_b: np.ndarray,
              cov_b: np.ndarray):
    """
    Intersect pairs of lines and propagate their full covariances to the position.

    :param line_a: (a, b, c) of the first lines, shape (C, 3)
    :param cov_a: their covariances, shape (C, 3, 3)
    :param line_b: (a, b, c) of the second lines, shape (C, 3)
    :param cov_b: their covariances, shape (C, 3, 3)
    :return: (position (C, 2) m, covariance (C, 2, 2) m^2, position Jacobians w.r.t. line_a
        and line_b, each (C, 2, 3))
    """
    a, b, c = np.array([line_a, line_b, line_a], dtype=float).transpose(2, 0, 1)
    with np.errstate(divide='ignore', invalid='ignore'):
        x, y, u, w = _solve(a, b, c)
    covariance = np.array([cov_a, cov_b], dtype=float).reshape(2, -1, 9).transpose(2, 0, 1)
    xx, xy, yy = _position_covariance(u, w, _covariance_times_h(covariance, x, y)[2])
    h = np.stack([x[0], y[0], np.ones_like(x[0])], axis=-1)
    jacobian = np.stack([-u, w], axis=-1)[..., None] * h[:, None, :]       # -A^-1 e_k h^T
    return (h[:, :2], np.stack([xx, xy, xy, yy], axis=-1).reshape(-1, 2, 2), jacobian[0],
            jacobian[1])


def find_corners(line: np.ndarray, line_covariance: np.ndarray,
                 start_xy_m: np.ndarray, end_xy_m: np.ndarray, first: np.ndarray,
                 second: np.ndarray, min_angle_rad: float,
                 line_offset_jacobian: Optional[np.ndarray] = None,
                 common_range_sigma_m: float = 0.0) -> CornerSet:
    """
    Intersect the given pairs of segments that are not close to parallel.

    A pair is rejected when its lines are closer to parallel than ``min_angle_rad``; whether
    both walls really end at the intersection is :func:`walls_end_at`'s question, not asked
    here. The corners of :func:`corner_candidates`, for lines given as arrays.

    :param line: (a, b, c) of every segment in the method's form, shape (S, 3)
    :param line_covariance: covariance of (a, b, c), shape (S, 3, 3)
    :param start_xy_m: first return of each segment projected on its line, shape (S, 2), m
    :param end_xy_m: last return projected on its line, shape (S, 2), m
    :param first: earlier segment of each candidate pair, shape (k,)
    :param second: later segment of each candidate pair, shape (k,)
    :param min_angle_rad: smallest angle between the two walls, rad
    :param line_offset_jacobian: d(a, b, c) / d(range offset common to the scan), (S, 3), per m
    :param common_range_sigma_m: std of that common offset, m: it moves both lines together, so
        its part of the corner covariance is sigma^2 j j^T with j = J_1 g_1 + J_2 g_2
    :return: the corners that pass (``end_seen`` is True: the ends were not tested)
    """
    count = len(line)
    if line_offset_jacobian is None:                 # no common offset to propagate
        line_offset_jacobian, common_range_sigma_m = np.zeros((count, 3)), 0.0
    # The other fields corner_candidates does not read.
    walls = SegmentSet.filled(count, line=line, line_covariance=line_covariance,
                              line_offset_jacobian=line_offset_jacobian, start_xy_m=start_xy_m,
                              end_xy_m=end_xy_m)
    found = corner_candidates(walls, first, second, min_angle_rad, common_range_sigma_m)
    return CornerSet(xy_m=found.xy_m, yaw_rad=found.yaw_rad, covariance=found.covariance,
                     opening_angle_rad=found.opening_angle_rad, first_segment=found.first_wall,
                     second_segment=found.second_wall,
                     end_seen=np.ones((found.yaw_rad.size, 2), dtype=bool))


def corner_candidates(walls: SegmentSet, first_wall: np.ndarray, second_wall: np.ndarray,
                      min_angle_rad: float, common_range_sigma_m: float) -> CornerCandidates:
    """
    Intersect pairs of walls that are not close to parallel.

    Whether both walls really end at the intersection is :func:`walls_end_at`'s question.

    For each pair: the corner z = -A^-1 (c_1, c_2) (the paper's eqs. (24)-(25)); the pair is
    rejected when the walls' unit normals have a cross product below sin(``min_angle_rad``).
    For the others: the bisector's yaw towards the open side the sensor sees, the opening
    angle, and the joint covariance of (x, y, yaw) (:func:`corner_covariance`).

    For every pair at once.

    :param walls: the walls (their line, line_covariance, line_offset_jacobian, start_xy_m and
        end_xy_m are read)
    :param first_wall: earlier wall of each pair, shape (k,)
    :param second_wall: later wall of each pair, shape (k,)
    :param min_angle_rad: smallest angle between the two walls, rad
    :param common_range_sigma_m: std of the range offset common to the scan, m
    :return: the candidates of the pairs that passed
    """
    pairs = np.array([first_wall, second_wall, first_wall], dtype=np.intp)   # see _solve
    pair = pairs[:2]
    lines = walls.line.T.take(pairs, 1)
    start, end = walls.start_xy_m.T.take(pair, 1), walls.end_xy_m.T.take(pair, 1)
    # Nearly parallel lines meet at inf / NaN: such pairs are carried along with the others and
    # dropped with the rest of the rejected ones at the end.
    with np.errstate(all='ignore'):
        x, y, u, w = _solve(lines[0], lines[1], lines[2])
        normal_x, normal_y, norm = _unit_normals(lines[0, :2], lines[1, :2])
        sine = abs(normal_x[0] * normal_y[1] - normal_y[0] * normal_x[1])
        from_start_x, from_start_y = x - start[0], y - start[1]
        from_end_x, from_end_y = x - end[0], y - end[1]
        kept = (sine >= math.sin(min_angle_rad)).nonzero()[0]

        # Unit vectors from the corner along each wall, towards the middle of its returns: the
        # wall direction (-normal_y, normal_x), reversed when that middle lies behind it. They
        # are held as (-x, y), i.e. (normal_y, normal_x) * side.
        side = np.copysign(1.0, normal_y * (from_start_x + from_end_x)
                           - normal_x * (from_start_y + from_end_y))
        direction_x, direction_y = normal_y * side, normal_x * side
        direction_x_0, direction_x_1 = direction_x[0], direction_x[1]
        direction_y_0, direction_y_1 = direction_y[0], direction_y[1]
        between = np.arccos(np.minimum(np.maximum(
            direction_x_0 * direction_x_1 + direction_y_0 * direction_y_1, -1.0), 1.0))
        bisector_x, bisector_y = direction_x_0 + direction_x_1, direction_y_0 + direction_y_1
        # The sensor (origin) sees the open side: inside a concave corner it lies along +bisector.
        concave = bisector_y * y[0] - bisector_x * x[0] < 0.0
        toward_sensor = np.where(concave, 1.0, -1.0)
        yaw = np.arctan2(bisector_y * toward_sensor, bisector_x * -toward_sensor)
        opening = np.where(concave, between, 2.0 * np.pi - between)
        # The covariance of the pairs kept, from the numbers above (not computed again).
        pair = pair.take(kept, axis=1)
        at_x, at_y, at_u, at_w, at_normal_x, at_normal_y, at_norm = np.array(
            [x, y, u, w, normal_x, normal_y, norm]).take(kept, axis=2)
        covariance = _joint_covariance(walls, pair, at_x, at_y, at_u, at_w, at_normal_x,
                                       at_normal_y, at_norm, common_range_sigma_m)
    return CornerCandidates(np.array([x[0], y[0]]).T.take(kept, 0), yaw[kept], covariance,
                            opening[kept], pair[0], pair[1])


def corner_covariance(walls: SegmentSet, first_wall: np.ndarray, second_wall: np.ndarray,
                      common_range_sigma_m: float) -> np.ndarray:
    """
    Return the joint covariance of (x, y, yaw) of the corners of pairs of walls.

    (D11)-(D14): sum_k J_k C_k J_k^T over the two walls' line covariances C_k, with
    dz/dL_k = -A^-1 e_k h^T at the corner z, h = (x, y, 1), and d yaw / dL_k = g_k =
    (-b_k, a_k, 0) / (2 (a_k^2 + b_k^2)), so that only three quadratic forms of each C_k enter:
    h^T C_k h, g_k^T C_k h and g_k^T C_k g_k. Plus sigma^2 j j^T for the range offset common to
    the scan, which moves both lines together: j = J_1 dL_1 / d offset + J_2 dL_2 / d offset
    ((D15)-(D16)). The upper triangle is computed and mirrored, so the matrix is exactly
    symmetric. The walls of a pair must not be parallel (their corner is inf).

    For every pair at once.

    :param walls: the walls (their line, line_covariance and line_offset_jacobian are read)
    :param first_wall: earlier wall of each corner, shape (C,)
    :param second_wall: later wall of each corner, shape (C,)
    :param common_range_sigma_m: std of the range offset common to the scan, m (0: none)
    :return: shape (C, 3, 3), over (x m, y m, yaw rad)
    """
    pairs = np.array([first_wall, second_wall, first_wall], dtype=np.intp)   # see _solve
    lines = walls.line.T.take(pairs, 1)
    with np.errstate(all='ignore'):
        x, y, u, w = _solve(lines[0], lines[1], lines[2])
        normal_x, normal_y, norm = _unit_normals(lines[0, :2], lines[1, :2])
        return _joint_covariance(walls, pairs[:2], x, y, u, w, normal_x, normal_y, norm,
                                 common_range_sigma_m)


def _joint_covariance(walls: SegmentSet, pair: np.ndarray, x: np.ndarray, y: np.ndarray,
                      u: np.ndarray, w: np.ndarray, normal_x: np.ndarray, normal_y: np.ndarray,
                      norm: np.ndarray, common_range_sigma_m: float) -> np.ndarray:
    """
    Return :func:`corner_covariance` from the pairs' intersections and normals.

    With floating-point warnings already silenced (parallel lines give inf).

    :param walls: the walls
    :param pair: the first and second wall of each corner, shape (2, C)
    :param x: x of the intersections, shape (2, C) (:func:`_solve`)
    :param y: y of the intersections, shape (2, C)
    :param u: b of the partner line over the determinant, shape (2, C)
    :param w: a of the partner line over the determinant, shape (2, C)
    :param normal_x: x of each line's unit normal, shape (2, C) (:func:`_unit_normals`)
    :param normal_y: y of that normal, shape (2, C)
    :param norm: the norm of each line's (a, b), shape (2, C)
    :param common_range_sigma_m: std of the range offset common to the scan, m (0: none)
    :return: shape (C, 3, 3), over (x m, y m, yaw rad)
    """
    covariance = walls.line_covariance.reshape(-1, 9).T.take(pair, 1)
    # Line k moves the position by -A^-1 e_k h^T dL_k and the yaw by g_k^T dL_k, with
    # g_k = (-gradient_x, gradient_y, 0).
    half_inv_norm = 0.5 / norm
    gradient_x, gradient_y = normal_y * half_inv_norm, normal_x * half_inv_norm
    moved_a, moved_b, along_h = _covariance_times_h(covariance, x, y)
    cross = gradient_x * moved_a - gradient_y * moved_b                # -g^T C h
    yaw_variance = (gradient_x * (gradient_x * covariance[0] - gradient_y * covariance[1])
                    + gradient_y * (gradient_y * covariance[4]
                                    - gradient_x * covariance[3]))    # g^T C g
    xx, xy, yy = _position_covariance(u, w, along_h)
    # -A^-1 e_k g^T C h, with A^-1 e_k = (u, -w).
    x_yaw, y_yaw = u * cross, w * cross
    upper = np.array([xx, xy, x_yaw[0] + x_yaw[1], yy, -(y_yaw[0] + y_yaw[1]),
                      yaw_variance[0] + yaw_variance[1]])
    if common_range_sigma_m > 0.0:
        offset_a, offset_b, offset_c = walls.line_offset_jacobian.T.take(pair, 1)
        offset_along_h = x * offset_a + y * offset_b + offset_c
        # Each wall's share of -j = -sum_k (-A^-1 e_k h^T, g_k^T) dL_k / d offset (the sign
        # drops out of j j^T).
        shift = np.array([u * offset_along_h, -(w * offset_along_h),
                          gradient_x * offset_a - gradient_y * offset_b])
        common = common_range_sigma_m * (shift[:, 0] + shift[:, 1])
        upper += common[_UPPER_ROW] * common[_UPPER_COLUMN]
    return upper.T.take(_UPPER_TO_FULL, 1).reshape(-1, 3, 3)


def _unit_normals(a: np.ndarray, b: np.ndarray):
    """
    Return the unit normals of lines a x + b y + c = 0 and the norms of their (a, b).

    :param a: a of the lines, any shape
    :param b: b of the lines, the same shape
    :return: (x of the unit normal, its y, sqrt(a^2 + b^2)), each that shape
    """
    norm = np.hypot(a, b)
    return a / norm, b / norm, norm


def end_window(contour: Returns, after_first: np.ndarray, before_second: np.ndarray,
               noise: Noise, rule: CornerEndRule) -> EndWindow[IndexArray]:
    """
    Gather the returns between two walls that the corner end rule looks at, for every corner.

    docs/derivation.md#corners, "Corner end rule": the first wall's facing end, the returns
    left out of both segments (at most ``rule.window``) and the second wall's facing end, each
    with its position noise and the tolerance of "on a line", ``sigmas`` times that noise plus
    ``floor_m``.

    For every corner at once.

    :param contour: the returns in circular order
    :param after_first: position of each first wall's last return, shape (C,)
    :param before_second: position of each second wall's first return, shape (C,)
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param rule: the rule's tolerances
    :return: the windows, each field shape (C, W) (``between`` (C,))
    """
    x_m, y_m = contour.x_m, contour.y_m
    steps = np.arange(rule.window + 2)
    between = (before_second - after_first - 1) % len(x_m)
    position = after_first[:, None] + steps
    position[:, -1] = before_second
    x, y = x_m.take(position, mode='wrap'), y_m.take(position, mode='wrap')
    sigma = np.sqrt(noise.deciding_sigma_m ** 2 + (x * x + y * y) * noise.bearing_sigma_rad ** 2)
    in_window = steps <= between[:, None]
    in_window[:, -1] = True                      # the second wall's facing end
    return EndWindow(x, y, sigma, rule.sigmas * sigma + rule.floor_m, in_window, between)


def wall_at_corner(walls: SegmentSet, wall: np.ndarray, corner_xy_m: np.ndarray,
                   corner_covariance: np.ndarray, step_rad: float,
                   rule: CornerEndRule) -> WallAtCorner[FloatArray]:
    """
    Describe one wall of every corner as seen from the corner.

    docs/derivation.md#corners, "Corner end rule": its unit normal, the unit direction from the
    corner into the wall (towards the middle of its returns), the corner's standard deviation
    along that direction (from its position covariance), the spacing of the beams on the wall
    at the corner (the range times the bearing step over the incidence, at most 1000 times the
    step), and the tolerance along the wall, ``sigmas`` times that deviation plus ``floor_m``.

    For every corner at once, and for both walls of every corner at once when ``wall`` has a
    row for each (shape (2, C)).

    :param walls: the walls
    :param wall: which wall of each corner, shape (C,) or (2, C)
    :param corner_xy_m: the corners, shape (C, 2), m
    :param corner_covariance: their (x, y, yaw) covariance, shape (C, 3, 3)
    :param step_rad: bearing step between beams, rad
    :param rule: the rule's tolerances
    :return: the walls, each field the shape of ``wall``
    """
    corner_x, corner_y = corner_xy_m[:, 0], corner_xy_m[:, 1]
    angle = walls.angle_rad[wall]
    normal_x, normal_y = np.cos(angle), np.sin(angle)
    middle = 0.5 * (walls.start_xy_m.take(wall, axis=0) + walls.end_xy_m.take(wall, axis=0))
    middle_x, middle_y = middle[..., 0], middle[..., 1]
    side = np.copysign(1.0, (middle_x - corner_x) * -normal_y + (middle_y - corner_y) * normal_x)
    inward_x, inward_y = -normal_y * side, normal_x * side
    xx, xy = corner_covariance[:, 0, 0], corner_covariance[:, 0, 1]
    yx, yy = corner_covariance[:, 1, 0], corner_covariance[:, 1, 1]
    along_sigma = np.sqrt(inward_x * xx * inward_x + inward_x * xy * inward_y
                          + inward_y * yx * inward_x + inward_y * yy * inward_y)
    corner_range = np.hypot(corner_x, corner_y)
    incidence = np.abs(normal_x * corner_x + normal_y * corner_y) / corner_range
    return WallAtCorner(normal_x, normal_y, walls.radius_m[wall], inward_x, inward_y,
                        along_sigma, corner_range * step_rad / np.maximum(incidence, 1e-3),
                        rule.sigmas * along_sigma + rule.floor_m)


def along_wall(window: EndWindow[IndexArray], wall: WallAtCorner[FloatArray],
               corner_x_m: np.ndarray, corner_y_m: np.ndarray) -> AlongWall:
    """
    Place the returns of every end window with respect to one wall of its corner.

    docs/derivation.md#corners, "Corner end rule": each return's offset in front of the wall's
    line, its distance from the corner into the wall, and whether it lies on the line (within
    its line tolerance; only the window's own returns).

    For every corner at once (for both walls at once when the wall's fields are (2, C)).

    :param window: the end windows
    :param wall: the wall of each corner
    :param corner_x_m: x of the corners, shape (C,), m
    :param corner_y_m: y of the corners, shape (C,), m
    :return: each field shape (C, W) ((2, C, W))
    """
    offset = window.x_m * wall.normal_x[..., None] + window.y_m * wall.normal_y[..., None]
    in_front = wall.radius_m[..., None] - offset
    return AlongWall(in_front, ((window.x_m - corner_x_m[:, None]) * wall.inward_x[..., None]
                                + (window.y_m - corner_y_m[:, None]) * wall.inward_y[..., None]),
                     window.in_window & (np.abs(in_front) <= window.line_tolerance_m))


def corner_zone(window: EndWindow[IndexArray], corner_x_m: np.ndarray, corner_y_m: np.ndarray,
                first: WallAtCorner[FloatArray], second: WallAtCorner[FloatArray], noise: Noise,
                rule: CornerEndRule) -> np.ndarray:
    """
    Tell which returns of every end window lie so close to the corner that they fit either wall.

    docs/derivation.md#corners, "Corner end rule": there both lines are within the noise of each
    other, and a beam's footprint on both walls returns a range in between (an inside corner
    looks rounded): within ``sigmas`` times the corner's noise (its position noise and the
    larger of its deviations along the walls) over the sine of the walls' angle, plus
    ``floor_m``, plus the smaller beam spacing.

    For every corner at once.

    :return: shape (C, W)
    """
    sine = np.abs(first.normal_x * second.normal_y - first.normal_y * second.normal_x)
    corner_noise = np.sqrt(noise.deciding_sigma_m ** 2
                           + (np.hypot(corner_x_m, corner_y_m) * noise.bearing_sigma_rad) ** 2)
    zone = (rule.sigmas * np.hypot(corner_noise, np.maximum(first.along_sigma_m,
                                                            second.along_sigma_m))
            / sine + rule.floor_m + np.minimum(first.spacing_m, second.spacing_m))
    return window.in_window & (np.hypot(window.x_m - corner_x_m[:, None],
                                        window.y_m - corner_y_m[:, None]) <= zone[:, None])


def without_object_in_front(window: EndWindow[IndexArray], wall: WallAtCorner[FloatArray],
                            placed: AlongWall, at_corner: np.ndarray,
                            rule: CornerEndRule) -> np.ndarray:
    """
    Return which returns lie on a wall's line, less a run that lies in front of it together.

    docs/derivation.md#corners, "Corner end rule": a wall reaches as far towards the corner as
    its returns do, also beyond something in front of it (e.g. a leg), unless the returns it
    claims beyond its segment (on its line, not past the corner's tolerance, outside the corner
    zone) lie in front of its line together: their residuals over the noise sum to more than
    ``run_sigmas`` times the square root of their number, an object before the wall's end
    (their line was fitted without them, so the plain sum is already a deleted-residual test,
    as :func:`~.segmentation.trim_offset`'s). The facing ends are the wall's own.

    For every corner at once (for both walls at once when the wall's fields are (2, C)).

    :return: shape (C, W) ((2, C, W))
    """
    if rule.run_sigmas <= 0.0:
        return placed.on_line
    claimed = placed.on_line & (placed.along_m >= -wall.tolerance_m[..., None]) & ~at_corner
    claimed[..., 0] = claimed[..., -1] = False
    if not np.count_nonzero(claimed):            # the usual case: nothing claimed, no run
        return placed.on_line
    run = np.add.reduce(claimed, axis=-1)
    together = (np.add.reduce(np.where(claimed, placed.in_front_m / window.sigma_m, 0.0), axis=-1)
                / np.sqrt(np.maximum(run, 1)))
    return placed.on_line & ~(claimed & (together > rule.run_sigmas)[..., None])


def reaches(wall: WallAtCorner[FloatArray], placed: AlongWall, on_line: np.ndarray,
            at_corner: np.ndarray) -> np.ndarray:
    """
    Tell which returns of every end window the wall reaches: in the corner zone, or on its line.

    docs/derivation.md#corners, "Corner end rule": a return on the wall's line reaches the
    corner when it lies no farther past it than the wall's tolerance along it.

    For every corner at once (for both walls at once when the wall's fields are (2, C)).

    :return: shape (C, W) ((2, C, W))
    """
    return at_corner | (on_line & (placed.along_m >= -wall.tolerance_m[..., None]))


def goes_on(first: WallAtCorner[FloatArray], second: WallAtCorner[FloatArray],
            first_placed: AlongWall, second_placed: AlongWall, first_on_line: np.ndarray,
            second_on_line: np.ndarray, at_corner: np.ndarray) -> np.ndarray:
    """
    Tell at which corners a wall's line carries returns past the corner.

    docs/derivation.md#corners, "Corner end rule": a return on one wall's line alone, outside
    the corner zone, past the corner by more than that wall's tolerance along it.

    For every corner at once.

    :return: shape (C,)
    """
    first_past = (first_on_line & ~second_on_line
                  & (first_placed.along_m < -first.tolerance_m[:, None]))
    second_past = (second_on_line & ~first_on_line
                   & (second_placed.along_m < -second.tolerance_m[:, None]))
    return np.logical_or.reduce(~at_corner & (first_past | second_past), axis=1)


def blocked(window: EndWindow[IndexArray], first: WallAtCorner[FloatArray],
            second: WallAtCorner[FloatArray], first_placed: AlongWall, second_placed: AlongWall,
            first_here: np.ndarray, second_here: np.ndarray, at_corner: np.ndarray) -> np.ndarray:
    """
    Tell at which corners anything lies between the two walls' reaches.

    docs/derivation.md#corners, "Corner end rule". Each wall's anchor is its last own return
    short of the corner zone (its facing end if none). Between the anchors every return must be
    reached by a wall; outside them (beyond something in front of a wall, where its own returns
    go on) a return reached by neither is allowed only when it lies in front of both lines (an
    occluder); a return behind them is a view through a gap where the walls do not meet.

    For every corner at once.

    :return: shape (C,)
    """
    interrupts = window.in_window & ~first_here & ~second_here
    if not np.count_nonzero(interrupts):         # every return reached: nothing in between
        return np.zeros(at_corner.shape[0], dtype=bool)
    steps = np.arange(at_corner.shape[1])
    first_anchor = np.maximum.reduce(np.where(first_here & ~at_corner, steps, 0), axis=1)
    second_anchor = np.minimum.reduce(np.where(second_here & ~at_corner, steps, steps[-1]),
                                      axis=1)
    occluder = (window.in_window & (first_placed.in_front_m > window.line_tolerance_m)
                & (second_placed.in_front_m > window.line_tolerance_m))
    outside = (steps < first_anchor[:, None]) | (steps > second_anchor[:, None])
    return np.logical_or.reduce(interrupts & (~occluder | ~outside), axis=1)


def short_of_corner(wall: WallAtCorner[FloatArray], placed: AlongWall, on_line: np.ndarray,
                    here: np.ndarray) -> np.ndarray:
    """
    Return how far a wall's own returns stop short of each corner, in beams beyond its tolerance.

    docs/derivation.md#corners, "Corner end rule": the nearest return on its line that reaches
    the corner, its distance from the corner into the wall less the wall's tolerance along it,
    over the beam spacing there. More than ``1 + CORNER_MISSING_BEAMS``: the corner is an
    extrapolation across an unseen stretch; at most 1: the wall's end was seen.

    For every corner at once (for both walls at once when the wall's fields are (2, C)).

    :return: shape (C,) ((2, C); inf: none of its returns reaches the corner)
    """
    gap = np.minimum.reduce(np.where(on_line & here, np.maximum(placed.along_m, 0.0), np.inf),
                            axis=-1)
    return np.maximum(gap - wall.tolerance_m, 0.0) / wall.spacing_m


def seen_through(corner_x_m: np.ndarray, corner_y_m: np.ndarray, wall: WallAtCorner[FloatArray],
                 other: WallAtCorner[FloatArray], contour: Returns, start: np.ndarray,
                 stop: np.ndarray, noise: Noise, rule: CornerEndRule) -> np.ndarray:
    """
    Tell whether the other wall is seen through a wall between its segment and the corner.

    docs/derivation.md#corners, "Seen through". If the wall ended at the corner it would stand
    between them, and no line of sight could cross its line there to a return farther away.
    Returns on the other wall's line (within ``sigmas`` standard deviations of their position
    noise plus ``floor_m``) whose line of sight crosses this wall's line farther than its
    tolerance along it from the corner, into the wall, and not in front of it by more than
    that noise tolerance, are tested together like :func:`~.segmentation.trim_offset`'s runs:
    the sum of their distances behind the line over their noise, over the square root of their
    number, above ``run_sigmas`` means the other wall goes on behind this one's end (the end
    is an edge: a pilaster, a wardrobe, a door frame in front of a wall, whose line merely
    meets the wall behind). One return behind by a few sigma is noise or a rounded corner; a
    run of them is not.

    Every test at once: each test's stretch of returns laid end to end, each return labelled
    with its test, the sums per test by label.

    :param corner_x_m: x of each test's corner, shape (K,) (or a number for one test), m
    :param corner_y_m: y of each test's corner, shape (K,), m
    :param wall: the wall at each corner, each field shape (K,)
    :param other: the other wall of each corner
    :param contour: the returns in circular order
    :param start: position of each test's first return (taken modulo n), shape (K,)
    :param stop: position of its last return (taken modulo n, after ``start``), shape (K,)
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param rule: the rule's tolerances
    :return: whether each wall is seen through, shape (K,)
    """
    start, stop = np.atleast_1d(start), np.atleast_1d(stop)
    lengths = (stop - start) % len(contour.x_m) + 1
    test = np.arange(lengths.size).repeat(lengths)
    ends = np.add.accumulate(lengths)
    crossing = np.arange(ends[-1]) + (start - (ends - lengths)).repeat(lengths)
    # Every per-test number the crossing needs at every return of its test's stretch, in one
    # repeat (twice as fast as a take by ``test``).
    radius, normal_x, normal_y, inward_x, inward_y, tolerance, corner_x, corner_y = np.array(
        [wall.radius_m, wall.normal_x, wall.normal_y, wall.inward_x, wall.inward_y,
         wall.tolerance_m, corner_x_m, corner_y_m], dtype=float).reshape(8, -1).repeat(lengths,
                                                                                       axis=1)
    x, y = contour.x_m.take(crossing, mode='wrap'), contour.y_m.take(crossing, mode='wrap')
    offset = x * normal_x + y * normal_y
    with np.errstate(divide='ignore', invalid='ignore'):
        to_line = radius / offset
        along = (x * to_line - corner_x) * inward_x + (y * to_line - corner_y) * inward_y
        # Where the sight line crosses the wall is the test few returns pass (on 1080-beam room
        # scans 1 in 150): the others are asked of those alone.
        crosses = ((offset > 0.0) & (along > tolerance)).nonzero()[0]
        if not crosses.size:
            return np.zeros(lengths.size, dtype=bool)
        test, x, y = test[crosses], x[crosses], y[crosses]
        offset, radius = offset[crosses], radius[crosses]
        other_radius, other_normal_x, other_normal_y = np.array(
            [other.radius_m, other.normal_x, other.normal_y], dtype=float).reshape(3, -1).take(
                test, axis=1)
        sigma = np.sqrt(noise.deciding_sigma_m ** 2
                        + (x ** 2 + y ** 2) * noise.bearing_sigma_rad ** 2)
        line_tolerance = rule.sigmas * sigma + rule.floor_m
        on_other = np.abs(other_radius - x * other_normal_x - y * other_normal_y)
        tested = (on_other <= line_tolerance) & (radius - offset <= line_tolerance)
        run = np.bincount(test[tested], minlength=lengths.size)
        behind = np.bincount(test[tested], ((offset - radius) / sigma)[tested], lengths.size)
        return (run > 0) & (behind / np.sqrt(run) > rule.run_sigmas)


def dark_wall(corner_x_m: np.ndarray, corner_y_m: np.ndarray, first: WallAtCorner[FloatArray],
              second: WallAtCorner[FloatArray], contour: Returns, after_first: np.ndarray,
              before_second: np.ndarray, step_rad: float) -> np.ndarray:
    """
    Tell whether a run of beams without a return crosses where a wall would reach the corner.

    docs/derivation.md#corners, "Dark wall". Between the walls' facing ends every beam sees the
    first wall's line up to the corner's bearing and the second's beyond it, or something in
    front of them (an occluder hides a corner, it returns). A run of more than
    ``1 + CORNER_MISSING_BEAMS`` beams without a return (the contour holds none of them: out of
    the scan's range_min and range_max, inf, NaN) is a view through an opening when the stretch
    of the walls' lines those beams would have met (each beam as wide as the bearing step, the
    first wall's line before the corner's bearing, the second's after it) is longer than
    ``CORNER_DARK_WALL_M``: a wall a few metres away returns, a dark spot on it leaves a few
    centimetres unseen.

    For every corner at once.

    :param corner_x_m: x of each corner, shape (K,), m
    :param corner_y_m: y of each corner, shape (K,), m
    :param first: the first wall at each corner, each field shape (K,)
    :param second: the second wall
    :param contour: the returns in circular order
    :param after_first: position of each first wall's last return, shape (K,)
    :param before_second: position of each second wall's first return, shape (K,)
    :param step_rad: bearing step between beams, rad
    :return: whether a dark run crosses the walls' reach, shape (K,)
    """
    between = (before_second - after_first - 1) % len(contour.bearing_rad)
    steps = np.arange(between.max(initial=0) + 1)
    # Each gap from a return to the next one, from the first wall's facing end up to the
    # second's, as an angle from the earlier return.
    bearing = contour.bearing_rad.take(after_first[:, None] + np.append(steps, steps.size),
                                       mode='wrap')
    here = bearing[:, :-1]
    gap = _wrap(bearing[:, 1:] - here)
    width = np.abs(gap)
    dark = ((steps <= between[:, None])
            & (np.rint(width / step_rad) - 1.0 > 1.0 + CORNER_MISSING_BEAMS))
    if not np.count_nonzero(dark):          # the usual case: the lengths below are not needed
        return np.zeros(between.size, dtype=bool)
    sense = np.copysign(1.0, gap)
    to_apex = _wrap(np.arctan2(corner_y_m, corner_x_m)[:, None] - here) * sense
    low, high = 0.5 * step_rad, width - 0.5 * step_rad     # the missing beams' own widths
    with np.errstate(all='ignore'):
        unseen = (_along_line(first, here, sense, low, np.minimum(high, to_apex))
                  + _along_line(second, here, sense, np.maximum(low, to_apex), high))
    return np.logical_or.reduce(dark & (unseen > CORNER_DARK_WALL_M), axis=1)


def _wrap(angle_rad: np.ndarray) -> np.ndarray:
    """Return angles taken into [-pi, pi), rad."""
    return np.remainder(angle_rad + math.pi, 2.0 * math.pi) - math.pi


def _along_line(wall: WallAtCorner[FloatArray], bearing: np.ndarray, sense: np.ndarray,
                start: Union[float, np.ndarray], stop: Union[float, np.ndarray]) -> np.ndarray:
    """
    Return the length of a wall's line between two lines of sight (0 when they do not follow).

    The sight lines at ``bearing + sense * start`` and ``... * stop`` meet the line (unit normal
    n at angle alpha, distance rho) at rho tan(phi - alpha) along it.

    :param wall: the wall, each field shape (K,)
    :param bearing: where each angle is measured from, shape (K, G), rad
    :param sense: the direction the angles turn, +-1, shape (K, G)
    :param start: the first sight line's angle from ``bearing`` (a number or shape (K, G)), rad
    :param stop: the second's, rad
    :return: shape (K, G), m
    """
    normal_x, normal_y = wall.normal_x[:, None], wall.normal_y[:, None]
    near, far = bearing + sense * start, bearing + sense * stop
    near_along = ((np.sin(near) * normal_x - np.cos(near) * normal_y)
                  / (np.cos(near) * normal_x + np.sin(near) * normal_y))
    far_along = ((np.sin(far) * normal_x - np.cos(far) * normal_y)
                 / (np.cos(far) * normal_x + np.sin(far) * normal_y))
    return np.where(stop > start, wall.radius_m[:, None] * np.abs(far_along - near_along), 0.0)


def walls_end_at(candidates: CornerCandidates, walls: SegmentSet, positions: np.ndarray,
                 contour: Returns, step_rad: float, noise: Noise, rule: CornerEndRule):
    """
    Tell which corners both walls end at, and at which the end was seen.

    docs/derivation.md#corners, "Corner end rule" and "Seen through". A corner is the point
    where two walls end; adjacent segments whose lines merely intersect near their ends (across
    an occlusion, a gap, a T-junction seen from the side where one wall goes on) are not
    corners. The returns between the first wall's last return and the second wall's first one
    (:func:`end_window`) are sorted by where they lie: on one of the two lines
    (:func:`along_wall`), around the corner (:func:`corner_zone`), in front of both lines (an
    occluder) or elsewhere; each wall reaches as far towards the corner as its returns do
    (:func:`reaches`), also beyond something in front of it, unless those returns lie in front
    of its line together (:func:`without_object_in_front`). The corner is rejected when

    - more than ``rule.window`` returns lie between the walls: they are not neighbours;
    - a facing end does not reach the corner;
    - a wall's line carries returns past the corner (:func:`goes_on`);
    - anything lies between the two reaches (:func:`blocked`);
    - a wall's reach stops short of the corner by more than ``1 + CORNER_MISSING_BEAMS`` beams
      beyond its tolerance (:func:`short_of_corner`): an extrapolation across an unseen stretch;
    - a wall is seen through where it would have to stand (:func:`seen_through`, when
      ``rule.run_sigmas`` > 0): the other wall goes on behind this wall's end, an edge in
      front of it, not a corner.
    - a run of beams without a return crosses where the walls would reach the corner
      (:func:`dark_wall`): a view through an opening between them.

    A wall's end is seen when its reach is within one beam's spacing of that bound.

    Each step over every candidate corner at once, the dark-wall and seen-through tests over
    the corners left.

    :param candidates: candidate corners
    :param walls: the walls
    :param positions: positions of every wall's first and last return, shape (2, S)
    :param contour: the returns in circular order
    :param step_rad: bearing step between beams, rad
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param rule: the rule's tolerances
    :return: (corners both walls end at, shape (C,); whether each wall's end was seen, shape
        (C, 2), column 0 the first wall)
    """
    one, two = candidates.first_wall, candidates.second_wall
    first_position, last_position = positions
    after_first, before_second = last_position[one], first_position[two]
    corner_x, corner_y = candidates.xy_m[:, 0], candidates.xy_m[:, 1]
    # The windows only as wide as the most returns between two walls (at most rule.window): the
    # columns past every corner's own returns are in none of its windows, and a window's facing
    # ends are its first and last columns at any width (on 1080-beam room scans 11 columns of
    # 42, on the LMS111 scans 23).
    widest = int(((before_second - after_first - 1) % len(contour.x_m)).max(initial=0))
    window = end_window(contour, after_first, before_second, noise,
                        rule._replace(window=min(widest, rule.window)))
    # Both walls of every corner at once where a step takes one wall: row 0 of every field
    # the first wall's, row 1 the second's.
    both = wall_at_corner(walls, np.array([one, two]), candidates.xy_m, candidates.covariance,
                          step_rad, rule)
    first, second = _row(both, 0), _row(both, 1)
    placed = along_wall(window, both, corner_x, corner_y)
    first_placed, second_placed = _row(placed, 0), _row(placed, 1)
    at_corner = corner_zone(window, corner_x, corner_y, first, second, noise, rule)
    on_line = without_object_in_front(window, both, placed, at_corner, rule)
    here = reaches(both, placed, on_line, at_corner)
    short = short_of_corner(both, placed, on_line, here)
    keep = ((window.between <= rule.window) & here[0, :, 0] & here[1, :, -1]
            & ~goes_on(first, second, first_placed, second_placed, on_line[0], on_line[1],
                       at_corner)
            & ~blocked(window, first, second, first_placed, second_placed, here[0], here[1],
                       at_corner)
            & (short[0] <= 1.0 + CORNER_MISSING_BEAMS)
            & (short[1] <= 1.0 + CORNER_MISSING_BEAMS))
    kept = keep.nonzero()[0]
    if not kept.size:
        return keep, np.ascontiguousarray((short <= 1.0).T)
    every_field = np.array(both)                 # (8, 2, C): both walls' fields, as rows
    fields = every_field.take(kept, axis=2)
    keep[kept] = ~dark_wall(corner_x[kept], corner_y[kept], WallAtCorner(*fields[:, 0]),
                            WallAtCorner(*fields[:, 1]), contour, after_first[kept],
                            before_second[kept], step_rad)
    kept = keep.nonzero()[0]
    if rule.run_sigmas > 0.0 and kept.size:
        # The first wall's stretch is crossed by the sight lines after its last return up to the
        # second wall's last; the second's by those from the first wall's first return up to
        # its own first: both tests of every corner left, in one call, the first walls' first.
        fields = every_field.take(kept, axis=2)
        twice = np.concatenate((kept, kept))
        seen = seen_through(
            corner_x[twice], corner_y[twice], WallAtCorner(*fields.reshape(8, -1)),
            WallAtCorner(*fields[:, ::-1].reshape(8, -1)), contour,
            np.concatenate([after_first[kept] + 1, first_position[one[kept]]]),
            np.concatenate([last_position[two[kept]], before_second[kept] - 1]), noise, rule)
        keep[kept] = ~(seen[:kept.size] | seen[kept.size:])
    return keep, np.ascontiguousarray((short <= 1.0).T)


def _row(record, row: int):
    """Return one wall's record from one holding both walls' rows."""
    return type(record)(*(field[row] for field in record))
