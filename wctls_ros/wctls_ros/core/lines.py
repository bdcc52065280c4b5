"""
Line fits with first-order covariance, batched over many segments at once.

Every fit works on the returns of S segments laid end to end: ``rho`` and ``theta`` of shape
(P,), segment k owning ``rho[offsets[k]:offsets[k] + counts[k]]``. The noise is independent per
return with std ``range_sigma`` (m) and ``bearing_sigma`` (rad), and every covariance is

    C = sum_i [ range_sigma^2 (dphi/drho_i)(dphi/drho_i)^T
                + bearing_sigma^2 (dphi/dtheta_i)(dphi/dtheta_i)^T ]

with the analytic Jacobians of ``../shared/spec/math.md`` (the paper's eqs. (6)-(23) with its
typos corrected). Each method returns the line in its own implicit form a x + b y + c = 0, the
3x3 covariance of (a, b, c) and the shift of (a, b, c) per metre of a range offset common to every
return of the scan (d(a, b, c)/d offset = sum_i d(a, b, c)/d rho_i), which lets a common-mode
range error be propagated with its correlation between lines; :func:`normal_form` gives every
method's line in one common form x cos(angle) + y sin(angle) = radius, radius >= 0, with the 2x2
covariance of (angle, radius).
"""

from dataclasses import dataclass

import numpy as np

from ._linalg import inverse_2x2, solve_2x2

# Gauss-Newton of the maximum-likelihood fit stops once every step is below this (rad and m)...
_ML_STEP_TOLERANCE = 1e-12
# ... or after this many iterations (it starts from the WTLS line and converges in 2-4).
_ML_MAX_ITERATIONS = 8


@dataclass(frozen=True)
class SegmentReturns:
    """
    The returns of S segments laid end to end.

    :ivar rho: ranges, shape (P,), m
    :ivar theta: bearings, shape (P,), rad
    :ivar x: rho cos(theta), shape (P,), m
    :ivar y: rho sin(theta), shape (P,), m
    :ivar offsets: first return of each segment, shape (S,)
    :ivar counts: returns per segment, shape (S,), each >= 2
    :ivar segment: the segment each return belongs to, shape (P,)
    """

    rho: np.ndarray
    theta: np.ndarray
    x: np.ndarray
    y: np.ndarray
    offsets: np.ndarray
    counts: np.ndarray
    segment: np.ndarray

    def sums(self, values: np.ndarray) -> np.ndarray:
        """
        Sum per-return values over each segment.

        :param values: shape (P,) or (P, k)
        :return: shape (S,) or (S, k)
        """
        return np.add.reduceat(values, self.offsets, axis=0)


def segment_returns(rho, theta, offsets, counts, x=None, y=None) -> SegmentReturns:
    """
    Bundle the returns of consecutive segments for the batched fits.

    :param rho: ranges, shape (P,), m
    :param theta: bearings, shape (P,), rad
    :param offsets: first return of each segment, shape (S,)
    :param counts: returns per segment, shape (S,), each >= 2
    :param x: rho cos(theta) when already known, shape (P,), m
    :param y: rho sin(theta) when already known, shape (P,), m
    :return: the bundle
    """
    rho = np.asarray(rho, dtype=float)
    theta = np.asarray(theta, dtype=float)
    counts = np.asarray(counts, dtype=np.intp)
    if x is None or y is None:
        x, y = rho * np.cos(theta), rho * np.sin(theta)
    return SegmentReturns(rho, theta, x, y, np.asarray(offsets, dtype=np.intp), counts,
                          np.repeat(np.arange(counts.size), counts))


