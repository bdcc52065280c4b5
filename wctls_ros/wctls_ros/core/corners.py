"""
Corners: intersections of adjacent lines with their jointly propagated (x, y, yaw) covariance.

For lines L_k = (a_k, b_k, c_k) with covariances C_k (from disjoint returns, so independent), the
corner z = -A^-1 (c_1, c_2), A = [[a_1, b_1], [a_2, b_2]] (the paper's eqs. (24)-(25)), has
dz/dL_k = -A^-1 e_k h^T with h = (x, y, 1). The yaw of the bisector moves with each wall's
direction by half its normal angle: d yaw / dL_k = (-b_k, a_k, 0) / (2 (a_k^2 + b_k^2)). The
joint covariance is sum_k J_k C_k J_k^T with J_k stacking both (3 x 3). Since h . L_k = 0 and
(-b_k, a_k, 0) . L_k = 0, it is exactly invariant to any rescaling of a line's (a, b, c).
"""

import numpy as np

from .features import CornerSet


def _solve(line_a: np.ndarray, line_b: np.ndarray):
    """
    Intersect pairs of lines by Cramer's rule (the paper's eqs. (24)-(25)).

    :return: (h = (x, y, 1) of shape (C, 3), the columns of A^-1 for each line, each (C, 2))
    """
    a1, b1, c1 = line_a.T
    a2, b2, c2 = line_b.T
    with np.errstate(divide='ignore', invalid='ignore'):
        inv_det = 1.0 / (a1 * b2 - a2 * b1)
    h = np.empty((len(a1), 3))
    h[:, 0] = (b1 * c2 - b2 * c1) * inv_det
    h[:, 1] = (a2 * c1 - a1 * c2) * inv_det
    h[:, 2] = 1.0
    column_a = np.empty((len(a1), 2))
    column_a[:, 0], column_a[:, 1] = b2 * inv_det, -a2 * inv_det
    column_b = np.empty((len(a1), 2))
    column_b[:, 0], column_b[:, 1] = -b1 * inv_det, a1 * inv_det
    return h, column_a, column_b


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
    h, column_a, column_b = _solve(line_a, line_b)
    jac_a = -column_a[:, :, None] * h[:, None, :]                  # -A^-1 e_1 h^T
    jac_b = -column_b[:, :, None] * h[:, None, :]
    covariance = (jac_a @ cov_a @ jac_a.transpose(0, 2, 1)
                  + jac_b @ cov_b @ jac_b.transpose(0, 2, 1))
    return h[:, :2], covariance, jac_a, jac_b


def _yaw_gradient(line: np.ndarray) -> np.ndarray:
    """Return d yaw / d(a, b, c) of each line: (-b, a, 0) / (2 (a^2 + b^2)), shape (C, 3)."""
    gradient = np.zeros_like(line)
    scale = 0.5 / (line[:, 0] ** 2 + line[:, 1] ** 2)
    gradient[:, 0], gradient[:, 1] = -line[:, 1] * scale, line[:, 0] * scale
    return gradient


