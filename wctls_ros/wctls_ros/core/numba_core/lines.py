# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Line fits with first-order covariance, compiled loops over each segment's returns.

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

import math

import numpy as np

from ._jit import jit
from ..config import METHODS
from ..features import LineFits, SegmentReturns
from ..records import Noise
from ..rules import ML_MAX_ITERATIONS, ML_STEP_TOLERANCE


def _fits(method: str, returns: SegmentReturns, range_sigma: float,
          bearing_sigma: float) -> LineFits:
    """Run :func:`fit_segments` on a bundle of returns and wrap its arrays."""
    with np.errstate(divide='ignore', invalid='ignore'):
        return LineFits(*fit_segments(
            METHODS.index(method), returns.rho, returns.theta, returns.x, returns.y,
            returns.offsets, returns.counts,
            Noise(float(range_sigma), float(bearing_sigma), float(range_sigma))))


def utls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Compiled twin of :func:`..numpy_core.lines.utls`.

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3), covariance (S, 3, 3), offset Jacobian (S, 3))
    """
    fits = _fits('utls', returns, range_sigma, bearing_sigma)
    return fits.line, fits.line_covariance, fits.line_offset_jacobian


def wtls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Compiled twin of :func:`..numpy_core.lines.wtls`.

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3), covariance (S, 3, 3), offset Jacobian (S, 3))
    """
    fits = _fits('wtls', returns, range_sigma, bearing_sigma)
    return fits.line, fits.line_covariance, fits.line_offset_jacobian