@dataclass(frozen=True)
class LineFits:
    """
    Fitted lines of S segments, in the method's own form and in normal form.

    :ivar line: (a, b, c) of a x + b y + c = 0 as the method defines them, shape (S, 3)
    :ivar line_covariance: covariance of (a, b, c), shape (S, 3, 3), in units of (a, b, c)^2
    :ivar angle_rad: direction of the line's normal, pointing from the origin to the line,
        shape (S,), rad in (-pi, pi]
    :ivar radius_m: distance of the line from the origin, shape (S,), m, >= 0
    :ivar normal_covariance: covariance of (angle, radius), shape (S, 2, 2): rad^2, rad m, m^2
    :ivar line_offset_jacobian: d(a, b, c) / d(range offset common to all returns), (S, 3), per m
    :ivar normal_offset_jacobian: d(angle, radius) / d(common range offset), (S, 2): rad/m, m/m
    """

    line: np.ndarray
    line_covariance: np.ndarray
    angle_rad: np.ndarray
    radius_m: np.ndarray
    normal_covariance: np.ndarray
    line_offset_jacobian: np.ndarray
    normal_offset_jacobian: np.ndarray

    def select(self, keep: np.ndarray) -> 'LineFits':
        """
        Return the fits where ``keep`` selects (a boolean or index array over the segments).

        :param keep: selection over the segments
        :return: the selected fits
        """
        return LineFits(self.line[keep], self.line_covariance[keep], self.angle_rad[keep],
                        self.radius_m[keep], self.normal_covariance[keep],
                        self.line_offset_jacobian[keep], self.normal_offset_jacobian[keep])


def _propagate(jac_rho: np.ndarray, jac_theta: np.ndarray, returns: SegmentReturns,
               range_sigma: float, bearing_sigma: float) -> np.ndarray:
    """
    Sum per-return Jacobian outer products into per-segment covariances.

    :param jac_rho: d(params)/d(rho_i), shape (P, k)
    :param jac_theta: d(params)/d(theta_i), shape (P, k)
    :return: covariance of the k parameters per segment, shape (S, k, k)
    """
    k = jac_rho.shape[1]
    rows, cols = np.triu_indices(k)                 # symmetric: sum the upper triangle only
    outer = (range_sigma ** 2 * jac_rho[:, rows] * jac_rho[:, cols]
             + bearing_sigma ** 2 * jac_theta[:, rows] * jac_theta[:, cols])
    covariance = np.empty((len(returns.counts), k, k))
    covariance[:, rows, cols] = covariance[:, cols, rows] = returns.sums(outer)
    return covariance


def _moments(returns: SegmentReturns, weight):
    """Return per-segment total weight and weighted means X, Y, X2, Y2, XY, each (S,)."""
    x, y = returns.x, returns.y
    sums = returns.sums(np.column_stack([weight, weight * x, weight * y, weight * x * x,
                                         weight * y * y, weight * x * y]))
    total = sums[:, 0]
    return total, *(sums[:, 1:] / total[:, None]).T


def _algebraic_line(total, mx, my, mxx, myy, mxy):
    """Return (a, b, c) of eqs. (2)-(4) / (10)-(12) from the (weighted) means, shape (S, 3)."""
    t2 = total * total
    return np.column_stack([t2 * (mx * myy - my * mxy), t2 * (my * mxx - mx * mxy),
                            t2 * (mxy * mxy - mxx * myy)])


def _bearing_jacobian(x, y, mx, my, mxx, myy, mxy) -> np.ndarray:
    """
    Return the bracket shared by eqs. (7d)-(7f) and (15d)-(15f): d(a, b, c)/d theta_i / scale.

    UTLS multiplies it by N, WTLS by w_i W (means weighted); shape (P, 3).
    """
    xy, dxy = x * y, x * x - y * y
    return np.column_stack([-y * myy + 2 * xy * mx - x * mxy - dxy * my,
                            x * mxx - 2 * xy * my + y * mxy - dxy * mx,
                            2 * (dxy * mxy + xy * (myy - mxx))])


