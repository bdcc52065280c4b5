# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Line fits with first-order covariance, batched over many segments at once.

Every fit works on the returns of S segments laid end to end: ``rho`` and ``theta`` of shape
(P,), segment k owning ``rho[offsets[k]:offsets[k] + counts[k]]``. The noise is independent per
return with std ``range_sigma`` (m) and ``bearing_sigma`` (rad), and every covariance is

    C = sum_i [ range_sigma^2 (dphi/drho_i)(dphi/drho_i)^T
                + bearing_sigma^2 (dphi/dtheta_i)(dphi/dtheta_i)^T ]

with the analytic Jacobians derived in ``docs/derivation.md`` (the paper's eqs. (6)-(23) with its
typos corrected). Each method returns the line in its own implicit form a x + b y + c = 0, the
3x3 covariance of (a, b, c) and the shift of (a, b, c) per metre of a range offset common to every
return of the scan (d(a, b, c)/d offset = sum_i d(a, b, c)/d rho_i), which lets a common-mode
range error be propagated with its correlation between lines; :func:`normal_form` gives every
method's line in one common form x cos(angle) + y sin(angle) = radius, radius >= 0, with the 2x2
covariance of (angle, radius).
"""

import numpy as np

from ..features import LineFits, SegmentReturns
from ..rules import ML_MAX_ITERATIONS, ML_STEP_TOLERANCE


def _square_order(k: int) -> np.ndarray:
    """
    Return where each entry of a symmetric k x k matrix, in row-major order, is summed.

    :func:`_lever_sums` sums the entries diagonal by diagonal: (0, 0), (1, 1), [(2, 2),] (0, 1),
    [(1, 2), (0, 2)].
    """
    order = np.empty((k, k), dtype=np.intp)
    place = 0
    for shift in range(k):
        for row in range(k - shift):
            order[row, row + shift] = order[row + shift, row] = place
            place += 1
    return order.ravel()


# Takes the summed entries, columns (S, k (k + 1) / 2), to the matrices (S, k, k) in one copy.
_SQUARE = {k: _square_order(k) for k in (2, 3)}


def _weighted_sums(returns: SegmentReturns, weighted: bool):
    """
    Return the per-segment sums S_x, S_y, S_xx, S_yy, S_xy, weighted or not.

    The weights are those of eq. (8) up to its constant factor: w_i = 1 / rho_i^2. The factor
    1 / (range_sigma bearing_sigma)^2 is left out: it scales (a_w, b_w, c_w) by a constant,
    which cancels in the normal form, in the WCTLS point Q and in every corner, and it is
    undefined for a zero bearing sigma.

    :return: (1 / rho (P,), weights (P,), both None when unweighted; sums, shape (5, S))
    """
    x, y = returns.x, returns.y
    if weighted:
        inv_rho = 1.0 / returns.rho
        weight = inv_rho * inv_rho
        wx, wy = weight * x, weight * y
    else:
        inv_rho, weight, wx, wy = None, None, x, y
    columns = np.empty((5, len(x)))
    columns[0], columns[1], columns[2], columns[3], columns[4] = wx, wy, wx * x, wy * y, wx * y
    return inv_rho, weight, np.add.reduceat(columns, returns.offsets, axis=1)


def _algebraic_line(sums: np.ndarray) -> np.ndarray:
    """Return (a, b, c) of eqs. (2)-(4) / (10)-(12) from the (weighted) sums, shape (S, 3)."""
    s_x, s_y, s_xx, s_yy, s_xy = sums
    line = np.empty((len(s_x), 3))
    line[:, 0] = s_x * s_yy - s_y * s_xy
    line[:, 1] = s_y * s_xx - s_x * s_xy
    line[:, 2] = s_xy * s_xy - s_xx * s_yy
    return line


# A degenerate segment (det S_M = 0: every return on one ray) yields NaN or inf, not warnings.
@np.errstate(divide='ignore', invalid='ignore')
def _lever_sums(returns: SegmentReturns, range_sigma: float, bearing_sigma: float,
                weighted: bool, scaled: bool):
    """
    Fit p of every segment and sum the first-order covariance of its coordinates u.

    UTLS, WTLS and WCTLS all rest on the least-squares solution p of p.z = 1: S_M p = S_g with
    S_M = sum w z z^T and S_g = sum w z. The (a, b, c) of eqs. (2)-(4) / (10)-(12) are
    (a, b) = adj(S_M) S_g and c = -det S_M, so (a, b, c) = s (p, -1) with s = det S_M; WCTLS
    gives (-p, 1) / |p| (eqs. (19)-(21) with Q = F p); and all have the normal form
    angle = atan2(p_y, p_x), radius = 1 / |p|. A return moves p by S_M^-1 (dS_g - dS_M p):

        dp/drho_i   = -(w_i / rho_i) S_M^-1 z_i           (eq. (8): w z z^T is free of rho)
        dp/drho_i   = ((1 - 2 p.z_i) / rho_i) S_M^-1 z_i  (unit weights)
        dp/dtheta_i = w_i S_M^-1 q_i,  q_i = (1 - p.z_i) z_perp_i - (p.z_perp_i) z_i

    and s by d ln s = tr(S_M^-1 dS_M): 2 w_i z_i^T S_M^-1 z_perp_i per bearing, and per range 0
    (eq. (8)) or 2 z_i^T S_M^-1 z_i / rho_i (unit weights). These are the Jacobians (7), (15)
    and (22) in other coordinates. With Pi = [p_perp, p]^T S_M^-1 (2x2 per segment), Pi dp =
    (p_perp.dp, p.dp) = (|p|^2 d angle, -|p|^3 d radius), and z^T S_M^-1 v =
    (p_perp.z (Pi v)_1 + p.z (Pi v)_2) / |p|^2. Each return's derivatives are projected before
    their products are summed: summing z z^T and applying S_M^-1 on both sides afterwards would
    lose digits on short, distant segments, where S_M is ill-conditioned.

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :param weighted: use the weights of eq. (8), else unit weights
    :param scaled: take u = (p_perp.dp, p.dp, |p|^2 d ln s / 2), for a line that carries the
        scale s, else u = (d angle, d radius)
    :return: ((a, b, c) (S, 3); p as (p_x, p_y), each (S,); 1 / |p| (S,); the covariance of u,
        its entries in the order of :func:`_square_order` (k (k + 1) / 2, S); its offset Jacobian
        du / d(range offset common to all returns) (k, S)), k = 3 if scaled else 2
    """
    inv_rho, weight, sums = _weighted_sums(returns, weighted)
    line = _algebraic_line(sums)
    x, y = returns.x, returns.y
    # Per segment Pi e_x, Pi e_y and p, repeated to every return, in rows Pi e_x, p_x, Pi e_y,
    # p_y, -Pi e_x, -p_x: rows 0-5 times x plus rows 3-8 times y are Pi z, p.z, Pi z_perp and
    # p.z_perp in one pass. S_M^-1 = adj(S_M) / det S_M makes the rows of Pi A^T adj(S_M) and
    # B^T adj(S_M) with A = p_perp / det S_M and B = p / det S_M, here also scaled by
    # (1 / |p|^2, -1 / |p|^3) when u = (d angle, d radius).
    inv_det = -1.0 / line[:, 2]
    px, py = line[:, 0] * inv_det, line[:, 1] * inv_det
    inv_norm = 1.0 / np.hypot(px, py)
    if scaled:
        to_angle, to_radius = inv_det, inv_det
    else:
        to_angle = inv_norm * inv_norm * inv_det
        to_radius = -inv_norm * to_angle
    a_x, a_y = -py * to_angle, px * to_angle
    b_x, b_y = px * to_radius, py * to_radius
    _, _, s_xx, s_yy, s_xy = sums
    pi_x = [a_x * s_yy - a_y * s_xy, b_x * s_yy - b_y * s_xy]     # Pi e_x
    pi_y = [a_y * s_xx - a_x * s_xy, b_y * s_xx - b_x * s_xy]     # Pi e_y
    basis = np.array([*pi_x, px, *pi_y, py, -pi_x[0], -pi_x[1], -px])
    basis = basis.repeat(returns.counts, axis=1)
    projected = basis[:6] * x
    projected += basis[3:] * y
    # Per return: Pi z_i (2 rows), p.z_i, Pi z_perp_i (2 rows), p.z_perp_i.
    along, ahead, across, turn = projected[:2], projected[2], projected[3:5], projected[5]
    k = 3 if scaled else 2
    pairs = k * (k + 1) // 2
    kinds = 1 if bearing_sigma == 0.0 else 2        # a zero bearing sigma adds nothing
    # Per kind (bearing if kept, then range): du/dtheta_i or -du/drho_i (the sign that costs no
    # operation, undone in the offset), then their products diagonal by diagonal. One array
    # holds them all, each row written in place (out=), so that a diagonal of products of both
    # kinds is one multiplication and the sums one reduction: this is the one hot loop of the
    # fits, and written row by row with temporaries fit_lines took 1.2-1.5 times as long on
    # 1000-4200 returns (side by side, 2-core AMD EPYC VM).
    work = np.empty((kinds, k + pairs, len(x)))
    jac = work[:, :k]
    if weighted:
        np.multiply(along, weight * inv_rho, out=jac[-1, :2])
    else:
        inv_rho = 1.0 / returns.rho
        np.multiply(along, (2.0 * ahead - 1.0) * inv_rho, out=jac[-1, :2])
    if scaled and weighted:
        jac[-1, 2] = 0.0
    elif scaled:
        np.multiply(turn * along[0] - ahead * along[1], inv_rho, out=jac[-1, 2])
    if kinds == 2:
        np.subtract((1.0 - ahead) * across, turn * along, out=jac[0, :2])
        if scaled:
            np.subtract(ahead * across[1], turn * across[0], out=jac[0, 2])
        if weighted:
            jac[0] *= weight
    start = k
    for shift in range(k):
        np.multiply(jac[:, :k - shift], jac[:, shift:], out=work[:, start:start + k - shift])
        start += k - shift
    # Rows summed per segment: [bearing products,] range -u, range products.
    sums = np.add.reduceat(work.reshape(-1, len(x))[(kinds - 1) * k:], returns.offsets,
                           axis=1)
    covariance = range_sigma ** 2 * sums[-pairs:]
    if kinds == 2:
        covariance += bearing_sigma ** 2 * sums[:pairs]
    return line, (px, py), inv_norm, covariance, -sums[-pairs - k:-pairs]


def _algebraic_fits(returns: SegmentReturns, range_sigma: float, bearing_sigma: float,
                    weighted: bool) -> LineFits:
    """
    Fit UTLS (unit weights) or WTLS (weights of eq. (8)) lines, see :func:`_lever_sums`.

    d(angle, radius) = (u_1 / |p|^2, -u_2 / |p|^3) and, as (a, b, c) = s (p, -1),
    d(a, b, c) = K u with K = (s / |p|^2) [(p_perp, 0), (p, 0), 2 (p, -1)] (by columns).
    """
    line, (px, py), inv_norm, pairs, offset = _lever_sums(returns, range_sigma, bearing_sigma,
                                                          weighted, True)
    covariance = pairs.take(_SQUARE[3], axis=0).T.reshape(-1, 3, 3)
    inv_n2 = inv_norm * inv_norm
    jac = np.zeros((len(px), 3, 3))
    jac[:, 0, 0], jac[:, 0, 1], jac[:, 0, 2] = -py, px, 2.0 * px
    jac[:, 1, 0], jac[:, 1, 1], jac[:, 1, 2] = px, py, 2.0 * py
    jac[:, 2, 2] = -2.0
    jac *= (-line[:, 2] * inv_n2)[:, None, None]
    to_normal = np.empty((len(px), 2))              # d(angle, radius) / d(u_1, u_2)
    to_normal[:, 0], to_normal[:, 1] = inv_n2, -inv_n2 * inv_norm
    normal = covariance[:, :2, :2] * to_normal[:, :, None] * to_normal[:, None, :]
    return LineFits(line, jac @ covariance @ jac.transpose(0, 2, 1), np.arctan2(py, px),
                    inv_norm, normal, (jac @ offset.T[:, :, None])[:, :, 0],
                    offset[:2].T * to_normal)


def _conformal_fits(returns: SegmentReturns, range_sigma: float,
                    bearing_sigma: float) -> LineFits:
    """
    Fit WCTLS lines, see :func:`_lever_sums`; there u = (d angle, d radius).

    The line (-cos angle, -sin angle, radius) moves by (sin angle, -cos angle, 0) d angle and
    (0, 0, 1) d radius: the J_WC of eq. (23) with Q = F p.
    """
    _, (px, py), inv_norm, pairs, offset = _lever_sums(returns, range_sigma, bearing_sigma,
                                                       True, False)
    var_angle, var_radius, cov_angle_radius = pairs
    normal = pairs.take(_SQUARE[2], axis=0).T.reshape(-1, 2, 2)
    count = len(px)
    minus_cos, sin = px * -inv_norm, py * inv_norm
    line = np.empty((count, 3))
    line[:, 0], line[:, 1], line[:, 2] = minus_cos, py * -inv_norm, inv_norm
    # d line = (sin, -cos, 0) d angle + (0, 0, 1) d radius.
    sin_var = sin * var_angle
    line_covariance = np.empty((count, 3, 3))
    line_covariance[:, 0, 0] = sin * sin_var
    line_covariance[:, 0, 1] = line_covariance[:, 1, 0] = minus_cos * sin_var
    line_covariance[:, 1, 1] = minus_cos * (minus_cos * var_angle)
    line_covariance[:, 0, 2] = line_covariance[:, 2, 0] = sin * cov_angle_radius
    line_covariance[:, 1, 2] = line_covariance[:, 2, 1] = minus_cos * cov_angle_radius
    line_covariance[:, 2, 2] = var_radius
    line_offset = np.empty((count, 3))
    line_offset[:, 0], line_offset[:, 1], line_offset[:, 2] = (sin * offset[0],
                                                               minus_cos * offset[0], offset[1])
    return LineFits(line, line_covariance, np.arctan2(py, px), inv_norm, normal, line_offset,
                    offset.T)


def utls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Unweighted algebraic fit of eqs. (2)-(4) with the covariance of eqs. (6)-(7) (corrected).

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3), covariance (S, 3, 3), offset Jacobian (S, 3))
    """
    fits = _algebraic_fits(returns, range_sigma, bearing_sigma, False)
    return fits.line, fits.line_covariance, fits.line_offset_jacobian


