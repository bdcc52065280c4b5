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
from typing import Optional

import numpy as np

from ..features import CornerSet

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
    both walls really end at the intersection is :func:`walls_end_at_corners`' question.

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
    :return: the corners that pass both tests
    """
    pairs = np.array([first, second, first], dtype=np.intp)        # first again: see _solve
    walls = pairs[:2]
    lines = line.T.take(pairs, 1)
    start, end = start_xy_m.T.take(walls, 1), end_xy_m.T.take(walls, 1)
    covariance = line_covariance.reshape(-1, 9).T.take(walls, 1)
    # Nearly parallel lines meet at inf / NaN: such pairs are carried along with the others and
    # dropped with the rest of the rejected ones at the end.
    with np.errstate(all='ignore'):
        x, y, u, w = _solve(lines[0], lines[1], lines[2])
        a, b = lines[0, :2], lines[1, :2]
        norm = np.hypot(a, b)
        normal_x, normal_y = a / norm, b / norm
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

        # Joint covariance of (x, y, yaw): line k moves the position by -A^-1 e_k h^T dL_k and
        # the yaw by g_k^T dL_k, so three quadratic forms of each C_k are all that is needed.
        # Here g_k = (-gradient_x, gradient_y, 0).
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
        if common_range_sigma_m > 0.0 and line_offset_jacobian is not None:
            offset_a, offset_b, offset_c = line_offset_jacobian.T.take(walls, 1)
            offset_along_h = x * offset_a + y * offset_b + offset_c
            # Each wall's share of -j = -sum_k (-A^-1 e_k h^T, g_k^T) dL_k / d offset (the sign
            # drops out of j j^T).
            shift = np.array([u * offset_along_h, -(w * offset_along_h),
                              gradient_x * offset_a - gradient_y * offset_b])
            common = common_range_sigma_m * (shift[:, 0] + shift[:, 1])
            upper += common[_UPPER_ROW] * common[_UPPER_COLUMN]
    covariance = upper.take(kept, 1).T.take(_UPPER_TO_FULL, 1).reshape(-1, 3, 3)
    return CornerSet(np.array([x[0], y[0]]).T.take(kept, 0), yaw[kept], covariance,
                     opening[kept], walls[0][kept], walls[1][kept],
                     np.ones((kept.size, 2), dtype=bool))


def _wrapped(angle: np.ndarray) -> np.ndarray:
    """Return angles wrapped to [-pi, pi)."""
    return np.remainder(angle + np.pi, 2.0 * np.pi) - np.pi


def walls_end_at_corners(corners: CornerSet, wall_angle_rad: np.ndarray,
                         wall_radius_m: np.ndarray, wall_middle_m: np.ndarray,
                         x_m: np.ndarray, y_m: np.ndarray, last_position: np.ndarray,
                         first_position: np.ndarray, step_rad: float, range_sigma_m: float,
                         bearing_sigma_rad: float, sigmas: float, floor_m: float, window: int,
                         max_missing_beams: int, run_sigmas: float):
    """
    Tell which corners both walls end at, and at which the end was seen.

    A corner is the point where two walls end; adjacent segments whose lines merely intersect
    near their ends (across an occlusion, a gap, a T-junction seen from the side where one wall
    goes on) are not corners. The returns between the first wall's last return and the second
    wall's first one (left out of both segments) are sorted by where they lie: on one of the
    two lines (within ``sigmas`` standard deviations of a return's position noise plus
    ``floor_m``), around the corner (where both lines are within the noise of each other, and
    a beam's footprint on both walls returns a range in between: an inside corner looks
    rounded), in front of both lines (an occluder) or elsewhere. Each wall reaches as far
    towards the corner as its returns do, also beyond something in front of it (e.g. a leg),
    unless those returns lie in front of its line together (their residuals over the noise sum
    to more than ``run_sigmas`` times the square root of their number, the test of
    :func:`trim_offset_ends`): an object before the wall's end.
    The corner is rejected when

    - a wall's line carries returns past the corner: the wall goes on, it does not end there;
    - anything lies between the two reaches: an occluder at the corner, or a view through a
      gap where the walls do not meet;
    - a wall's reach stops short of the corner by more than ``sigmas`` standard deviations of
      the corner's position along that wall, plus ``floor_m``, plus ``1 + max_missing_beams``
      beams' spacing on the wall: the corner is an extrapolation across an unseen stretch;
    - a wall is seen through where it would have to stand (:func:`_seen_through`).

    A wall's end is seen when its reach is within one beam's spacing of that bound.

    :param corners: candidate corners
    :param wall_angle_rad: normal angle of every segment's line, shape (S,), rad
    :param wall_radius_m: radius of every segment's line, shape (S,), m
    :param wall_middle_m: middle of every segment, shape (S, 2), m (tells its side of a corner)
    :param x_m: x of the returns in position order, shape (n,), m
    :param y_m: y of the returns in position order, shape (n,), m
    :param last_position: position of every segment's last return, shape (S,)
    :param first_position: position of every segment's first return, shape (S,)
    :param step_rad: bearing step between beams, rad
    :param range_sigma_m: range noise std, m
    :param bearing_sigma_rad: bearing noise std, rad
    :param sigmas: tolerance in standard deviations
    :param floor_m: tolerance floor, m
    :param window: most returns between the two walls (more: not adjacent)
    :param max_missing_beams: most beams without a return between a corner and a wall's reach
    :param run_sigmas: largest sum of normalised residuals (in front) over sqrt(count) of the
        returns a wall claims beyond its segment (0: no such test)
    :return: (corners both walls end at, shape (C,); whether each wall's end was seen, shape
        (C, 2), column 0 the first wall)
    """
    count = len(x_m)
    walls = np.stack([corners.first_segment, corners.second_segment])        # (2, C)
    after_first, before_second = last_position[walls[0]], first_position[walls[1]]
    between = (before_second - after_first - 1) % count
    # Column 0 is the first wall's facing end, the last column the second's; between them the
    # returns that belong to neither segment (absent where there are fewer).
    steps = np.arange(window + 2)
    position = after_first[:, None] + steps
    position[:, -1] = before_second
    present = (steps <= between[:, None]) | (steps == window + 1)
    x, y = x_m.take(position, mode='wrap'), y_m.take(position, mode='wrap')
    corner = corners.xy_m.T[:, :, None]                                     # (2, C, 1)
    corner_range = np.hypot(*corners.xy_m.T)
    noise = np.sqrt(range_sigma_m ** 2 + (x * x + y * y) * bearing_sigma_rad ** 2)
    line_tolerance = sigmas * noise + floor_m
    # Per wall: its unit normal and the unit direction from the corner into the wall.
    normal = np.stack([np.cos(wall_angle_rad[walls]), np.sin(wall_angle_rad[walls])])
    inward = np.stack([-normal[1], normal[0]])                              # (2, 2, C)
    towards_middle = ((wall_middle_m[walls].transpose(2, 0, 1) - corner[:, None, :, 0])
                      * inward).sum(axis=0)
    inward *= np.copysign(1.0, towards_middle)
    # Each return's offset in front of each line (towards the sensor) and along each wall.
    offset = x * normal[0, :, :, None] + y * normal[1, :, :, None]
    in_front = wall_radius_m[walls][:, :, None] - offset                   # (2, C, W)
    along = ((x - corner[0]) * inward[0, :, :, None]
             + (y - corner[1]) * inward[1, :, :, None])                     # (2, C, W)
    on_line = present & (np.abs(in_front) <= line_tolerance)
    occluder = present & (in_front > line_tolerance).all(axis=0)
    # The corner's std along each wall, and how far apart the wall's returns are there.
    along_sigma = np.sqrt(np.einsum('ikc,cij,jkc->kc', inward, corners.covariance[:, :2, :2],
                                    inward))
    incidence = np.abs((normal * corners.xy_m.T[:, None, :]).sum(axis=0)) / corner_range
    spacing = corner_range * step_rad / np.maximum(incidence, 1e-3)
    tolerance = sigmas * along_sigma + floor_m                              # (2, C)
    # Returns this close to the corner belong to either wall (the lines are within the noise
    # of each other there, and within a beam a footprint on both walls returns a range in
    # between).
    sine = np.abs(normal[0, 0] * normal[1, 1] - normal[1, 0] * normal[0, 1])
    corner_noise = np.sqrt(range_sigma_m ** 2 + (corner_range * bearing_sigma_rad) ** 2)
    zone = (sigmas * np.hypot(corner_noise, along_sigma.max(axis=0)) / sine + floor_m
            + spacing.min(axis=0))
    at_corner = present & (np.hypot(x - corner[0], y - corner[1]) <= zone[:, None])
    # Returns away from the corner that a wall claims beyond its segment (past something in
    # front of it) must not lie in front of its line together, by the test of
    # trim_offset_ends: a run of returns each within the noise of the line but all nearer is
    # an object standing before the wall. (All farther is the wall itself, a few mm off
    # straight.)
    claimed = on_line & (along >= -tolerance[:, :, None]) & ~at_corner
    claimed[:, :, 0] = claimed[:, :, -1] = False
    run = claimed.sum(axis=2)
    together = np.where(claimed, in_front / noise, 0.0).sum(axis=2) / np.sqrt(np.maximum(run, 1))
    if run_sigmas > 0.0:
        claimed &= (together > run_sigmas)[:, :, None]
        on_line &= ~claimed
    here = at_corner | (on_line & (along >= -tolerance[:, :, None]))        # (2, C, W)
    goes_on = (~at_corner & on_line & ~on_line[::-1]
               & (along < -tolerance[:, :, None])).any(axis=(0, 2))
    # Each wall's anchor: its last own return short of the corner zone (the facing end if
    # none). Beyond something in front of a wall its own returns may go on; around the corner
    # itself nothing may interrupt the run from one wall to the other.
    own = on_line & (along >= -tolerance[:, :, None]) & ~at_corner
    first_anchor = np.where(own[0], steps, 0).max(axis=1)
    second_anchor = np.where(own[1], steps, window + 1).min(axis=1)
    interrupts = present & ~here[0] & ~here[1]
    before_first = steps < first_anchor[:, None]
    after_second = steps > second_anchor[:, None]
    blocked = ((interrupts & ~occluder & (before_first | after_second))
               | (interrupts & ~before_first & ~after_second)).any(axis=1)
    # How far each wall's own returns stop short of the corner, beyond the tolerance, in beams.
    gap = np.where(on_line & here, np.maximum(along, 0.0), np.inf).min(axis=2)
    short = np.maximum(gap - tolerance, 0.0) / spacing
    keep = ((between <= window) & here[0, :, 0] & here[1, :, -1] & ~goes_on & ~blocked
            & (short <= 1.0 + max_missing_beams).all(axis=0))
    if run_sigmas > 0.0:
        # Wall 0's stretch is crossed by the sight lines after its last return up to wall 1's
        # last; wall 1's by those from wall 0's first return up to its own first.
        spans = ((after_first + 1, last_position[walls[1]]),
                 (first_position[walls[0]], before_second - 1))
        for c in np.flatnonzero(keep):
            for k, (start, stop) in enumerate(spans):
                crossing = np.arange(start[c], start[c] + (stop[c] - start[c]) % count + 1)
                if _seen_through(corners.xy_m[c], normal[:, k, c], wall_radius_m[walls[k, c]],
                                 inward[:, k, c], tolerance[k, c], normal[:, 1 - k, c],
                                 wall_radius_m[walls[1 - k, c]],
                                 x_m.take(crossing, mode='wrap'), y_m.take(crossing, mode='wrap'),
                                 range_sigma_m, bearing_sigma_rad, sigmas, floor_m, run_sigmas):
                    keep[c] = False
    return keep, (short <= 1.0).T


def _seen_through(corner_xy_m: np.ndarray, normal: np.ndarray, radius_m: float,
                  inward: np.ndarray, along_tolerance_m: float, other_normal: np.ndarray,
                  other_radius_m: float, x_m: np.ndarray, y_m: np.ndarray, range_sigma_m: float,
                  bearing_sigma_rad: float, sigmas: float, floor_m: float,
                  run_sigmas: float) -> bool:
    """
    Tell whether the other wall is seen through a wall between its segment and the corner.

    The returns on the other wall's line whose sight lines cross this wall's line farther than
    ``along_tolerance_m`` into the wall (and that are not in front of it beyond the noise) lie
    behind it together: sum of (distance behind / noise) over sqrt(count) > ``run_sigmas``.

    :param corner_xy_m: the corner, shape (2,), m
    :param normal: the wall's unit normal, shape (2,)
    :param radius_m: the wall's radius, m
    :param inward: unit direction from the corner into the wall, shape (2,)
    :param along_tolerance_m: how far from the corner a crossing is surely on the wall, m
    :param other_normal: the other wall's unit normal, shape (2,)
    :param other_radius_m: the other wall's radius, m
    :param x_m: x of the returns whose sight lines may cross, shape (m,), m
    :param y_m: y of those returns, shape (m,), m
    :param range_sigma_m: range noise std, m
    :param bearing_sigma_rad: bearing noise std, rad
    :param sigmas: tolerance in standard deviations
    :param floor_m: tolerance floor, m
    :param run_sigmas: largest sum of normalised residuals (behind) over sqrt(count)
    :return: whether the wall is seen through
    """
    noise = np.sqrt(range_sigma_m ** 2 + (x_m ** 2 + y_m ** 2) * bearing_sigma_rad ** 2)
    line_tolerance = sigmas * noise + floor_m
    offset = x_m * normal[0] + y_m * normal[1]
    on_other = np.abs(other_radius_m - x_m * other_normal[0] - y_m * other_normal[1])
    with np.errstate(divide='ignore', invalid='ignore'):
        crossing = np.column_stack([x_m, y_m]) * (radius_m / offset)[:, None]
    along = (crossing - corner_xy_m) @ inward
    tested = ((on_other <= line_tolerance) & (offset > 0.0)
              & (radius_m - offset <= line_tolerance) & (along > along_tolerance_m))
    run = np.count_nonzero(tested)
    return bool(run) and ((offset - radius_m)[tested] / noise[tested]).sum() / np.sqrt(run) > (
        run_sigmas)
