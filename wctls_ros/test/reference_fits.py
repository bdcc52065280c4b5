# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A slow, plain reference of the line fits and the corner propagation, from docs/derivation.md.

One segment and one corner at a time, in plain loops over the returns, with the formulas as the
derivation writes them: the paper's Jacobians R, S (UTLS, (7) corrected) and T, U (WTLS, (15)
corrected), C_Q (D9) and J_WC (23) for WCTLS, Gauss-Newton with the Fisher information for ML,
and (D11)-(D16) for a corner. It shares no code with wctls_ros.core, so that
test_core_reference.py can check the fast, batched code against it.
"""

import math

import numpy as np

ML_STEP_TOLERANCE = 1e-12     # docs/derivation.md#maximum-likelihood: stop below this step...
ML_MAX_ITERATIONS = 8         # ... or after this many iterations


def _sums(rho, theta, weights):
    """Return the weighted sums S_x, S_y, S_xx, S_yy, S_xy and W = sum w of one segment."""
    s_x = s_y = s_xx = s_yy = s_xy = total = 0.0
    for r, t, w in zip(rho, theta, weights):
        x, y = r * math.cos(t), r * math.sin(t)
        s_x += w * x
        s_y += w * y
        s_xx += w * x * x
        s_yy += w * y * y
        s_xy += w * x * y
        total += w
    return s_x, s_y, s_xx, s_yy, s_xy, total


def normal_form(line, covariance):
    """
    Return (angle, radius, 2x2 covariance) of a x + b y + c = 0 (docs: Normal form).

    :param line: (a, b, c)
    :param covariance: its 3x3 covariance
    """
    a, b, c = line
    sign = -1.0 if c > 0.0 else 1.0
    n = math.hypot(a, b)
    jacobian = _normal_jacobian(line)
    return (math.atan2(sign * b, sign * a), -sign * c / n,
            jacobian @ np.asarray(covariance) @ jacobian.T)


def _normal_jacobian(line):
    """Return d(angle, radius) / d(a, b, c) of a x + b y + c = 0, shape (2, 3)."""
    a, b, c = line
    sign = -1.0 if c > 0.0 else 1.0
    n2 = a * a + b * b
    n = math.sqrt(n2)
    return np.array([[-b / n2, a / n2, 0.0],
                     [sign * c * a / (n2 * n), sign * c * b / (n2 * n), -sign / n]])


def algebraic_fit(rho, theta, range_sigma, bearing_sigma, weighted):
    """
    UTLS (eqs. (2)-(7)) or WTLS (eqs. (8)-(15), weights 1 / rho^2) of one segment.

    :return: (line (a, b, c), its 3x3 covariance, its offset Jacobian sum_i dL / drho_i)
    """
    weights = [1.0 / (r * r) if weighted else 1.0 for r in rho]
    s_x, s_y, s_xx, s_yy, s_xy, total = _sums(rho, theta, weights)
    line = np.array([s_x * s_yy - s_y * s_xy, s_y * s_xx - s_x * s_xy,
                     s_xy * s_xy - s_xx * s_yy])
    # Means of the (weighted) products and of the coordinates, as the derivation writes them.
    mx, my = s_x / total, s_y / total
    mxx, myy, mxy = s_xx / total, s_yy / total, s_xy / total
    covariance = np.zeros((3, 3))
    offset = np.zeros(3)
    for r, t, w in zip(rho, theta, weights):
        x, y = r * math.cos(t), r * math.sin(t)
        if weighted:            # T (range) and U (bearing) of (15), corrected
            d_range = (w * total / r) * np.array([-x * myy + y * mxy, -y * mxx + x * mxy, 0.0])
            scale = w * total
        else:                   # R (range) and S (bearing) of (7), corrected
            d_range = (total / r) * np.array([
                x * myy + 2 * y * y * mx - y * mxy - 2 * x * y * my,
                y * mxx + 2 * x * x * my - x * mxy - 2 * x * y * mx,
                2 * (2 * x * y * mxy - x * x * myy - y * y * mxx)])
            scale = total
        d_bearing = scale * np.array([
            -y * myy + 2 * x * y * mx - x * mxy - (x * x - y * y) * my,
            x * mxx - 2 * x * y * my + y * mxy - (x * x - y * y) * mx,
            2 * ((x * x - y * y) * mxy + x * y * (myy - mxx))])
        covariance += (range_sigma ** 2 * np.outer(d_range, d_range)
                       + bearing_sigma ** 2 * np.outer(d_bearing, d_bearing))
        offset += d_range
    return line, covariance, offset


def conformal_fit(rho, theta, range_sigma, bearing_sigma):
    """
    WCTLS of one segment: Q = F p (D8), C_Q (D9), the normalised line (D10) and J_WC (23).

    :return: (line (a, b, c), its 3x3 covariance, its offset Jacobian)
    """
    weights = [1.0 / (r * r) for r in rho]
    s_x, s_y, s_xx, s_yy, s_xy, _ = _sums(rho, theta, weights)
    s_m = np.array([[s_xx, s_xy], [s_xy, s_yy]])
    s_m_inv = np.linalg.inv(s_m)
    p = s_m_inv @ np.array([s_x, s_y])
    flip = np.diag([1.0, -1.0])
    inner = np.zeros((2, 2))
    dp_offset = np.zeros(2)
    for r, t, w in zip(rho, theta, weights):
        z = np.array([r * math.cos(t), r * math.sin(t)])
        z_perp = np.array([-z[1], z[0]])
        q = (1.0 - p @ z) * z_perp - (p @ z_perp) * z
        inner += (range_sigma ** 2 * (w / r) ** 2 * np.outer(z, z)
                  + bearing_sigma ** 2 * w * w * np.outer(q, q))
        dp_offset += -(w / r) * (s_m_inv @ z)
    cov_q = flip @ s_m_inv @ inner @ s_m_inv @ flip
    x_q, y_q = flip @ p
    norm = math.hypot(x_q, y_q)
    line = np.array([-x_q, y_q, 1.0]) / norm
    j_wc = np.array([[-y_q * y_q, x_q * y_q], [-x_q * y_q, x_q * x_q], [-x_q, -y_q]]) / norm ** 3
    return line, j_wc @ cov_q @ j_wc.T, j_wc @ flip @ dp_offset


def ml_fit(rho, theta, range_sigma, bearing_sigma):
    """
    Maximum-likelihood line of one segment from the WTLS line, with F^-1 and d(angle, r)/d offset.

    Variances and gradients at the range to the current line along each beam
    (docs/derivation.md#maximum-likelihood).

    :return: (angle, radius, 2x2 covariance of (angle, radius), offset Jacobian (2,))
    """
    line, _, _ = algebraic_fit(rho, theta, range_sigma, bearing_sigma, True)
    angle, radius, _ = normal_form(line, np.zeros((3, 3)))

    def system(angle, radius):
        fisher = np.zeros((2, 2))
        gradient_sum = np.zeros(2)
        offset_sum = np.zeros(2)
        for r, t in zip(rho, theta):
            incidence = t - angle
            g = np.array([radius * math.tan(incidence), -1.0])
            variance = ((range_sigma * math.cos(incidence)) ** 2
                        + (bearing_sigma * radius * math.tan(incidence)) ** 2)
            residual = r * math.cos(incidence) - radius
            fisher += np.outer(g, g) / variance
            gradient_sum += g * residual / variance
            offset_sum += g * math.cos(incidence) / variance
        return fisher, gradient_sum, offset_sum

    for _ in range(ML_MAX_ITERATIONS):
        fisher, gradient_sum, _ = system(angle, radius)
        step = -np.linalg.solve(fisher, gradient_sum)
        angle, radius = angle + step[0], radius + step[1]
        if np.all(np.abs(step) <= ML_STEP_TOLERANCE):
            break
    fisher, _, offset_sum = system(angle, radius)
    covariance = np.linalg.inv(fisher)
    offset = -covariance @ offset_sum
    if radius < 0.0:            # reflect to (angle + pi, -radius)
        angle, radius = angle + math.pi, -radius
        covariance = covariance * np.array([[1.0, -1.0], [-1.0, 1.0]])
        offset = offset * np.array([1.0, -1.0])
    return math.atan2(math.sin(angle), math.cos(angle)), radius, covariance, offset


def fit(method, rho, theta, range_sigma, bearing_sigma):
    """
    Fit one segment with one method in both forms.

    :return: (line (a, b, c), 3x3 covariance, angle, radius, 2x2 covariance of (angle, radius),
        line offset Jacobian (3,), normal offset Jacobian (2,))
    """
    if method == 'ml':
        angle, radius, normal, normal_offset = ml_fit(rho, theta, range_sigma, bearing_sigma)
        jacobian = np.array([[-math.sin(angle), 0.0], [math.cos(angle), 0.0], [0.0, -1.0]])
        line = np.array([math.cos(angle), math.sin(angle), -radius])
        return (line, jacobian @ normal @ jacobian.T, angle, radius, normal,
                jacobian @ normal_offset, normal_offset)
    if method == 'wctls':
        line, covariance, offset = conformal_fit(rho, theta, range_sigma, bearing_sigma)
    else:
        line, covariance, offset = algebraic_fit(rho, theta, range_sigma, bearing_sigma,
                                                 method == 'wtls')
    angle, radius, normal = normal_form(line, covariance)
    return line, covariance, angle, radius, normal, offset, _normal_jacobian(line) @ offset


def corner(line_1, cov_1, offset_1, line_2, cov_2, offset_2, middle_1, middle_2,
           common_range_sigma):
    """
    Intersect two lines and propagate their covariances to (x, y, yaw), (D11)-(D16).

    :param middle_1: a point of wall 1's returns (tells which way the wall runs from the corner)
    :param middle_2: the same for wall 2
    :return: (x, y, yaw, opening angle, 3x3 covariance of (x, y, yaw))
    """
    a_matrix = np.array([line_1[:2], line_2[:2]])
    z = -np.linalg.solve(a_matrix, np.array([line_1[2], line_2[2]]))
    h = np.array([z[0], z[1], 1.0])
    a_inv = np.linalg.inv(a_matrix)
    directions, jacobians = [], []
    for k, (line, middle) in enumerate(((line_1, middle_1), (line_2, middle_2))):
        a, b, _ = line
        n = math.hypot(a, b)
        t = np.array([-b, a]) / n
        if t @ (np.asarray(middle) - z) < 0.0:
            t = -t
        directions.append(t)
        g = np.array([-b, a, 0.0]) / (2.0 * (a * a + b * b))
        jacobians.append(np.vstack([-np.outer(a_inv[:, k], h), g]))
    bisector = directions[0] + directions[1]
    between = math.acos(min(max(directions[0] @ directions[1], -1.0), 1.0))
    concave = bisector @ z < 0.0
    facing = bisector if concave else -bisector
    yaw = math.atan2(facing[1], facing[0])
    opening = between if concave else 2.0 * math.pi - between
    covariance = (jacobians[0] @ cov_1 @ jacobians[0].T
                  + jacobians[1] @ cov_2 @ jacobians[1].T)
    common = jacobians[0] @ offset_1 + jacobians[1] @ offset_2
    covariance += common_range_sigma ** 2 * np.outer(common, common)
    return z[0], z[1], yaw, opening, covariance