def wtls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Weighted algebraic fit of eqs. (8)-(12) with the covariance of eqs. (14)-(15) (corrected).

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3), covariance (S, 3, 3), offset Jacobian (S, 3))
    """
    fits = _algebraic_fits(returns, range_sigma, bearing_sigma, True)
    return fits.line, fits.line_covariance, fits.line_offset_jacobian


def wctls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Weighted conformal fit of eqs. (16)-(23): the normalised line from the point Q.

    Q is the weighted least-squares solution of x_Q x - y_Q y = 1 with the WTLS weights, and C_Q
    its exact first-order covariance (docs/derivation.md#wctls, (D9); the paper never defines
    C_Q).

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3) with a^2 + b^2 = 1 and c > 0, covariance (S, 3, 3) of rank 2, offset
        Jacobian (S, 3))
    """
    fits = _conformal_fits(returns, range_sigma, bearing_sigma)
    return fits.line, fits.line_covariance, fits.line_offset_jacobian


def line_angle_radius(line: np.ndarray):
    """
    Return the normal form of implicit lines a x + b y + c = 0 (no covariance).

    :param line: (a, b, c), shape (S, 3)
    :return: (angle (S,) rad in (-pi, pi], radius (S,) m >= 0; NaN where a = b = 0)
    """
    a, b, c = line.T
    sign = np.where(c > 0.0, -1.0, 1.0)            # so that radius = -sign c / |(a, b)| >= 0
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.arctan2(sign * b, sign * a), -sign * c / np.hypot(a, b)