def find_corners(line: np.ndarray, line_covariance: np.ndarray,
                 start_xy_m: np.ndarray, end_xy_m: np.ndarray, first: np.ndarray,
                 second: np.ndarray, min_angle_rad: float, max_gap_m: float,
                 line_offset_jacobian: np.ndarray = None,
                 common_range_sigma_m: float = 0.0) -> CornerSet:
    """
    Intersect the given pairs of segments and keep the real corners.

    A pair is rejected when its lines are closer to parallel than ``min_angle_rad`` or when the
    intersection lies farther than ``max_gap_m`` from the first segment's end point or from the
    second segment's start point (a virtual intersection, e.g. across an occlusion).

    :param line: (a, b, c) of every segment in the method's form, shape (S, 3)
    :param line_covariance: covariance of (a, b, c), shape (S, 3, 3)
    :param start_xy_m: first return of each segment projected on its line, shape (S, 2), m
    :param end_xy_m: last return projected on its line, shape (S, 2), m
    :param first: earlier segment of each candidate pair, shape (k,)
    :param second: later segment of each candidate pair, shape (k,)
    :param min_angle_rad: smallest angle between the two walls, rad
    :param max_gap_m: largest distance from the corner to either facing end point, m
    :param line_offset_jacobian: d(a, b, c) / d(range offset common to the scan), (S, 3), per m
    :param common_range_sigma_m: std of that common offset, m: it moves both lines together, so
        its part of the corner covariance is sigma^2 j j^T with j = J_1 g_1 + J_2 g_2
    :return: the corners that pass both tests
    """
    first = np.asarray(first, dtype=np.intp)
    second = np.asarray(second, dtype=np.intp)
    unit = line[:, :2] / np.hypot(line[:, 0], line[:, 1])[:, None]          # line normals
    sine = np.abs(unit[first, 0] * unit[second, 1] - unit[first, 1] * unit[second, 0])
    steep = sine >= np.sin(min_angle_rad)
    first, second = first[steep], second[steep]
    h, column_a, column_b = _solve(line[first], line[second])
    xy = h[:, :2]
    gap_a = np.hypot(xy[:, 0] - end_xy_m[first, 0], xy[:, 1] - end_xy_m[first, 1])
    gap_b = np.hypot(xy[:, 0] - start_xy_m[second, 0], xy[:, 1] - start_xy_m[second, 1])
    near = np.flatnonzero((gap_a <= max_gap_m) & (gap_b <= max_gap_m))
    first, second, h, xy = first[near], second[near], h[near], xy[near]
    column_a, column_b = column_a[near], column_b[near]

    # Both walls of every corner at once: rows [0, C) are the first walls, [C, 2C) the second.
    count = len(xy)
    walls = np.concatenate([first, second])
    xy2 = np.concatenate([xy, xy])
    h2 = np.concatenate([h, h])
    # Unit vectors from the corner along each wall, towards the segment's returns.
    direction = np.empty((2 * count, 2))
    direction[:, 0], direction[:, 1] = -unit[walls, 1], unit[walls, 0]
    middle = 0.5 * (start_xy_m[walls] + end_xy_m[walls]) - xy2
    direction[np.einsum('ci,ci->c', middle, direction) < 0.0] *= -1.0
    bisector = direction[:count] + direction[count:]
    between = np.arccos(np.clip(np.einsum('ci,ci->c', direction[:count], direction[count:]),
                                -1.0, 1.0))
    # The sensor (origin) sees the open side: inside a concave corner it lies along +bisector.
    concave = np.einsum('ci,ci->c', bisector, xy) < 0.0
    bisector[~concave] *= -1.0
    opening = np.where(concave, between, 2.0 * np.pi - between)

    # Joint covariance of (x, y, yaw): line k moves the position by -A^-1 e_k h^T dL_k and the
    # yaw by g_k^T dL_k, so three quadratic forms of each C_k are all that is needed.
    cov = line_covariance[walls]
    gradient = _yaw_gradient(line[walls])
    cov_h = np.einsum('cij,cj->ci', cov, h2)
    along_h = np.einsum('ci,ci->c', h2, cov_h)                      # h^T C h
    cross = np.einsum('ci,ci->c', gradient, cov_h)                  # g^T C h
    yaw = np.einsum('ci,cij,cj->c', gradient, cov, gradient)        # g^T C g
    column = np.concatenate([column_a, column_b])
    covariance = np.empty((count, 3, 3))
    # (c_i c_j) h^T C h: exactly symmetric in floating point.
    block = np.einsum('ci,cj->cij', column, column) * along_h[:, None, None]
    covariance[:, :2, :2] = block[:count] + block[count:]
    offdiagonal = column * cross[:, None]
    covariance[:, :2, 2] = covariance[:, 2, :2] = -(offdiagonal[:count] + offdiagonal[count:])
    covariance[:, 2, 2] = yaw[:count] + yaw[count:]
    if common_range_sigma_m > 0.0 and line_offset_jacobian is not None:
        offset = line_offset_jacobian[walls]
        shift = np.empty((2 * count, 3))
        shift[:, :2] = -column * np.einsum('ci,ci->c', h2, offset)[:, None]
        shift[:, 2] = np.einsum('ci,ci->c', gradient, offset)
        common = shift[:count] + shift[count:]
        covariance += common_range_sigma_m ** 2 * common[:, :, None] * common[:, None, :]
    return CornerSet(xy, np.arctan2(bisector[:, 1], bisector[:, 0]), covariance, opening,
                     first, second)
