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
from typing import Optional

import numpy as np

from ._jit import jit
from ._order import wrapped
from ..features import CornerSet

# A corner may sit one beam without a return beyond a wall's last return (a dropout there),
# reported with that wall's end not seen; farther, it is an extrapolation, not a corner.
CORNER_MISSING_BEAMS = 1


def intersect(line_a: np.ndarray, cov_a: np.ndarray, line_b: np.ndarray,
              cov_b: np.ndarray):
    """
    Intersect pairs of lines and propagate their full covariances to the position.

    :param line_a: (a, b, c) of the first lines, shape (C, 3)
    :param cov_a: their covariances, shape (C, 3, 3)
    :param line_b: (a, b, c) of the second lines, shape (C, 3)
    :param cov_b: their covariances, shape (C, 3, 3)
    :return: (position (C, 2) m, covariance (C, 2, 2) m^2, position Jacobians w.r.t. line_a
        and line_b, each (C, 2, 3): -A^-1 e_k h^T with h = (x, y, 1))
    """
    count = len(line_a)
    line = np.concatenate([line_a, line_b]).astype(float)
    pairs = np.arange(count)
    with np.errstate(all='ignore'):
        _, xy, _, covariance, _ = corner_candidates(
            line, np.concatenate([cov_a, cov_b]).astype(float), np.zeros((2 * count, 2)),
            np.zeros((2 * count, 2)), pairs, pairs + count, -1.0, np.zeros_like(line), 0.0)
        inverse = np.linalg.inv(np.stack([line[:count, :2], line[count:, :2]], axis=1))
    h = np.column_stack([xy, np.ones(count)])
    return (xy, covariance[:, :2, :2], -inverse[:, :, :1] * h[:, None, :],
            -inverse[:, :, 1:] * h[:, None, :])


def find_corners(line: np.ndarray, line_covariance: np.ndarray,
                 start_xy_m: np.ndarray, end_xy_m: np.ndarray, first: np.ndarray,
                 second: np.ndarray, min_angle_rad: float,
                 line_offset_jacobian: Optional[np.ndarray] = None,
                 common_range_sigma_m: float = 0.0) -> CornerSet:
    """
    Intersect the given pairs of segments that are not close to parallel.

    A pair is rejected when its lines are closer to parallel than ``min_angle_rad``; whether
    both walls really end at the intersection is :func:`walls_end_at`'s question.

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
    :return: the corners that pass the test
    """
    line = np.asarray(line, dtype=float)
    first, second = np.asarray(first, dtype=np.intp), np.asarray(second, dtype=np.intp)
    offset = (np.zeros_like(line) if line_offset_jacobian is None
              else np.asarray(line_offset_jacobian, dtype=float))
    with np.errstate(all='ignore'):
        kept, xy, yaw, covariance, opening = corner_candidates(
            line, np.asarray(line_covariance, dtype=float), np.asarray(start_xy_m, dtype=float),
            np.asarray(end_xy_m, dtype=float), first, second, float(min_angle_rad), offset,
            float(common_range_sigma_m))
    return CornerSet(xy, yaw, covariance, opening, first[kept], second[kept],
                     np.ones((kept.size, 2), dtype=bool))


# The upper triangle of the symmetric (x, y, yaw) covariance, row by row: (row, column) of each
# of its six entries.
_UPPER_ROWS = (0, 0, 0, 1, 1, 2)
_UPPER_COLUMNS = (0, 1, 2, 1, 2, 2)