def normal_jacobian(line: np.ndarray) -> np.ndarray:
    """Return d(angle, radius) / d(a, b, c) of implicit lines, shape (S, 2, 3)."""
    a, b, c = line.T
    n2 = a * a + b * b
    n = np.sqrt(n2)
    sign = np.where(c > 0.0, -1.0, 1.0)
    jac = np.zeros((len(a), 2, 3))
    with np.errstate(divide='ignore', invalid='ignore'):   # a = b = 0 gives NaN, caught later
        jac[:, 0, 0], jac[:, 0, 1] = -b / n2, a / n2
        jac[:, 1, 0], jac[:, 1, 1] = sign * c * a / (n2 * n), sign * c * b / (n2 * n)
        jac[:, 1, 2] = -sign / n
    return jac


def normal_form(line: np.ndarray, line_covariance: np.ndarray):
    """
    Convert implicit lines a x + b y + c = 0 to x cos(angle) + y sin(angle) = radius >= 0.

    :param line: (a, b, c), shape (S, 3)
    :param line_covariance: shape (S, 3, 3)
    :return: (angle (S,) rad, radius (S,) m, covariance of (angle, radius) (S, 2, 2))
    """
    jac = normal_jacobian(line)
    return (*line_angle_radius(line), jac @ line_covariance @ jac.transpose(0, 2, 1))