def utls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Unweighted algebraic fit of eqs. (2)-(4) with the covariance of eqs. (6)-(7) (corrected).

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3), covariance (S, 3, 3), offset Jacobian (S, 3))
    """
    total, mx, my, mxx, myy, mxy = _moments(returns, np.ones_like(returns.rho))
    line = _algebraic_line(total, mx, my, mxx, myy, mxy)
    s = returns.segment
    n, mx, my, mxx, myy, mxy = total[s], mx[s], my[s], mxx[s], myy[s], mxy[s]
    x, y, rho = returns.x, returns.y, returns.rho
    xy = x * y
    jac_rho = (n / rho)[:, None] * np.column_stack([
        x * myy + 2 * y * y * mx - y * mxy - 2 * xy * my,
        y * mxx + 2 * x * x * my - x * mxy - 2 * xy * mx,
        2 * (2 * xy * mxy - x * x * myy - y * y * mxx)])
    jac_theta = n[:, None] * _bearing_jacobian(x, y, mx, my, mxx, myy, mxy)
    return (line, _propagate(jac_rho, jac_theta, returns, range_sigma, bearing_sigma),
            returns.sums(jac_rho))


def _range_weights(returns: SegmentReturns):
    """
    Return the WTLS weights, proportional to eq. (8): w_i = 1 / rho_i^2.

    The paper's constant factor 1 / (range_sigma bearing_sigma)^2 is left out: it scales
    (a_w, b_w, c_w) by a constant, which cancels in the normal form, in the WCTLS point Q and in
    every corner, and it is undefined for a zero bearing sigma.
    """
    return 1.0 / (returns.rho * returns.rho)


def wtls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Weighted algebraic fit of eqs. (8)-(12) with the covariance of eqs. (14)-(15) (corrected).

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3), covariance (S, 3, 3), offset Jacobian (S, 3))
    """
    w = _range_weights(returns)
    total, mx, my, mxx, myy, mxy = _moments(returns, w)
    line = _algebraic_line(total, mx, my, mxx, myy, mxy)
    s = returns.segment
    ww = w * total[s]
    mx, my, mxx, myy, mxy = mx[s], my[s], mxx[s], myy[s], mxy[s]
    x, y = returns.x, returns.y
    jac_rho = (ww / returns.rho)[:, None] * np.column_stack([
        -x * myy + y * mxy, -y * mxx + x * mxy, np.zeros_like(x)])
    jac_theta = ww[:, None] * _bearing_jacobian(x, y, mx, my, mxx, myy, mxy)
    return (line, _propagate(jac_rho, jac_theta, returns, range_sigma, bearing_sigma),
            returns.sums(jac_rho))


def wctls(returns: SegmentReturns, range_sigma: float, bearing_sigma: float):
    """
    Weighted conformal fit of eqs. (16)-(23): the normalised line from the point Q.

    Q is the weighted least-squares solution of x_Q x - y_Q y = 1 with the WTLS weights, and C_Q
    its exact first-order covariance (math.md; the paper never defines C_Q).

    :param returns: the segments' returns
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (line (S, 3) with a^2 + b^2 = 1 and c > 0, covariance (S, 3, 3) of rank 2, offset
        Jacobian (S, 3))
    """
    w = _range_weights(returns)
    total, mx, my, mxx, myy, mxy = _moments(returns, w)
    # p solves M p = g with M = sum w z z^T, g = sum w z (divided through by the total weight);
    # M^-1 = [[i_xx, i_xy], [i_xy, i_yy]] (symmetric).
    with np.errstate(divide='ignore', invalid='ignore'):
        inv_det = 1.0 / (mxx * myy - mxy * mxy)
    i_xx, i_xy, i_yy = myy * inv_det, -mxy * inv_det, mxx * inv_det
    px, py = i_xx * mx + i_xy * my, i_xy * mx + i_yy * my
    s = returns.segment
    x, y = returns.x, returns.y
    k = w / total[s]
    a, b, d = i_xx[s], i_xy[s], i_yy[s]
    # dp/drho_i = -w_i M^-1 z_i / rho_i ;
    # dp/dtheta_i = w_i M^-1 ((1 - p.z_i) z_perp_i - z_i (p.z_perp_i)), z_perp = (-y, x).
    scale = -k / returns.rho
    jac_rho = np.empty((len(x), 2))
    jac_rho[:, 0] = scale * (a * x + b * y)
    jac_rho[:, 1] = scale * (b * x + d * y)
    pxs, pys = px[s], py[s]
    residual = 1.0 - pxs * x - pys * y
    turn = pys * x - pxs * y                       # p . z_perp
    qx, qy = -residual * y - x * turn, residual * x - y * turn
    jac_theta = np.empty((len(x), 2))
    jac_theta[:, 0] = k * (a * qx + b * qy)
    jac_theta[:, 1] = k * (b * qx + d * qy)
    cov_p = _propagate(jac_rho, jac_theta, returns, range_sigma, bearing_sigma)
    flip = np.array([1.0, -1.0])
    xq, yq = px, -py                               # Q = F p, F = diag(1, -1)
    cov_q = cov_p * flip[:, None] * flip[None, :]
    offset_q = returns.sums(jac_rho) * flip
    norm = np.hypot(xq, yq)
    line = np.column_stack([-xq, yq, np.ones_like(xq)]) / norm[:, None]
    jac = np.empty((len(xq), 3, 2))                 # J_WC of eq. (23)
    jac[:, 0, 0], jac[:, 0, 1] = -yq * yq, xq * yq
    jac[:, 1, 0], jac[:, 1, 1] = -xq * yq, xq * xq
    jac[:, 2, 0], jac[:, 2, 1] = -xq, -yq
    jac /= (norm ** 3)[:, None, None]
    return line, jac @ cov_q @ jac.transpose(0, 2, 1), np.einsum('sij,sj->si', jac, offset_q)


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