@jit
def corner_candidates(line, line_covariance, start_xy_m, end_xy_m, first, second, min_angle_rad,
                      line_offset_jacobian, common_range_sigma_m):
    """
    Intersect pairs of walls that are not close to parallel.

    Whether both walls really end at the intersection is :func:`walls_end_at`'s question.

    For each pair: the corner z = -A^-1 (c_1, c_2) (the paper's eqs. (24)-(25)), the bisector's
    yaw towards the open side the sensor sees, the opening angle, and the joint covariance of
    (x, y, yaw) of (D11)-(D14): sum_k J_k C_k J_k^T with dz/dL_k = -A^-1 e_k h^T, h = (x, y, 1),
    d yaw / dL_k = g_k = (-b_k, a_k, 0) / (2 (a_k^2 + b_k^2)); plus sigma^2 j j^T for the range
    offset common to the scan, j = sum_k J_k dL_k / d offset ((D15)-(D16)).

    :param line: (a, b, c) of every wall, shape (S, 3)
    :param line_covariance: covariance of (a, b, c), shape (S, 3, 3)
    :param start_xy_m: first return of each wall projected on its line, shape (S, 2), m
    :param end_xy_m: last return projected on its line, shape (S, 2), m
    :param first: earlier wall of each pair, shape (k,)
    :param second: later wall of each pair, shape (k,)
    :param min_angle_rad: smallest angle between the two walls, rad
    :param line_offset_jacobian: d(a, b, c) / d(common range offset), shape (S, 3), per m
    :param common_range_sigma_m: std of that common offset, m
    :return: (which pairs passed (C,), position (C, 2) m, yaw (C,) rad, covariance of (x, y,
        yaw) (C, 3, 3), opening angle (C,) rad)
    """
    pairs = first.size
    kept = np.empty(pairs, np.intp)
    xy = np.empty((pairs, 2))
    yaw = np.empty(pairs)
    covariance = np.empty((pairs, 3, 3))
    opening = np.empty(pairs)
    found = 0
    min_sine = math.sin(min_angle_rad)
    walls = np.empty(2, np.intp)
    u, w = np.empty(2), np.empty(2)
    normal_x, normal_y, norm = np.empty(2), np.empty(2), np.empty(2)
    direction_x, direction_y = np.empty(2), np.empty(2)
    upper = np.empty(6)
    common = np.empty(3)
    for p in range(pairs):
        walls[0], walls[1] = first[p], second[p]
        one, two = line[walls[0]], line[walls[1]]
        det = one[0] * two[1] - two[0] * one[1]
        inv_det = 1.0 / det
        x = (one[1] * two[2] - two[1] * one[2]) * inv_det
        y = (two[0] * one[2] - one[0] * two[2]) * inv_det
        # A^-1 e_k = (u_k, -w_k): the partner's b and a over the determinant of the row whose
        # own line is k (the second row's is -det).
        u[0], w[0] = two[1] * inv_det, two[0] * inv_det
        u[1], w[1] = one[1] * (1.0 / -det), one[0] * (1.0 / -det)
        for k in range(2):
            a, b = line[walls[k], 0], line[walls[k], 1]
            norm[k] = math.hypot(a, b)
            normal_x[k], normal_y[k] = a / norm[k], b / norm[k]
        sine = abs(normal_x[0] * normal_y[1] - normal_y[0] * normal_x[1])
        if not sine >= min_sine:
            continue
        # Unit vectors from the corner along each wall, towards the middle of its returns,
        # held as (-x, y).
        for k in range(2):
            wall = walls[k]
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
        kept[found] = p
        xy[found, 0], xy[found, 1] = x, y
        yaw[found] = math.atan2(bisector_y * toward_sensor, bisector_x * -toward_sensor)
        opening[found] = between if concave else 2.0 * np.pi - between
        # Three quadratic forms of each C_k: h^T C h, g^T C h, g^T C g (g = (-gx, gy, 0)).
        upper[:] = 0.0
        common[:] = 0.0
        for k in range(2):
            c = line_covariance[walls[k]]
            half_inv_norm = 0.5 / norm[k]
            gradient_x, gradient_y = normal_y[k] * half_inv_norm, normal_x[k] * half_inv_norm
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
                offset = line_offset_jacobian[walls[k]]
                offset_along_h = x * offset[0] + y * offset[1] + offset[2]
                common[0] += u[k] * offset_along_h
                common[1] += -(w[k] * offset_along_h)
                common[2] += gradient_x * offset[0] - gradient_y * offset[1]
        upper[1] = -upper[1]
        upper[4] = -upper[4]
        if common_range_sigma_m > 0.0:
            for entry in range(6):
                upper[entry] += (common_range_sigma_m * common[_UPPER_ROWS[entry]]
                                 * (common_range_sigma_m * common[_UPPER_COLUMNS[entry]]))
        for entry in range(6):
            row, column = _UPPER_ROWS[entry], _UPPER_COLUMNS[entry]
            covariance[found, row, column] = covariance[found, column, row] = upper[entry]
        found += 1
    return kept[:found], xy[:found], yaw[:found], covariance[:found], opening[:found]