def implicit_from_normal(angle: np.ndarray, radius: np.ndarray, covariance: np.ndarray):
    """
    Convert normal-form lines to L = (cos angle, sin angle, -radius) with covariance J C J^T.

    :param angle: shape (S,), rad
    :param radius: shape (S,), m
    :param covariance: covariance of (angle, radius), shape (S, 2, 2)
    :return: (line (S, 3), covariance (S, 3, 3), Jacobian d line / d(angle, radius) (S, 3, 2))
    """
    c, s = np.cos(angle), np.sin(angle)
    jac = np.zeros((len(c), 3, 2))
    jac[:, 0, 0], jac[:, 1, 0], jac[:, 2, 1] = -s, c, -1.0
    return (np.column_stack([c, s, -radius]), jac @ covariance @ jac.transpose(0, 2, 1), jac)


# A singular Fisher information (e.g. every return on one ray) yields NaN or inf, not warnings.
@np.errstate(divide='ignore', invalid='ignore')
def ml(returns: SegmentReturns, range_sigma: float, bearing_sigma: float,
       start_angle: np.ndarray, start_radius: np.ndarray):
    """
    Maximum-likelihood line (Pfister et al. 2003) with the inverse Fisher information.

    Minimises sum d_i^2 / s_i^2, d_i = rho_i cos(theta_i - angle) - radius,
    s_i^2 = range_sigma^2 cos^2(theta_i - angle) + bearing_sigma^2 rho_i^2 sin^2(theta_i - angle),
    by Gauss-Newton with the variances re-evaluated at each iterate; all segments iterate
    together until every step is below ML_STEP_TOLERANCE (or ML_MAX_ITERATIONS). The covariance
    is the inverse Fisher information F^-1 = [[C, B], [B, A]] / det F (:func:`_ml_sums`), and
    the offset Jacobian d(angle, radius) / d(offset of every range) is -F^-1 (sum iv g cos,
    -sum iv cos), from the estimating equations sum_i s_i^-2 (g_i, -1) d_i = 0 (first order).

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :param start_angle: initial normal angles, shape (S,), rad (e.g. the WTLS line)
    :param start_radius: initial radii, shape (S,), m
    :return: (angle (S,), radius (S,), covariance of (angle, radius) (S, 2, 2),
        d(angle, radius) / d(common range offset) (S, 2))
    """
    angle = np.array(start_angle, dtype=float)
    radius = np.array(start_radius, dtype=float)
    inv_rho = 1.0 / returns.rho
    for _ in range(ML_MAX_ITERATIONS):
        sums, inv_det = _ml_sums(returns, inv_rho, angle, radius, range_sigma, bearing_sigma)
        step = _ml_solve(sums, inv_det, 3)
        angle += step[0]
        radius += step[1]
        if not np.count_nonzero(np.abs(step) > ML_STEP_TOLERANCE):
            break
    sums, inv_det = _ml_sums(returns, inv_rho, angle, radius, range_sigma, bearing_sigma)
    offset = _ml_solve(sums, inv_det, 5)
    flip = radius < 0.0
    angle = np.where(flip, angle + np.pi, angle)
    angle = np.angle(np.exp(1j * angle))
    # Reflecting (angle, radius) -> (angle + pi, -radius) flips the sign of their correlation.
    sign = np.where(flip, -1.0, 1.0)
    offset[1] *= sign
    covariance = np.empty((len(angle), 2, 2))      # F^-1 = [[C, B], [B, A]] / det F
    covariance[:, 0, 0] = sums[0] * inv_det
    covariance[:, 1, 1] = sums[2] * inv_det
    covariance[:, 0, 1] = covariance[:, 1, 0] = sums[1] * (inv_det * sign)
    return angle, np.abs(radius), covariance, offset.T