def wctls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Compiled twin of :func:`..numpy_core.lines.wctls`.

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3) with a^2 + b^2 = 1 and c > 0, covariance (S, 3, 3) of rank 2, offset
        Jacobian (S, 3))
    """
    fits = _fits('wctls', returns, range_sigma, bearing_sigma)
    return fits.line, fits.line_covariance, fits.line_offset_jacobian


def normal_jacobian(line: np.ndarray) -> np.ndarray:
    """Compiled twin of :func:`..numpy_core.lines.normal_jacobian`: shape (S, 2, 3)."""
    with np.errstate(divide='ignore', invalid='ignore'):
        return normal_jacobians(np.asarray(line, dtype=float))


def normal_form(line: np.ndarray, line_covariance: np.ndarray):
    """
    Compiled twin of :func:`..numpy_core.lines.normal_form` (its Jacobian compiled).

    :param line: (a, b, c), shape (S, 3)
    :param line_covariance: shape (S, 3, 3)
    :return: (angle (S,) rad, radius (S,) m, covariance of (angle, radius) (S, 2, 2))
    """
    a, b, c = np.asarray(line, dtype=float).T
    sign = np.where(c > 0.0, -1.0, 1.0)            # so that radius = -sign c / |(a, b)| >= 0
    jac = normal_jacobian(line)
    with np.errstate(divide='ignore', invalid='ignore'):
        return (np.arctan2(sign * b, sign * a), -sign * c / np.hypot(a, b),
                jac @ line_covariance @ jac.transpose(0, 2, 1))


def fit_lines(method: str, returns: SegmentReturns, range_sigma: float,
              bearing_sigma: float) -> LineFits:
    """
    Compiled twin of :func:`..numpy_core.lines.fit_lines`.

    :param method: 'utls', 'wtls', 'wctls' or 'ml'
    :param returns: the segments' returns (each segment with >= 2 returns)
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: the fits
    :raises ValueError: on an unknown method
    """
    if method not in METHODS:
        raise ValueError(f'unknown line fit {method!r}; use one of utls, wtls, wctls, ml')
    return _fits(method, returns, range_sigma, bearing_sigma)


_UTLS, _WTLS, _WCTLS, _ML = (METHODS.index(method) for method in ('utls', 'wtls', 'wctls', 'ml'))


@jit
def _moment_sums(x, y, rho, first, stop, weighted):
    """
    Compiled twin of :func:`..numpy_core.lines._weighted_sums` for the returns first..stop-1.

    :return: (sum w x, sum w y, sum w x^2, sum w y^2, sum w x y), w = 1 / rho^2 when weighted,
        else 1
    """
    s_x = s_y = s_xx = s_yy = s_xy = 0.0
    for i in range(first, stop):
        inv_rho = 1.0 / rho[i]
        weight = inv_rho * inv_rho if weighted else 1.0
        wx, wy = weight * x[i], weight * y[i]
        s_x += wx
        s_y += wy
        s_xx += wx * x[i]
        s_yy += wy * y[i]
        s_xy += wx * y[i]
    return s_x, s_y, s_xx, s_yy, s_xy


@jit
def _lever_segment(x, y, rho, first, stop, range_sigma, bearing_sigma, weighted, scaled,
                   covariance, offset):
    """
    Compiled twin of :func:`..numpy_core.lines._lever_sums` for one segment.

    The per-return products are summed in scalars, not in small arrays: the compiler keeps
    scalars in registers, where it must store every array entry (it cannot tell that an array
    does not alias the returns), and the six distinct entries of each symmetric product are
    summed once (a product is the same either way round, so the sums are too).

    :param covariance: written: the covariance of u, its top-left (k, k) block, shape (3, 3)
    :param offset: written: its offset Jacobian, the first k entries, shape (3,)
    :return: (a, b, c, p_x, p_y, 1 / |p|), k = 3 if scaled else 2
    """
    s_x, s_y, s_xx, s_yy, s_xy = _moment_sums(x, y, rho, first, stop, weighted)
    a, b, c = s_x * s_yy - s_y * s_xy, s_y * s_xx - s_x * s_xy, s_xy * s_xy - s_xx * s_yy
    inv_det = -1.0 / c
    px, py = a * inv_det, b * inv_det
    inv_norm = 1.0 / math.hypot(px, py)
    if scaled:
        to_angle = to_radius = inv_det
    else:
        to_angle = inv_norm * inv_norm * inv_det
        to_radius = -inv_norm * to_angle
    a_x, a_y = -py * to_angle, px * to_angle
    b_x, b_y = px * to_radius, py * to_radius
    pi_x0, pi_x1 = a_x * s_yy - a_y * s_xy, b_x * s_yy - b_y * s_xy          # Pi e_x
    pi_y0, pi_y1 = a_y * s_xx - a_x * s_xy, b_y * s_xx - b_x * s_xy          # Pi e_y
    # The upper triangles of the range and bearing products, and the offset.
    range00 = range01 = range02 = range11 = range12 = range22 = 0.0
    bearing00 = bearing01 = bearing02 = bearing11 = bearing12 = bearing22 = 0.0
    offset0 = offset1 = offset2 = 0.0
    by_range2 = by_bearing2 = 0.0              # the third components, when not scaled
    for i in range(first, stop):
        x_i, y_i, inv_rho = x[i], y[i], 1.0 / rho[i]
        # Pi z_i, p.z_i, Pi z_perp_i, p.z_perp_i.
        along0, along1 = pi_x0 * x_i + pi_y0 * y_i, pi_x1 * x_i + pi_y1 * y_i
        ahead = px * x_i + py * y_i
        across0, across1 = pi_y0 * x_i - pi_x0 * y_i, pi_y1 * x_i - pi_x1 * y_i
        turn = py * x_i - px * y_i
        # -du/drho_i (the sign is undone in the offset), then du/dtheta_i.
        if weighted:
            weight = inv_rho * inv_rho
            by_range0, by_range1 = along0 * (weight * inv_rho), along1 * (weight * inv_rho)
        else:
            lever = (2.0 * ahead - 1.0) * inv_rho
            by_range0, by_range1 = along0 * lever, along1 * lever
        if scaled:
            by_range2 = 0.0 if weighted else (turn * along0 - ahead * along1) * inv_rho
        by_bearing0 = (1.0 - ahead) * across0 - turn * along0
        by_bearing1 = (1.0 - ahead) * across1 - turn * along1
        if scaled:
            by_bearing2 = ahead * across1 - turn * across0
        if weighted:
            by_bearing0 *= weight
            by_bearing1 *= weight
            by_bearing2 *= weight
        offset0 -= by_range0
        offset1 -= by_range1
        range00 += by_range0 * by_range0
        range01 += by_range0 * by_range1
        range11 += by_range1 * by_range1
        bearing00 += by_bearing0 * by_bearing0
        bearing01 += by_bearing0 * by_bearing1
        bearing11 += by_bearing1 * by_bearing1
        if scaled:
            offset2 -= by_range2
            range02 += by_range0 * by_range2
            range12 += by_range1 * by_range2
            range22 += by_range2 * by_range2
            bearing02 += by_bearing0 * by_bearing2
            bearing12 += by_bearing1 * by_bearing2
            bearing22 += by_bearing2 * by_bearing2
    _put_symmetric(covariance, range00, range01, range02, range11, range12, range22,
                   range_sigma)
    if bearing_sigma != 0.0:           # a zero bearing sigma adds nothing, not 0 * inf
        _add_symmetric(covariance, bearing00, bearing01, bearing02, bearing11, bearing12,
                       bearing22, bearing_sigma)
    offset[0], offset[1], offset[2] = offset0, offset1, offset2
    return a, b, c, px, py, inv_norm


@jit
def _put_symmetric(out, m00, m01, m02, m11, m12, m22, sigma):
    """Write sigma^2 times the symmetric 3 x 3 matrix of the upper triangle m into ``out``."""
    out[0, 0] = sigma ** 2 * m00
    out[0, 1] = out[1, 0] = sigma ** 2 * m01
    out[0, 2] = out[2, 0] = sigma ** 2 * m02
    out[1, 1] = sigma ** 2 * m11
    out[1, 2] = out[2, 1] = sigma ** 2 * m12
    out[2, 2] = sigma ** 2 * m22


@jit
def _add_symmetric(out, m00, m01, m02, m11, m12, m22, sigma):
    """Add sigma^2 times the symmetric 3 x 3 matrix of the upper triangle m to ``out``."""
    out[0, 0] += sigma ** 2 * m00
    out[0, 1] += sigma ** 2 * m01
    out[1, 0] += sigma ** 2 * m01
    out[0, 2] += sigma ** 2 * m02
    out[2, 0] += sigma ** 2 * m02
    out[1, 1] += sigma ** 2 * m11
    out[1, 2] += sigma ** 2 * m12
    out[2, 1] += sigma ** 2 * m12
    out[2, 2] += sigma ** 2 * m22


@jit
def _sandwich(jacobian, covariance, out):
    """Write J C J^T into ``out`` (m, m) for a small Jacobian J (m, k) and covariance C (k, k)."""
    rows, inner = jacobian.shape
    for r in range(rows):
        for c in range(rows):
            total = 0.0
            for k in range(inner):
                moved = 0.0
                for m in range(inner):
                    moved += jacobian[r, m] * covariance[m, k]
                total += moved * jacobian[c, k]
            out[r, c] = total


@jit
def _times(jacobian, vector, out):
    """Write J v into ``out`` (m,) for a small Jacobian J (m, k) and vector v (k,)."""
    for r in range(jacobian.shape[0]):
        total = 0.0
        for k in range(jacobian.shape[1]):
            total += jacobian[r, k] * vector[k]
        out[r] = total


@jit
def fit_segments(method_code, rho, theta, x, y, offsets, counts, noise):
    """
    Compiled twin of :func:`..numpy_core.lines.fit_lines`, one segment at a time.

    The returns come as arrays laid end to end and the method as its code, so that the pipeline's
    compiled function calls it; :func:`fit_lines` wraps it for Python.

    :param method_code: METHODS.index of the method: utls 0, wtls 1, wctls 2, ml 3
    :param rho: ranges of the returns laid end to end, shape (P,), m
    :param theta: bearings, shape (P,), rad
    :param x: rho cos(theta), shape (P,), m
    :param y: rho sin(theta), shape (P,), m
    :param offsets: first return of each segment, shape (S,)
    :param counts: returns per segment, shape (S,)
    :param noise: the noise (the fits weigh the returns by its range_sigma_m and
        bearing_sigma_rad)
    :return: (line (S, 3), its covariance (S, 3, 3), angle (S,) rad, radius (S,) m, covariance of
        (angle, radius) (S, 2, 2), d line / d offset (S, 3), d (angle, radius) / d offset (S, 2))
    """
    range_sigma, bearing_sigma = noise.range_sigma_m, noise.bearing_sigma_rad
    count = offsets.size
    line = np.empty((count, 3))
    line_covariance = np.empty((count, 3, 3))
    angle, radius = np.empty(count), np.empty(count)
    normal_covariance = np.empty((count, 2, 2))
    line_offset, normal_offset = np.empty((count, 3)), np.empty((count, 2))
    if method_code == _ML:
        angle, radius, normal_covariance, normal_offset = _ml_fits(rho, theta, x, y, offsets,
                                                                   counts, noise)
        to_line = np.zeros((3, 2))                 # d line / d(angle, radius)
        to_line[2, 1] = -1.0
        for s in range(count):
            c, sn = math.cos(angle[s]), math.sin(angle[s])
            to_line[0, 0], to_line[1, 0] = -sn, c
            line[s, 0], line[s, 1], line[s, 2] = c, sn, -radius[s]
            _sandwich(to_line, normal_covariance[s], line_covariance[s])
            _times(to_line, normal_offset[s], line_offset[s])
        return (line, line_covariance, angle, radius, normal_covariance, line_offset,
                normal_offset)
    weighted, scaled = method_code != _UTLS, method_code != _WCTLS
    to_line = np.zeros((3, 3))
    # Each segment's covariance of u and its offset Jacobian, written by _lever_segment: (k, k)
    # and (k,) of them, k = 3 if scaled else 2.
    pairs, whole_offset = np.empty((3, 3)), np.empty(3)
    offset = whole_offset[:3 if scaled else 2]
    for s in range(count):
        own_a, own_b, own_c, p_x, p_y, inv_norm = _lever_segment(
            x, y, rho, offsets[s], offsets[s] + counts[s], range_sigma, bearing_sigma, weighted,
            scaled, pairs, whole_offset)
        angle[s], radius[s] = math.atan2(p_y, p_x), inv_norm
        if scaled:
            # (a, b, c) = s (p, -1): d(a, b, c) = K u, K = (s / |p|^2) [(p_perp, 0), (p, 0),
            # 2 (p, -1)] by columns; d(angle, radius) = (u_1 / |p|^2, -u_2 / |p|^3).
            inv_n2 = inv_norm * inv_norm
            scale = -own_c * inv_n2
            to_line[0, 0], to_line[0, 1], to_line[0, 2] = -p_y * scale, p_x * scale, (
                2.0 * p_x * scale)
            to_line[1, 0], to_line[1, 1], to_line[1, 2] = p_x * scale, p_y * scale, (
                2.0 * p_y * scale)
            to_line[2, 2] = -2.0 * scale
            line[s, 0], line[s, 1], line[s, 2] = own_a, own_b, own_c
            _sandwich(to_line, pairs, line_covariance[s])
            _times(to_line, offset, line_offset[s])
            to_angle, to_radius = inv_n2, -inv_n2 * inv_norm
            normal_covariance[s, 0, 0] = pairs[0, 0] * to_angle * to_angle
            normal_covariance[s, 0, 1] = pairs[0, 1] * to_angle * to_radius
            normal_covariance[s, 1, 0] = pairs[1, 0] * to_radius * to_angle
            normal_covariance[s, 1, 1] = pairs[1, 1] * to_radius * to_radius
            normal_offset[s, 0], normal_offset[s, 1] = offset[0] * to_angle, offset[1] * to_radius
        else:
            # WCTLS: (-cos, -sin, radius) moves by (sin, -cos, 0) d angle + (0, 0, 1) d radius.
            minus_cos, sin = p_x * -inv_norm, p_y * inv_norm
            var_angle, var_radius, cov_angle_radius = pairs[0, 0], pairs[1, 1], pairs[0, 1]
            line[s, 0], line[s, 1], line[s, 2] = minus_cos, p_y * -inv_norm, inv_norm
            sin_var = sin * var_angle
            line_covariance[s, 0, 0] = sin * sin_var
            line_covariance[s, 0, 1] = line_covariance[s, 1, 0] = minus_cos * sin_var
            line_covariance[s, 1, 1] = minus_cos * (minus_cos * var_angle)
            line_covariance[s, 0, 2] = line_covariance[s, 2, 0] = sin * cov_angle_radius
            line_covariance[s, 1, 2] = line_covariance[s, 2, 1] = minus_cos * cov_angle_radius
            line_covariance[s, 2, 2] = var_radius
            normal_covariance[s, 0, 0], normal_covariance[s, 1, 1] = var_angle, var_radius
            normal_covariance[s, 0, 1] = normal_covariance[s, 1, 0] = cov_angle_radius
            line_offset[s, 0], line_offset[s, 1] = sin * offset[0], minus_cos * offset[0]
            line_offset[s, 2] = offset[1]
            normal_offset[s, 0], normal_offset[s, 1] = offset[0], offset[1]
    return line, line_covariance, angle, radius, normal_covariance, line_offset, normal_offset


@jit
def _ml_sums(x, y, rho, first, stop, angle, radius, range_sigma, bearing_sigma, sums):
    """
    Compiled twin of :func:`..numpy_core.lines._ml_sums` for one segment, written into ``sums``.

    :param sums: shape (7,), for sum iv, iv g, iv g^2, iv d, iv g d, iv cos, iv g cos
    """
    c, s = math.cos(angle), math.sin(angle)
    sums[:] = 0.0
    for i in range(first, stop):
        along = c * x[i] + s * y[i]                       # rho cos(theta - angle)
        across = -s * x[i] + c * y[i]                     # rho sin(theta - angle)
        cos_d = along * (1.0 / rho[i])
        residual = along - radius
        g_angle = radius * across / along
        inv_var = 1.0 / (range_sigma ** 2 * (cos_d * cos_d)
                         + bearing_sigma ** 2 * (g_angle * g_angle))
        inv_var_g = inv_var * g_angle
        sums[0] += inv_var
        sums[1] += inv_var_g
        sums[2] += inv_var_g * g_angle
        sums[3] += inv_var * residual
        sums[4] += inv_var_g * residual
        sums[5] += inv_var * cos_d
        sums[6] += inv_var_g * cos_d


@jit
def _ml_fits(rho, theta, x, y, offsets, counts, noise):
    """
    Compiled twin of :func:`..numpy_core.lines.ml`, starting from the WTLS line it fits itself.

    :return: (angle (S,) rad, radius (S,) m, covariance of (angle, radius) (S, 2, 2),
        d(angle, radius) / d offset (S, 2))
    """
    range_sigma, bearing_sigma = noise.range_sigma_m, noise.bearing_sigma_rad
    count = offsets.size
    angle, radius = np.empty(count), np.empty(count)
    covariance, normal_offset = np.empty((count, 2, 2)), np.empty((count, 2))
    for s in range(count):
        s_x, s_y, s_xx, s_yy, s_xy = _moment_sums(x, y, rho, offsets[s], offsets[s] + counts[s],
                                                  True)
        a, b, c = s_x * s_yy - s_y * s_xy, s_y * s_xx - s_x * s_xy, s_xy * s_xy - s_xx * s_yy
        sign = -1.0 if c > 0.0 else 1.0
        angle[s], radius[s] = math.atan2(sign * b, sign * a), -sign * c / math.hypot(a, b)
    sums = np.empty((count, 7))
    for _ in range(ML_MAX_ITERATIONS):
        moving = False
        for s in range(count):
            _ml_sums(x, y, rho, offsets[s], offsets[s] + counts[s], angle[s], radius[s],
                     range_sigma, bearing_sigma, sums[s])
        for s in range(count):
            f = sums[s]
            inv_det = 1.0 / (f[2] * f[0] - f[1] * f[1])
            step_angle = (f[1] * f[3] - f[0] * f[4]) * inv_det
            step_radius = (f[2] * f[3] - f[1] * f[4]) * inv_det
            angle[s] += step_angle
            radius[s] += step_radius
            moving |= abs(step_angle) > ML_STEP_TOLERANCE or abs(step_radius) > ML_STEP_TOLERANCE
        if not moving:
            break
    for s in range(count):
        f = sums[s]
        _ml_sums(x, y, rho, offsets[s], offsets[s] + counts[s], angle[s], radius[s], range_sigma,
                 bearing_sigma, f)
        inv_det = 1.0 / (f[2] * f[0] - f[1] * f[1])
        normal_offset[s, 0] = (f[1] * f[5] - f[0] * f[6]) * inv_det
        normal_offset[s, 1] = (f[2] * f[5] - f[1] * f[6]) * inv_det
        # Reflecting (angle, radius) -> (angle + pi, -radius) flips their correlation's sign.
        sign = 1.0
        if radius[s] < 0.0:
            angle[s] += np.pi
            sign = -1.0
        angle[s] = math.atan2(math.sin(angle[s]), math.cos(angle[s]))
        normal_offset[s, 1] *= sign
        covariance[s, 0, 0] = f[0] * inv_det
        covariance[s, 1, 1] = f[2] * inv_det
        covariance[s, 0, 1] = covariance[s, 1, 0] = f[1] * (inv_det * sign)
        radius[s] = abs(radius[s])
    return angle, radius, covariance, normal_offset


@jit
def residual_chi2_dof(rho, x, y, offsets, counts, lines, noise):
    """
    Compiled twin of :func:`..numpy_core.pipeline._residual_chi2_dof`, one return at a time.

    With x_i = rho_i cos theta_i and y_i = rho_i sin theta_i, rho_i cos(theta_i - angle) =
    x_i cos angle + y_i sin angle and rho_i sin(theta_i - angle) = y_i cos angle - x_i sin
    angle: no sine or cosine per return.

    :param rho: ranges of the returns laid end to end, shape (P,), m
    :param x: rho cos(theta), shape (P,), m
    :param y: rho sin(theta), shape (P,), m
    :param offsets: first return of each segment, shape (S,)
    :param counts: returns per segment, shape (S,)
    :param lines: each segment's fitted line
    :param noise: the noise model (its range_sigma_m and bearing_sigma_rad)
    :return: shape (S,)
    """
    angle_rad, radius_m = lines.angle_rad, lines.radius_m
    range_sigma, bearing_sigma = noise.range_sigma_m, noise.bearing_sigma_rad
    chi2 = np.zeros(offsets.size)
    for s in range(offsets.size):
        cos, sin = math.cos(angle_rad[s]), math.sin(angle_rad[s])
        for i in range(offsets[s], offsets[s] + counts[s]):
            along, across = x[i] * cos + y[i] * sin, y[i] * cos - x[i] * sin
            residual = along - radius_m[s]
            variance = (range_sigma * along / rho[i]) ** 2 + (bearing_sigma * across) ** 2
            chi2[s] += residual * residual / variance
        chi2[s] /= max(counts[s] - 2, 1)
    return chi2


@jit
def normal_jacobians(line):
    """
    Compiled twin of :func:`..numpy_core.lines.normal_jacobian`, one line at a time.

    :param line: (a, b, c), shape (S, 3)
    :return: shape (S, 2, 3); NaN where a = b = 0
    """
    jacobian = np.zeros((line.shape[0], 2, 3))
    for s in range(line.shape[0]):
        a, b, c = line[s, 0], line[s, 1], line[s, 2]
        n2 = a * a + b * b
        n = math.sqrt(n2)
        sign = -1.0 if c > 0.0 else 1.0
        jacobian[s, 0, 0], jacobian[s, 0, 1] = -b / n2, a / n2
        jacobian[s, 1, 0], jacobian[s, 1, 1] = sign * c * a / (n2 * n), sign * c * b / (n2 * n)
        jacobian[s, 1, 2] = -sign / n
    return jacobian