@jit
def seen_through(corner_x_m, corner_y_m, normal_x, normal_y, radius_m, inward_x, inward_y,
                 along_tolerance_m, other_normal_x, other_normal_y, other_radius_m, x_m, y_m,
                 start, stop, range_sigma_m, bearing_sigma_rad, sigmas, floor_m, run_sigmas):
    """
    Tell whether the other wall is seen through a wall's stretch between its segment and a corner.

    If the wall ended at the corner it would stand between them, and no line of sight could
    cross its line there to a return farther away. Returns on the other wall's line (within
    ``sigmas`` standard deviations of their position noise plus ``floor_m``) whose line of
    sight crosses this wall's line farther than ``along_tolerance_m`` from the corner, into
    the wall, and not in front of it by more than that noise tolerance, are tested together
    like :func:`~.segmentation.trim_offset`'s runs: the sum of their distances behind the line
    over their noise, over the square root of their number, above ``run_sigmas`` means the
    other wall goes on behind this one's end (the end is an edge: a pilaster, a wardrobe, a
    door frame in front of a wall, whose line merely meets the wall behind). One return
    behind by a few sigma is noise or a rounded corner; a run of them is not.

    :param corner_x_m: x of the corner, m
    :param corner_y_m: y of the corner, m
    :param normal_x: x of the wall's unit normal (towards its line from the sensor)
    :param normal_y: y of the wall's unit normal
    :param radius_m: the wall's radius, m (>= 0)
    :param inward_x: x of the unit direction from the corner into the wall
    :param inward_y: y of that direction
    :param along_tolerance_m: how far from the corner a crossing is surely on the wall, m
    :param other_normal_x: x of the other wall's unit normal
    :param other_normal_y: y of the other wall's unit normal
    :param other_radius_m: the other wall's radius, m
    :param x_m: x of the returns in position order, shape (n,), m
    :param y_m: y of the returns in position order, shape (n,), m
    :param start: position of the first return to test (taken modulo n)
    :param stop: position of the last return to test (taken modulo n, after ``start``)
    :param range_sigma_m: range noise std, m
    :param bearing_sigma_rad: bearing noise std, rad
    :param sigmas: tolerance in standard deviations
    :param floor_m: tolerance floor, m
    :param run_sigmas: largest sum of normalised residuals (behind) over sqrt(count)
    :return: whether the wall is seen through
    """
    count = x_m.size
    run, behind = 0, 0.0
    for step in range((stop - start) % count + 1):
        position = wrapped(start + step, count)
        x, y = x_m[position], y_m[position]
        noise = math.sqrt(range_sigma_m ** 2 + (x * x + y * y) * bearing_sigma_rad ** 2)
        line_tolerance = sigmas * noise + floor_m
        offset = x * normal_x + y * normal_y
        if (abs(other_radius_m - x * other_normal_x - y * other_normal_y) > line_tolerance
                or offset <= 0.0 or radius_m - offset > line_tolerance):
            continue
        # Where the line of sight crosses the wall's line: the return scaled by radius/offset.
        scale = radius_m / offset
        along = ((scale * x - corner_x_m) * inward_x + (scale * y - corner_y_m) * inward_y)
        if along > along_tolerance_m:
            run += 1
            behind += (offset - radius_m) / noise
    return run > 0 and behind / math.sqrt(run) > run_sigmas