def _ml_sums(returns, inv_rho, angle, radius, range_sigma, bearing_sigma):
    """
    Return the sums of the Gauss-Newton system and 1 / det F at the lines (angle, radius).

    With the residual d_i, its gradient (g_i, -1) by (angle, radius) and s_i^-2 as iv_i, the
    rows are C = sum iv, B = sum iv g, A = sum iv g^2 (the Fisher information
    F = [[A, -B], [-B, C]]), sum iv d, sum iv g d, sum iv cos(theta_i - angle),
    sum iv g cos(theta_i - angle). The variances s_i^2 use the range to the current line along
    each beam instead of the measured range: a weight computed from the noisy range would
    correlate with the residual and bias the line (by several mm at grazing incidence).
    rho cos(theta - angle) and rho sin(theta - angle) are x cos + y sin and y cos - x sin of the
    angle, so no trigonometric function runs per return.

    :return: (sums (7, S), 1 / det F (S,))
    """
    # Each segment's line, repeated to every one of its returns.
    cos, sin, line_radius = np.array([np.cos(angle), np.sin(angle), radius]).repeat(
        returns.counts, axis=1)
    x, y = returns.x, returns.y
    along = cos * x + sin * y                      # rho cos(theta - angle)
    across = -sin * x + cos * y                    # rho sin(theta - angle)
    cos_d = along * inv_rho
    residual = along - line_radius
    g_angle = line_radius * across / along         # d residual / d angle; d / d radius = -1
    # The rows of the sums, each written once into the array that is summed.
    columns = np.empty((7, len(x)))
    columns[0] = inv_var = 1.0 / (range_sigma ** 2 * (cos_d * cos_d)
                                  + bearing_sigma ** 2 * (g_angle * g_angle))
    columns[1] = inv_var_g = inv_var * g_angle
    columns[2] = inv_var_g * g_angle
    columns[3], columns[4] = inv_var * residual, inv_var_g * residual
    columns[5], columns[6] = inv_var * cos_d, inv_var_g * cos_d
    sums = np.add.reduceat(columns, returns.offsets, axis=1)
    return sums, 1.0 / (sums[2] * sums[0] - sums[1] * sums[1])


