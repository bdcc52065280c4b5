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

from ._linalg import inverse_2x2
from .features import CornerSet


def acute_angle_between(normal_a_rad: np.ndarray, normal_b_rad: np.ndarray) -> np.ndarray:
    """
    Return the acute angle between lines given by their normal angles.

    :param normal_a_rad: shape (k,), rad
    :param normal_b_rad: shape (k,), rad
    :return: shape (k,), rad in [0, pi/2]
    """
    return np.arcsin(np.minimum(np.abs(np.sin(normal_a_rad - normal_b_rad)), 1.0))


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
    matrix = np.stack([line_a[:, :2], line_b[:, :2]], axis=1)       # A, (C, 2, 2)
    inverse = inverse_2x2(matrix)
    xy = -np.einsum('cij,cj->ci', inverse, np.column_stack([line_a[:, 2], line_b[:, 2]]))
    h = np.column_stack([xy, np.ones(len(xy))])
    jac_a = -inverse[:, :, 0, None] * h[:, None, :]                # -A^-1 e_1 h^T
    jac_b = -inverse[:, :, 1, None] * h[:, None, :]
    covariance = (jac_a @ cov_a @ jac_a.transpose(0, 2, 1)
                  + jac_b @ cov_b @ jac_b.transpose(0, 2, 1))
    return xy, covariance, jac_a, jac_b


def _yaw_jacobian(line: np.ndarray) -> np.ndarray:
    """Return d yaw / d(a, b, c) for each line, shape (C, 1, 3)."""
    a, b = line[:, 0], line[:, 1]
    n2 = 2.0 * (a * a + b * b)
    return np.stack([-b / n2, a / n2, np.zeros_like(a)], -1)[:, None, :]


def find_corners(line: np.ndarray, line_covariance: np.ndarray,
                 start_xy_m: np.ndarray, end_xy_m: np.ndarray, first: np.ndarray,
                 second: np.ndarray, min_angle_rad: float, max_gap_m: float
                 ) -> CornerSet:
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
    :return: the corners that pass both tests
    """
    first = np.asarray(first, dtype=np.intp)
    second = np.asarray(second, dtype=np.intp)
    angle_rad = np.arctan2(line[:, 1], line[:, 0])
    steep = acute_angle_between(angle_rad[first], angle_rad[second]) >= min_angle_rad
    first, second = first[steep], second[steep]
    xy, _, jac_a, jac_b = intersect(line[first], line_covariance[first], line[second],
                                    line_covariance[second])
    gap_a = np.hypot(*(xy - end_xy_m[first]).T)
    gap_b = np.hypot(*(xy - start_xy_m[second]).T)
    near = (gap_a <= max_gap_m) & (gap_b <= max_gap_m) & np.isfinite(xy).all(axis=1)
    first, second, xy = first[near], second[near], xy[near]
    jac_a, jac_b = jac_a[near], jac_b[near]

    # Unit vectors from the corner along each wall, towards the segment's returns.
    walls = []
    for segment in (first, second):
        middle = 0.5 * (start_xy_m[segment] + end_xy_m[segment]) - xy
        direction = np.column_stack([-np.sin(angle_rad[segment]), np.cos(angle_rad[segment])])
        sign = np.where(np.einsum('ci,ci->c', middle, direction) < 0.0, -1.0, 1.0)
        walls.append(direction * sign[:, None])
    bisector = walls[0] + walls[1]
    between = np.arccos(np.clip(np.einsum('ci,ci->c', walls[0], walls[1]), -1.0, 1.0))
    # The sensor (origin) sees the open side: inside a concave corner it lies along +bisector.
    concave = np.einsum('ci,ci->c', bisector, -xy) > 0.0
    bisector = np.where(concave[:, None], bisector, -bisector)
    opening = np.where(concave, between, 2.0 * np.pi - between)

    full_a = np.concatenate([jac_a, _yaw_jacobian(line[first])], axis=1)     # (C, 3, 3)
    full_b = np.concatenate([jac_b, _yaw_jacobian(line[second])], axis=1)
    covariance = (full_a @ line_covariance[first] @ full_a.transpose(0, 2, 1)
                  + full_b @ line_covariance[second] @ full_b.transpose(0, 2, 1))
    covariance = 0.5 * (covariance + covariance.transpose(0, 2, 1))
    return CornerSet(xy, np.arctan2(bisector[:, 1], bisector[:, 0]), covariance, opening,
                     first, second)