@jit
def walls_end_at(candidates, walls, contour, step_rad, noise, rule):
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
    to more than ``run_sigmas`` times the square root of their number): an object before the
    wall's end.
    The corner is rejected when

    - a wall's line carries returns past the corner: the wall goes on, it does not end there;
    - anything lies between the two reaches: an occluder at the corner, or a view through a
      gap where the walls do not meet;
    - a wall's reach stops short of the corner by more than ``sigmas`` standard deviations of
      the corner's position along that wall, plus ``floor_m``, plus ``1 + max_missing_beams``
      beams' spacing on the wall: the corner is an extrapolation across an unseen stretch;
    - a wall is seen through where it would have to stand (:func:`seen_through`): the other
      wall goes on behind this wall's end, an edge in front of it, not a corner.

    A wall's end is seen when its reach is within one beam's spacing of that bound.

    :param candidates: the candidate corners
    :param walls: the walls (their middles tell their side of a corner)
    :param contour: the returns in circular order
    :param step_rad: bearing step between beams, rad
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param rule: the rule's tolerances (``sigmas``, ``floor_m``, ``window``, ``run_sigmas``: the
        largest sum of normalised residuals (in front) over sqrt(count) of the returns a wall
        claims beyond its segment, 0: no such test); at most ``CORNER_MISSING_BEAMS`` beams
        without a return lie between a corner and a wall's reach
    :return: (corners both walls end at (C,), whether each wall's end was seen (C, 2), column 0
        the first wall)
    """
    corner_xy_m, corner_covariance = candidates.xy_m, candidates.covariance
    first_segment, second_segment = candidates.first_wall, candidates.second_wall
    wall_angle_rad, wall_radius_m = walls.angle_rad, walls.radius_m
    wall_middle_m = 0.5 * (walls.start_xy_m + walls.end_xy_m)
    x_m, y_m = contour.x_m, contour.y_m
    last_position, first_position = walls.last_position, walls.first_position
    range_sigma_m, bearing_sigma_rad = noise.deciding_sigma_m, noise.bearing_sigma_rad
    sigmas, floor_m, window, run_sigmas = rule.sigmas, rule.floor_m, rule.window, rule.run_sigmas
    max_missing_beams = CORNER_MISSING_BEAMS
    corners, count, width = corner_xy_m.shape[0], x_m.size, window + 2
    keep = np.zeros(corners, np.bool_)
    seen = np.zeros((corners, 2), np.bool_)
    present = np.empty(width, np.bool_)
    x, y, noise = np.empty(width), np.empty(width), np.empty(width)
    line_tolerance = np.empty(width)
    in_front, along = np.empty((2, width)), np.empty((2, width))
    on_line, here = np.empty((2, width), np.bool_), np.empty((2, width), np.bool_)
    at_corner = np.empty(width, np.bool_)
    normal, inward = np.empty((2, 2)), np.empty((2, 2))
    along_sigma, spacing, tolerance = np.empty(2), np.empty(2), np.empty(2)
    walls = np.empty(2, np.intp)
    for c in range(corners):
        walls[0], walls[1] = first_segment[c], second_segment[c]
        after_first, before_second = last_position[walls[0]], first_position[walls[1]]
        between = (before_second - after_first - 1) % count
        corner_x, corner_y = corner_xy_m[c, 0], corner_xy_m[c, 1]
        corner_range = math.hypot(corner_x, corner_y)
        # Column 0 is the first wall's facing end, the last column the second's; between them
        # the returns that belong to neither segment (absent where there are fewer).
        for s in range(width):
            position = before_second if s == width - 1 else after_first + s
            present[s] = s <= between or s == width - 1
            position = wrapped(position, count)
            x[s], y[s] = x_m[position], y_m[position]
            noise[s] = math.sqrt(range_sigma_m ** 2 + (x[s] * x[s] + y[s] * y[s])
                                 * bearing_sigma_rad ** 2)
            line_tolerance[s] = sigmas * noise[s] + floor_m
        for k in range(2):
            wall = walls[k]
            normal[k, 0] = math.cos(wall_angle_rad[wall])
            normal[k, 1] = math.sin(wall_angle_rad[wall])
            inward[k, 0], inward[k, 1] = -normal[k, 1], normal[k, 0]
            towards_middle = ((wall_middle_m[wall, 0] - corner_x) * inward[k, 0]
                              + (wall_middle_m[wall, 1] - corner_y) * inward[k, 1])
            side = math.copysign(1.0, towards_middle)
            inward[k, 0] *= side
            inward[k, 1] *= side
            for s in range(width):
                offset = x[s] * normal[k, 0] + y[s] * normal[k, 1]
                in_front[k, s] = wall_radius_m[wall] - offset
                along[k, s] = (x[s] - corner_x) * inward[k, 0] + (y[s] - corner_y) * inward[k, 1]
                on_line[k, s] = present[s] and abs(in_front[k, s]) <= line_tolerance[s]
            # The corner's std along the wall, and how far apart the wall's returns are there.
            variance = 0.0
            for i in range(2):
                for j in range(2):
                    variance += inward[k, i] * corner_covariance[c, i, j] * inward[k, j]
            along_sigma[k] = math.sqrt(variance)
            incidence = abs(normal[k, 0] * corner_x + normal[k, 1] * corner_y) / corner_range
            spacing[k] = corner_range * step_rad / max(incidence, 1e-3)
            tolerance[k] = sigmas * along_sigma[k] + floor_m
        # Returns this close to the corner belong to either wall.
        sine = abs(normal[0, 0] * normal[1, 1] - normal[0, 1] * normal[1, 0])
        corner_noise = math.sqrt(range_sigma_m ** 2 + (corner_range * bearing_sigma_rad) ** 2)
        zone = (sigmas * math.hypot(corner_noise, max(along_sigma[0], along_sigma[1])) / sine
                + floor_m + min(spacing[0], spacing[1]))
        for s in range(width):
            at_corner[s] = present[s] and math.hypot(x[s] - corner_x, y[s] - corner_y) <= zone
        # Returns away from the corner that a wall claims beyond its segment must not lie in
        # front of its line together. Its line was fitted without them, so their plain sum of
        # normalised residuals is already a deleted-residual test (segmentation.trim_offset
        # tests a segment's own returns, and so against the line of the others).
        for k in range(2):
            run, together = 0, 0.0
            for s in range(1, width - 1):
                if on_line[k, s] and along[k, s] >= -tolerance[k] and not at_corner[s]:
                    run += 1
                    together += in_front[k, s] / noise[s]
            together /= math.sqrt(max(run, 1))
            if run_sigmas > 0.0 and together > run_sigmas:
                for s in range(1, width - 1):
                    if on_line[k, s] and along[k, s] >= -tolerance[k] and not at_corner[s]:
                        on_line[k, s] = False
        goes_on = False
        first_anchor, second_anchor = 0, width - 1
        for s in range(width):
            occluder = present[s] and in_front[0, s] > line_tolerance[s] and (
                in_front[1, s] > line_tolerance[s])
            for k in range(2):
                reaches = along[k, s] >= -tolerance[k]
                here[k, s] = at_corner[s] or (on_line[k, s] and reaches)
                if (not at_corner[s] and on_line[k, s] and not on_line[1 - k, s]
                        and along[k, s] < -tolerance[k]):
                    goes_on = True
            if on_line[0, s] and along[0, s] >= -tolerance[0] and not at_corner[s]:
                first_anchor = max(first_anchor, s)
            if on_line[1, s] and along[1, s] >= -tolerance[1] and not at_corner[s]:
                second_anchor = min(second_anchor, s)
            present[s] = present[s] and not occluder      # reused below: present, no occluder
        blocked = False
        for s in range(width):
            visible = s <= between or s == width - 1
            interrupts = visible and not here[0, s] and not here[1, s]
            outside = s < first_anchor or s > second_anchor
            if interrupts and ((present[s] and outside) or not outside):
                blocked = True
        # How far each wall's own returns stop short of the corner, beyond the tolerance, in
        # beams.
        short_ok, ends = True, np.zeros(2, np.bool_)
        for k in range(2):
            gap = np.inf
            for s in range(width):
                if on_line[k, s] and here[k, s]:
                    gap = min(gap, max(along[k, s], 0.0))
            short = max(gap - tolerance[k], 0.0) / spacing[k]
            short_ok = short_ok and short <= 1.0 + max_missing_beams
            ends[k] = short <= 1.0
        keep[c] = (between <= window and here[0, 0] and here[1, width - 1] and not goes_on
                   and not blocked and short_ok)
        for k in range(2):
            if keep[c] and run_sigmas > 0.0:
                # Wall 0's stretch is crossed by the sight lines after its last return, up to
                # wall 1's last; wall 1's by those from wall 0's first return to its own first.
                start = after_first + 1 if k == 0 else first_position[walls[0]]
                stop = last_position[walls[1]] if k == 0 else before_second - 1
                keep[c] = not seen_through(
                    corner_x, corner_y, normal[k, 0], normal[k, 1], wall_radius_m[walls[k]],
                    inward[k, 0], inward[k, 1], tolerance[k], normal[1 - k, 0],
                    normal[1 - k, 1], wall_radius_m[walls[1 - k]], x_m, y_m, start, stop,
                    range_sigma_m, bearing_sigma_rad, sigmas, floor_m, run_sigmas)
        seen[c, 0], seen[c, 1] = ends[0], ends[1]
    return keep, seen