def _ml_solve(sums, inv_det, row):
    """
    Return -F^-1 (sum iv g q, -sum iv q) for the pair of rows (sum iv q, sum iv g q) at ``row``.

    q = d gives the Gauss-Newton step; q = cos(theta - angle) the offset Jacobian
    d(angle, radius) / d(offset of every range), from the estimating equations
    sum_i s_i^-2 (g_i, -1) d_i = 0 (first order). Shape (2, S).
    """
    return (sums[1:3] * sums[row] - sums[:2] * sums[row + 1]) * inv_det


def fit_lines(method: str, returns: SegmentReturns, range_sigma: float,
              bearing_sigma: float) -> LineFits:
    """
    Fit every segment with one method and report it in both forms.

    UTLS and WTLS: eqs. (2)-(4) / (8)-(12) with the covariance of (6)-(7) / (14)-(15)
    (corrected); WCTLS: eqs. (16)-(23) with C_Q of (D9); ML: Gauss-Newton from the WTLS line
    with the inverse Fisher information (docs/derivation.md#maximum-likelihood).

    :param method: 'utls', 'wtls', 'wctls' or 'ml'
    :param returns: the segments' returns (each segment with >= 2 returns)
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: the fits
    :raises ValueError: on an unknown method
    """
    if method == 'ml':
        start = line_angle_radius(_algebraic_line(_weighted_sums(returns, True)[-1]))  # WTLS
        angle, radius, covariance, offset = ml(returns, range_sigma, bearing_sigma, *start)
        line, line_covariance, jac = implicit_from_normal(angle, radius, covariance)
        return LineFits(line, line_covariance, angle, radius, covariance,
                        np.einsum('sij,sj->si', jac, offset), offset)
    if method == 'wctls':
        return _conformal_fits(returns, range_sigma, bearing_sigma)
    if method not in ('utls', 'wtls'):
        raise ValueError(f'unknown line fit {method!r}; use one of utls, wtls, wctls, ml')
    return _algebraic_fits(returns, range_sigma, bearing_sigma, method == 'wtls')