def _normal_jacobian(line: np.ndarray) -> np.ndarray:
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
    jac = _normal_jacobian(line)
    return (*line_angle_radius(line), jac @ line_covariance @ jac.transpose(0, 2, 1))


def moment_prefix_sums(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """
    Return prefix sums of the per-return quantities :func:`moment_fit` needs.

    Row i holds the sums over returns 0..i-1 of (1, x, y, x^2, y^2, x y, rho^2), so the sums
    over returns [start, stop) are ``prefix[stop] - prefix[start]``.

    :param x: shape (P,), m
    :param y: shape (P,), m
    :return: shape (P + 1, 7)
    """
    columns = np.empty((7, len(x) + 1))
    columns[:, 0] = 0.0
    rows = columns[:, 1:]
    rows[0], rows[1], rows[2] = 1.0, x, y
    np.multiply(x, x, out=rows[3])
    np.multiply(y, y, out=rows[4])
    np.multiply(x, y, out=rows[5])
    np.add(rows[3], rows[4], out=rows[6])
    np.cumsum(columns, axis=1, out=columns)
    return columns.T


def moment_fit(sums: np.ndarray, range_sigma: float, bearing_sigma: float):
    """
    Fit lines from per-segment sums alone: orthogonal regression with an isotropic covariance.

    Cheap enough to refit merged segments from prefix sums in O(1) each; meant for
    segmentation decisions, not for the published covariance. Each return is taken to scatter
    isotropically with variance range_sigma^2 + bearing_sigma^2 rho^2 (an upper bound of its
    scatter across the line), which gives Var(angle) = s2 / (N L), Cov(angle, radius) = d Var
    (angle), Var(radius) = s2 / N + d^2 Var(angle), with L the variance of the returns along the
    line and d the offset of their centroid from the foot of the perpendicular.

    :param sums: per-segment sums, differences of :func:`moment_prefix_sums`, shape (S, 7)
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: (angle (S,) rad, radius (S,) m, covariance of (angle, radius) (S, 2, 2))
    """
    n = sums[:, 0]
    mx, my, mxx, myy, mxy, mrr = (sums[:, 1:] / n[:, None]).T
    cxx, cyy, cxy = mxx - mx * mx, myy - my * my, mxy - mx * my
    angle = 0.5 * np.arctan2(-2.0 * cxy, cyy - cxx)        # normal: the minor axis
    c, s = np.cos(angle), np.sin(angle)
    radius = mx * c + my * s
    angle = np.where(radius < 0.0, angle + np.pi, angle)
    angle = np.where(angle > np.pi, angle - 2.0 * np.pi, angle)
    radius = np.abs(radius)
    c, s = np.cos(angle), np.sin(angle)
    along = cxx * s * s + cyy * c * c - 2.0 * cxy * s * c     # variance along the line
    offset = -mx * s + my * c
    scatter = range_sigma ** 2 + bearing_sigma ** 2 * mrr
    with np.errstate(divide='ignore', invalid='ignore'):
        var_angle = scatter / (n * along)
    covariance = np.empty((len(n), 2, 2))
    covariance[:, 0, 0] = var_angle
    covariance[:, 0, 1] = covariance[:, 1, 0] = offset * var_angle
    covariance[:, 1, 1] = scatter / n + offset * offset * var_angle
    return angle, radius, covariance


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


def ml(returns: SegmentReturns, range_sigma: float, bearing_sigma: float,
       start_angle: np.ndarray, start_radius: np.ndarray):
    """
    Maximum-likelihood line (Pfister et al. 2003) with the inverse Fisher information.

    Minimises sum d_i^2 / s_i^2, d_i = rho_i cos(theta_i - angle) - radius,
    s_i^2 = range_sigma^2 cos^2(theta_i - angle) + bearing_sigma^2 rho_i^2 sin^2(theta_i - angle),
    by Gauss-Newton with the variances re-evaluated at each iterate.

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
    s = returns.segment
    rho, theta = returns.rho, returns.theta
    for _ in range(_ML_MAX_ITERATIONS):
        fisher, step, _ = _ml_fisher_and_step(rho, theta, angle[s], radius[s], returns,
                                              range_sigma, bearing_sigma)
        angle, radius = angle + step[:, 0], radius + step[:, 1]
        if not (np.abs(step) > _ML_STEP_TOLERANCE).any():
            break
    fisher, _, offset = _ml_fisher_and_step(rho, theta, angle[s], radius[s], returns,
                                            range_sigma, bearing_sigma)
    flip = radius < 0.0
    angle = np.where(flip, angle + np.pi, angle)
    angle = np.angle(np.exp(1j * angle))
    covariance = inverse_2x2(fisher)
    # Reflecting (angle, radius) -> (angle + pi, -radius) flips the sign of their correlation.
    covariance[flip, 0, 1] *= -1.0
    covariance[flip, 1, 0] *= -1.0
    offset[flip, 1] *= -1.0
    return angle, np.abs(radius), covariance, offset


def _ml_fisher_and_step(rho, theta, angle, radius, returns, range_sigma, bearing_sigma):
    """
    Return the Fisher information (S, 2, 2), the Gauss-Newton step (S, 2) and the offset Jacobian.

    The variances s_i^2 use the range to the current line along each beam instead of the
    measured range: a weight computed from the noisy range would correlate with the residual
    and bias the line (by several mm at grazing incidence). The offset Jacobian is
    d(angle, radius) / d(offset of every range) = -F^-1 sum_i s_i^-2 g_i cos(theta_i - angle),
    from the estimating equations sum_i s_i^-2 g_i d_i = 0 (first order).
    """
    cos_d, sin_d = np.cos(theta - angle), np.sin(theta - angle)
    residual = rho * cos_d - radius
    on_line = radius / cos_d
    inv_var = 1.0 / (range_sigma ** 2 * cos_d ** 2 + (bearing_sigma * on_line * sin_d) ** 2)
    g_angle = on_line * sin_d                      # d residual / d angle; d / d radius = -1
    sums = returns.sums(np.column_stack([inv_var * g_angle * g_angle, -inv_var * g_angle,
                                         inv_var, inv_var * g_angle * residual,
                                         -inv_var * residual, inv_var * g_angle * cos_d,
                                         -inv_var * cos_d]))
    fisher = np.stack([sums[:, 0:2], sums[:, 1:3]], -2)
    return fisher, -solve_2x2(fisher, sums[:, 3:5]), -solve_2x2(fisher, sums[:, 5:7])


def fit_lines(method: str, returns: SegmentReturns, range_sigma: float,
              bearing_sigma: float) -> LineFits:
    """
    Fit every segment with one method and report it in both forms.

    :param method: 'utls', 'wtls', 'wctls' or 'ml'
    :param returns: the segments' returns (each segment with >= 2 returns)
    :param range_sigma: range noise std, m
    :param bearing_sigma: bearing noise std, rad
    :return: the fits
    :raises ValueError: on an unknown method
    """
    if method == 'ml':
        start = line_angle_radius(wtls(returns, range_sigma, bearing_sigma)[0])
        angle, radius, covariance, offset = ml(returns, range_sigma, bearing_sigma, *start)
        line, line_covariance, jac = implicit_from_normal(angle, radius, covariance)
        return LineFits(line, line_covariance, angle, radius, covariance,
                        np.einsum('sij,sj->si', jac, offset), offset)
    fits = {'utls': utls, 'wtls': wtls, 'wctls': wctls}
    if method not in fits:
        raise ValueError(f'unknown line fit {method!r}; use one of utls, wtls, wctls, ml')
    line, line_covariance, line_offset = fits[method](returns, range_sigma, bearing_sigma)
    jac = _normal_jacobian(line)
    return LineFits(line, line_covariance, *line_angle_radius(line),
                    jac @ line_covariance @ jac.transpose(0, 2, 1), line_offset,
                    np.einsum('sij,sj->si', jac, line_offset))
