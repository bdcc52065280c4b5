# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The dock's fit to a scan's returns compiled: the window, the assignment, Gauss-Newton, the tests.

The compiled twin of :func:`wctls_ros.frontend.dock.fit_returns`, whose numpy steps stay the
specification (docs/docking.md, eq. D5-D10): one compiled call per start takes the window of
beams that may see the dock, assigns its returns to the faces twice (eq. D5), fits the apex
frame to their inverse ranges between (eq. D6), and gives the covariance (eq. D7), each face's
reach and the returns past its end (eq. D8), the faces' own opening angle (eq. D9) and their
straightness (eq. D10). The numpy steps pay numpy's cost per call about 60 times a pass over a
window of 100-260 returns; here each pass is one loop over them. The sums are taken in the
order of the beams (numpy's matrix products sum in blocks): the tests hold both to the same
results within 1e-9 relative.

The dock is given as the tuple ``shape`` = (right face m, left face m, opening angle rad, face
tolerance m, angle tolerance rad) and the scan's noise model as ``noise`` = (range sigma m,
bearing sigma rad, model error sigma m, common range sigma m, flatness sigma m);
:func:`fit_returns` gives its results in one array (``FIT_SIZE`` values, laid out as its
docstring says), empty when the numpy twin gives None. The starts are compiled too: from the
corners (:func:`corner_starts`), the pairs of segments (:func:`segment_pair_starts`) and one
segment alone with its test of the other face (:func:`segment_starts`, eq. D11).
"""

import math

import numpy as np

from ._jit import jit

# The numpy twin's constants (wctls_ros.frontend.dock), which the compiled code cannot import
# (the frontend imports no compiled code); the tests hold both to the same results.
ON_FACE_SIGMAS = 3.0
MIN_FACE_RETURNS = 4
BEYOND_M = 0.05
WINDOW_MARGIN_M = 0.05
SINGLE_SEGMENT_M = 0.1
SINGLE_SEGMENT_RETURNS = 30
# The values of a fit: pose 3, covariance 9, counts 2, reach 2, spacing 2, past end 4, the own
# lines' opening angle 1, bends 2, chi2 1.
FIT_SIZE = 26


@jit
def _wrap(angle):
    """Compiled twin of the frontend's ``_wrap`` (``math.remainder`` by 2 pi), rad."""
    return angle - 2.0 * math.pi * np.round(angle / (2.0 * math.pi))


@jit
def _faces(x, y, yaw, shape):
    """Compiled twin of ``_faces``: rows (ux, uy, nx, ny, length), right then left."""
    half = 0.5 * shape[2]
    c, s = math.cos(yaw), math.sin(yaw)
    faces = np.empty((2, 5))
    for k in range(2):
        side = -1.0 if k == 0 else 1.0
        dx, dy = -math.cos(half), side * math.sin(half)
        ux, uy = c * dx - s * dy, s * dx + c * dy
        faces[k, 0], faces[k, 1], faces[k, 2], faces[k, 3] = ux, uy, -uy, ux
        faces[k, 4] = shape[k]
    return faces


@jit
def _window(ranges, angle_min, increment, full_turn, x, y, yaw, shape, beyond_m):
    """Compiled twin of ``_beams``: the window's beam indices (empty when there is none)."""
    faces = _faces(x, y, yaw, shape)
    apex_bearing = math.atan2(y, x)
    count = ranges.size
    centre = (apex_bearing - angle_min) / increment
    if full_turn:
        centre %= count
    low = high = centre            # the apex's offset is 0
    for k in range(2):
        px = x + (faces[k, 4] + beyond_m) * faces[k, 0]
        py = y + (faces[k, 4] + beyond_m) * faces[k, 1]
        end = centre + _wrap(math.atan2(py, px) - apex_bearing) / increment
        low, high = min(low, end), max(high, end)
    first, last = math.floor(low) - 1, math.ceil(high) + 1
    if last - first > count:
        return np.empty(0, np.int64)
    index = np.empty(last - first + 1, np.int64)
    kept = 0
    for beam in range(first, last + 1):
        if full_turn:
            index[kept] = beam % count
            kept += 1
        elif 0 <= beam < count:
            index[kept] = beam
            kept += 1
    if kept < 2 * MIN_FACE_RETURNS:
        return np.empty(0, np.int64)
    return index[:kept]


@jit
def _pass(rho, cos_b, sin_b, valid, gate_cos2, gate, x, y, yaw, shape, noise, final, sums,
          scalars, counts, extras):
    """
    Compiled twin of ``_assign``: assign the window's returns and sum what the fit needs.

    Fills ``sums`` (2, 2, 6: per face, sum w u_i column_j), ``scalars`` (2, 2) and ``counts``
    (2,); when final also ``extras`` (rows reach, first and last fitted position, past end on
    and farther, own line's sums axx axy ayy bx by, bend: 2 x 11). Returns False when a face
    has fewer than MIN_FACE_RETURNS returns on it.
    """
    faces = _faces(x, y, yaw, shape)
    size = rho.size
    hit = np.empty((2, size))
    along = np.empty((2, size))
    cosine = np.empty((2, size))
    on = np.empty((2, size), np.bool_)
    meets = np.empty((2, size), np.bool_)
    for k in range(2):
        ux, uy, nx, ny, length = faces[k, 0], faces[k, 1], faces[k, 2], faces[k, 3], faces[k, 4]
        radius, position = nx * x + ny * y, ux * x + uy * y
        for m in range(size):
            c = nx * cos_b[m] + ny * sin_b[m]
            h = radius / c
            hit[k, m], cosine[k, m] = h, c
            along[k, m] = h * (ux * cos_b[m] + uy * sin_b[m]) - position
            offset = (rho[m] - h) * c
            on[k, m] = offset * offset <= gate_cos2[m] * c * c + gate[m] and valid[m]
            meets[k, m] = h > 0.0 and along[k, m] >= 0.0 and along[k, m] <= length
    sees = np.empty((2, size), np.bool_)
    for m in range(size):
        both, nearer_right = meets[0, m] and meets[1, m], hit[0, m] <= hit[1, m]
        sees[0, m] = meets[0, m] and (not both or nearer_right)
        sees[1, m] = meets[1, m] and (not both or not nearer_right)
    for k in range(2):
        counts[k] = 0
        for m in range(size):
            if sees[k, m] and on[k, m]:
                counts[k] += 1
    if min(counts[0], counts[1]) < MIN_FACE_RETURNS:
        return False
    sigma2, bearing2 = noise[0] * noise[0], noise[1] * noise[1]
    deciding = sigma2 + noise[2] * noise[2]
    sums[:] = 0.0
    scalars[:] = 0.0
    inverse = np.empty((2, size))
    weights = np.empty((2, size))
    h2s = np.empty((2, size))
    tangent2 = np.empty((2, size))
    for k in range(2):
        for m in range(size):
            # Only the returns a face sees are fitted, gated or walked (the numpy twin's
            # placeholders where it sees none are never read).
            if not sees[k, m]:
                continue
            h2, c2 = hit[k, m] * hit[k, m], cosine[k, m] * cosine[k, m]
            h2s[k, m], tangent2[k, m] = h2, h2 * (1.0 - c2) / c2
            # The inverse range, its second-order bias removed, and its weight (eq. D6).
            inverse[k, m] = 1.0 / rho[m] - sigma2 / (h2 * math.sqrt(h2))
            weights[k, m] = h2 * h2 / (sigma2 + bearing2 * tangent2[k, m])
            if not on[k, m]:
                continue
            w = weights[k, m]
            columns = (cos_b[m], sin_b[m], inverse[k, m], 1.0 / h2, 1.0 / h2 / cosine[k, m],
                       1.0 / h2 / cosine[k, m] * along[k, m])
            for j in range(6 if final else 3):
                sums[k, 0, j] += w * cos_b[m] * columns[j]
                sums[k, 1, j] += w * sin_b[m] * columns[j]
            scalars[k, 0] += w
            scalars[k, 1] += w * inverse[k, m] * inverse[k, m]
    if not final:
        return True
    tolerance_sin = math.sin(shape[4])
    for k in range(2):
        length = faces[k, 4]
        tolerated = length + shape[3]
        other = 1 - k
        # Each face's own line (eq. D9), from its returns within the gate widened by the
        # opening angle's tolerance.
        own = np.zeros(size, np.bool_)
        axx = axy = ayy = bx = by = 0.0
        first, last = math.inf, -math.inf
        past_on = past_farther = 0
        for m in range(size):
            c = cosine[k, m]
            offset = (rho[m] - hit[k, m]) * c
            if sees[k, m] and valid[m] and abs(offset) <= math.sqrt(
                    gate_cos2[m] * c * c + gate[m]) + max(along[k, m], 0.0) * tolerance_sin:
                own[m] = True
                w = weights[k, m]
                axx += w * cos_b[m] * cos_b[m]
                axy += w * cos_b[m] * sin_b[m]
                ayy += w * sin_b[m] * sin_b[m]
                bx += w * cos_b[m] * inverse[k, m]
                by += w * sin_b[m] * inverse[k, m]
            if sees[k, m] and on[k, m]:
                first, last = min(first, along[k, m]), max(last, along[k, m])
            # Past the end and its tolerance (eq. D8): on the face's line, or farther (none).
            beyond = (along[k, m] > length and along[k, m] <= tolerated + BEYOND_M
                      and not sees[other, m] and hit[k, m] > 0.0)
            if beyond and along[k, m] > tolerated:
                if on[k, m]:
                    past_on += 1
                elif not valid[m] or rho[m] > hit[k, m]:
                    past_farther += 1
        # The residuals from that line over the deciding noise (eq. D10): their walk.
        det = axx * ayy - axy * axy
        px, py = (ayy * bx - axy * by) / det, (axx * by - axy * bx) / det
        n = 0
        for m in range(size):
            if own[m]:
                n += 1
        bend = math.inf
        if n > 2:
            walk = np.empty(n)
            total, i = 0.0, 0
            for m in range(size):
                if own[m]:
                    total += (inverse[k, m] - (px * cos_b[m] + py * sin_b[m])) * h2s[k, m] / (
                        math.sqrt(deciding + bearing2 * tangent2[k, m]))
                    walk[i] = total
                    i += 1
            bend = 0.0
            for i in range(n):
                bend = max(bend, abs(walk[i] - walk[n - 1] * (i + 1) / n))
            bend /= math.sqrt(n)
        # The reach (eq. D8): the face's returns and those past its outer end, in the order of
        # their position along it, up to the first two in a row off its line.
        looked = np.empty(size, np.int64)
        count = 0
        for m in range(size):
            beyond = (along[k, m] > length and along[k, m] <= tolerated + BEYOND_M
                      and not sees[other, m] and hit[k, m] > 0.0)
            if (sees[k, m] or beyond) and valid[m]:
                looked[count] = m
                count += 1
        backwards = count > 1 and along[k, looked[0]] > along[k, looked[count - 1]]
        reach = -math.inf
        for i in range(count):
            m = looked[count - 1 - i] if backwards else looked[i]
            if i + 1 < count:
                following = looked[count - 2 - i] if backwards else looked[i + 1]
                if not (on[k, m] or on[k, following]):
                    break
            if on[k, m]:
                reach = max(reach, along[k, m])
        extras[k, 0] = reach if reach > -math.inf else math.nan
        extras[k, 1], extras[k, 2] = first, last
        extras[k, 3], extras[k, 4] = past_on, past_farther
        extras[k, 5], extras[k, 6], extras[k, 7] = axx, axy, ayy
        extras[k, 8], extras[k, 9], extras[k, 10] = bx, by, bend
    return True


@jit
def _face_line(normal_offset, x, y, yaw, line):
    """Compiled twin of ``_face_line``: writes p (row 0) and dp/ds (rows 1-2); False via (0, 0)."""
    nx, ny = math.cos(yaw + normal_offset), math.sin(yaw + normal_offset)
    radius = nx * x + ny * y
    if abs(radius) < 1e-9:
        return False
    inverse2 = 1.0 / (radius * radius)
    turn = (nx * y - ny * x) * inverse2
    line[0, 0], line[0, 1] = nx / radius, ny / radius
    line[1, 0], line[1, 1], line[1, 2] = -nx * nx * inverse2, -nx * ny * inverse2, (
        -ny / radius - nx * turn)
    line[2, 0], line[2, 1], line[2, 2] = -ny * nx * inverse2, -ny * ny * inverse2, (
        nx / radius - ny * turn)
    return True


@jit
def _normal_equations(sums, scalars, offsets, x, y, yaw, normal, gradient):
    """Compiled twin of ``_normal_equations``: fills J^T W J and J^T W e; chi2 (NaN: none)."""
    normal[:] = 0.0
    gradient[:] = 0.0
    chi2 = 0.0
    line = np.zeros((3, 3))
    for k in range(2):
        if not _face_line(offsets[k], x, y, yaw, line):
            return math.nan
        axx, axy, ayy = sums[k, 0, 0], sums[k, 0, 1], sums[k, 1, 1]
        bx, by = sums[k, 0, 2], sums[k, 1, 2]
        px, py = line[0, 0], line[0, 1]
        rx, ry = axx * px + axy * py - bx, axy * px + ayy * py - by
        chi2 += px * (rx - bx) + py * (ry - by) + scalars[k, 1]
        for i in range(3):
            ji, ki = line[1, i], line[2, i]
            for j in range(i, 3):
                jj, kj = line[1, j], line[2, j]
                normal[i, j] += ji * (axx * jj + axy * kj) + ki * (axy * jj + ayy * kj)
            gradient[i] += ji * rx + ki * ry
    for i in range(3):
        for j in range(i):
            normal[i, j] = normal[j, i]
    return chi2


@jit
def _inverse3(matrix, out):
    """Compiled twin of ``_inverse3`` (the adjugate over the determinant); False if singular."""
    a, b, c = matrix[0, 0], matrix[0, 1], matrix[0, 2]
    d, e, f = matrix[1, 0], matrix[1, 1], matrix[1, 2]
    g, h, i = matrix[2, 0], matrix[2, 1], matrix[2, 2]
    out[0, 0], out[0, 1], out[0, 2] = e * i - f * h, c * h - b * i, b * f - c * e
    out[1, 0], out[1, 1], out[1, 2] = f * g - d * i, a * i - c * g, c * d - a * f
    out[2, 0], out[2, 1], out[2, 2] = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * out[0, 0] + b * out[1, 0] + c * out[2, 0]
    if not abs(det) > 0.0:
        return False
    for row in range(3):
        for column in range(3):
            out[row, column] /= det
    return True


@jit
def fit_returns(ranges, angle_min, increment, full_turn, range_limits, noise, residual_scaling,
                start, shape):
    """
    Compiled twin of :func:`wctls_ros.frontend.dock.fit_returns` (eq. D5-D10).

    :param ranges: the scan's ranges, shape (N,), m
    :param angle_min: bearing of beam 0, rad
    :param increment: bearing step, rad
    :param full_turn: the beams go all the way round
    :param range_limits: (shortest, longest) valid range, m
    :param noise: (range sigma m, bearing sigma rad, model error sigma m, common range sigma
        m, flatness sigma m)
    :param residual_scaling: scale the covariance by the excess chi2
    :param start: the apex frame's start (x, y, yaw), m, m, rad
    :param shape: (right face m, left face m, opening angle rad, face tolerance m, angle
        tolerance rad)
    :return: shape (FIT_SIZE,): pose (x, y, yaw wrapped) 0-2, covariance 3-11 (row-major),
        returns per face 12-13, reach 14-15, spacing 16-17, past end (right on, farther, left
        on, farther) 18-21, the own lines' opening angle 22, bends 23-24, chi2 25; shape (0,)
        where the numpy twin gives None
    """
    nothing = np.empty(0)
    x, y, yaw = start[0], start[1], start[2]
    faces0 = _faces(0.0, 0.0, 0.0, shape)
    offsets = np.array([math.atan2(faces0[0, 3], faces0[0, 2]),
                        math.atan2(faces0[1, 3], faces0[1, 2])])
    index = _window(ranges, angle_min, increment, full_turn, x, y, yaw, shape,
                    shape[3] + BEYOND_M + WINDOW_MARGIN_M)
    size = index.size
    if size == 0:
        return nothing
    rho, cos_b, sin_b = np.empty(size), np.empty(size), np.empty(size)
    valid = np.empty(size, np.bool_)
    gate_cos2, gate = np.empty(size), np.empty(size)
    across = ON_FACE_SIGMAS ** 2 * (noise[0] * noise[0] + noise[2] * noise[2])
    for m in range(size):
        value = ranges[index[m]]
        bearing = angle_min + increment * index[m]
        valid[m] = (math.isfinite(value) and value > 0.0 and value >= range_limits[0]
                    and value <= range_limits[1])
        rho[m] = value if valid[m] else 1.0
        cos_b[m], sin_b[m] = math.cos(bearing), math.sin(bearing)
        gate[m] = (ON_FACE_SIGMAS * noise[1]) ** 2 * rho[m] * rho[m]
        gate_cos2[m] = across - gate[m]
    sums, scalars = np.zeros((2, 2, 6)), np.zeros((2, 2))
    counts, extras = np.zeros(2, np.int64), np.zeros((2, 11))
    normal, gradient, inverse = np.zeros((3, 3)), np.zeros(3), np.zeros((3, 3))
    for final in (False, True):
        if not _pass(rho, cos_b, sin_b, valid, gate_cos2, gate, x, y, yaw, shape, noise, final,
                     sums, scalars, counts, extras):
            return nothing
        # Gauss-Newton (the numpy twin's _gauss_newton): two steps, then up to four.
        for _ in range(4 if final else 2):
            if math.isnan(_normal_equations(sums, scalars, offsets, x, y, yaw, normal,
                                            gradient)) or not _inverse3(normal, inverse):
                return nothing
            dx = -(inverse[0, 0] * gradient[0] + inverse[0, 1] * gradient[1]
                   + inverse[0, 2] * gradient[2])
            dy = -(inverse[1, 0] * gradient[0] + inverse[1, 1] * gradient[1]
                   + inverse[1, 2] * gradient[2])
            dt = -(inverse[2, 0] * gradient[0] + inverse[2, 1] * gradient[1]
                   + inverse[2, 2] * gradient[2])
            x, y, yaw = x + dx, y + dy, yaw + dt
            if abs(dx) + abs(dy) < 1e-6 and abs(dt) < 1e-6:
                break
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            return nothing
    chi2 = _normal_equations(sums, scalars, offsets, x, y, yaw, normal, gradient)
    if math.isnan(chi2) or not _inverse3(normal, inverse):
        return nothing
    dof = counts[0] + counts[1] - 3
    scale = 1.0
    if residual_scaling and dof > 0:
        scale = max(1.0, chi2 / dof - math.sqrt(2.0 / dof))
    # What moves the fit besides the returns' own noise (eq. D7): the common range offset,
    # and each face's two ends off its line.
    moves, variances = np.zeros((5, 3)), np.zeros(5)
    variances[0] = noise[3] * noise[3]
    used = 1
    line = np.zeros((3, 3))
    for k in range(2):
        _face_line(offsets[k], x, y, yaw, line)
        for i in range(3):
            moves[0, i] += line[1, i] * sums[k, 0, 3] + line[2, i] * sums[k, 1, 3]
        first, last = extras[k, 1], extras[k, 2]
        if noise[4] > 0.0 and last > first:
            far0 = (sums[k, 0, 5] - first * sums[k, 0, 4]) / (last - first)
            far1 = (sums[k, 1, 5] - first * sums[k, 1, 4]) / (last - first)
            for i in range(3):
                moves[used, i] = (line[1, i] * (sums[k, 0, 4] - far0)
                                  + line[2, i] * (sums[k, 1, 4] - far1))
                moves[used + 1, i] = line[1, i] * far0 + line[2, i] * far1
            variances[used] = variances[used + 1] = noise[4] * noise[4]
            used += 2
    out = np.empty(FIT_SIZE)
    moved = np.zeros((5, 3))
    for e in range(used):
        for i in range(3):
            for j in range(3):
                moved[e, i] += inverse[i, j] * moves[e, j]
    for i in range(3):
        for j in range(3):
            value = scale * inverse[i, j]
            for e in range(used):
                value += moved[e, i] * variances[e] * moved[e, j]
            out[3 + 3 * i + j] = value
    for i in range(3):
        for j in range(i + 1, 3):
            both = 0.5 * (out[3 + 3 * i + j] + out[3 + 3 * j + i])
            out[3 + 3 * i + j] = out[3 + 3 * j + i] = both
    for i in range(9):
        if not math.isfinite(out[3 + i]):
            return nothing
    out[0], out[1], out[2] = x, y, _wrap(yaw)
    faces = _faces(x, y, yaw, shape)
    directions = np.empty((2, 2))
    for k in range(2):
        out[12 + k], out[14 + k] = counts[k], extras[k, 0]
        # The returns' spacing along the face at its outer end (``_spacing``).
        tip_x, tip_y = x + faces[k, 4] * faces[k, 0], y + faces[k, 4] * faces[k, 1]
        tip_range = math.hypot(tip_x, tip_y)
        cosine = abs(faces[k, 2] * tip_x + faces[k, 3] * tip_y) / max(tip_range, 1e-12)
        out[16 + k] = abs(increment) * tip_range / max(cosine, 1e-3)
        out[18 + 2 * k], out[19 + 2 * k] = extras[k, 3], extras[k, 4]
        out[23 + k] = extras[k, 10]
        # The face's own line's direction (``_own_lines_angle``), along the face outwards.
        axx, axy, ayy, bx, by = extras[k, 5], extras[k, 6], extras[k, 7], extras[k, 8], extras[
            k, 9]
        px, py = ayy * bx - axy * by, axx * by - axy * bx
        dx, dy = -py, px
        if dx * faces[k, 0] + dy * faces[k, 1] < 0.0:
            dx, dy = -dx, -dy
        directions[k, 0], directions[k, 1] = dx, dy
    norm = math.hypot(directions[0, 0], directions[0, 1]) * math.hypot(directions[1, 0],
                                                                       directions[1, 1])
    between = math.nan
    if norm > 0.0:
        between = math.acos(max(-1.0, min(1.0, (directions[0, 0] * directions[1, 0]
                                                + directions[0, 1] * directions[1, 1]) / norm)))
        if not shape[2] < math.pi:
            between = 2.0 * math.pi - between
    out[22], out[25] = between, chi2
    return out


@jit
def _wrap_half_open(angle):
    """Compiled twin of the frontend's ``wrap_angle`` for one angle: into (-pi, pi], rad."""
    return math.pi - (math.pi - angle) % (2.0 * math.pi)


@jit
def fit_apex(angle, radius, covariance, right, left, x, y, yaw, opening):
    """
    Compiled twin of :func:`wctls_ros.frontend.dock.fit_apex` (eq. D1).

    :param angle: the segments' normal angles, shape (N,), rad
    :param radius: their distances from the sensor, shape (N,), m
    :param covariance: their (alpha, r) covariances, shape (N, 2, 2)
    :param right: index of the right face's segment
    :param left: index of the left face's segment
    :param x: the start's apex x, m
    :param y: the start's apex y, m
    :param yaw: the start's yaw, rad
    :param opening: the dock's opening angle, rad
    :return: shape (12,): (x, y, yaw wrapped) and the covariance (row-major); shape (0,) where
        the numpy twin gives None
    """
    half = 0.5 * opening
    c, s = math.cos(yaw), math.sin(yaw)
    sensor_x, sensor_y = -(c * x + s * y), s * x - c * y
    faces = np.empty((2, 6))
    for k in range(2):
        wall = right if k == 0 else left
        normal_x, normal_y = math.sin(half), (-1.0 if k == 0 else 1.0) * math.cos(half)
        if normal_x * sensor_x + normal_y * sensor_y > 0.0:
            normal_x, normal_y = -normal_x, -normal_y
        caa, car, crr = covariance[wall, 0, 0], covariance[wall, 0, 1], covariance[wall, 1, 1]
        det = caa * crr - car * car
        if not (caa > 0.0 and det > 0.0):
            return np.empty(0)
        faces[k, 0], faces[k, 1], faces[k, 2] = math.atan2(normal_y, normal_x), angle[wall], (
            radius[wall])
        faces[k, 3], faces[k, 4], faces[k, 5] = crr / det, -car / det, caa / det
    normal, inverse = np.zeros((3, 3)), np.zeros((3, 3))
    for _ in range(2):
        nxx = nxy = nyy = nxt = nyt = ntt = gx = gy = gt = 0.0
        for k in range(2):
            alpha = yaw + faces[k, 0]
            ca, sa = math.cos(alpha), math.sin(alpha)
            q = ca * y - sa * x
            error_alpha = _wrap(faces[k, 1] - alpha)
            error_radius = faces[k, 2] - (ca * x + sa * y)
            waa, war, wrr = faces[k, 3], faces[k, 4], faces[k, 5]
            u = waa * error_alpha + war * error_radius
            v = war * error_alpha + wrr * error_radius
            nxx += wrr * ca * ca
            nxy += wrr * ca * sa
            nyy += wrr * sa * sa
            nxt += (war + wrr * q) * ca
            nyt += (war + wrr * q) * sa
            ntt += waa + 2.0 * war * q + wrr * q * q
            gx += ca * v
            gy += sa * v
            gt += u + q * v
        normal[0, 0], normal[0, 1], normal[0, 2] = nxx, nxy, nxt
        normal[1, 0], normal[1, 1], normal[1, 2] = nxy, nyy, nyt
        normal[2, 0], normal[2, 1], normal[2, 2] = nxt, nyt, ntt
        if not _inverse3(normal, inverse):
            return np.empty(0)
        x += inverse[0, 0] * gx + inverse[0, 1] * gy + inverse[0, 2] * gt
        y += inverse[0, 1] * gx + inverse[1, 1] * gy + inverse[1, 2] * gt
        yaw += inverse[0, 2] * gx + inverse[1, 2] * gy + inverse[2, 2] * gt
    out = np.empty(12)
    out[0], out[1], out[2] = x, y, _wrap(yaw)
    for i in range(3):
        for j in range(3):
            out[3 + 3 * i + j] = inverse[i, j]
    for i in range(12):
        if not math.isfinite(out[i]):
            return np.empty(0)
    return out


@jit
def _pair_start(angle, radius, covariance, ends, i, j, x, y, yaw, opening, starts, count):
    """Compiled twin of ``_pair_start``: write the start as row ``count``; return the count."""
    c, s = math.cos(yaw), math.sin(yaw)
    sides = np.empty(2)
    for k in range(2):
        wall = i if k == 0 else j
        sides[k] = (c * (0.5 * (ends[wall, 1] + ends[wall, 3]) - y)
                    - s * (0.5 * (ends[wall, 0] + ends[wall, 2]) - x))
    if not sides[0] * sides[1] < 0.0:
        return count
    right, left = (i, j) if sides[0] < 0.0 else (j, i)
    fit = fit_apex(angle, radius, covariance, right, left, x, y, yaw, opening)
    if fit.size:
        starts[count, 0], starts[count, 1], starts[count, 2] = fit[0], fit[1], fit[2]
    else:
        starts[count, 0], starts[count, 1], starts[count, 2] = x, y, yaw
    return count + 1


@jit
def _farther_than(ends, i, j, x, y, distance):
    """Compiled twin of ``_farther_than``: either segment reaches farther from (x, y)."""
    for wall in (i, j):
        if (math.hypot(ends[wall, 0] - x, ends[wall, 1] - y) > distance
                or math.hypot(ends[wall, 2] - x, ends[wall, 3] - y) > distance):
            return True
    return False


@jit
def corner_starts(angle, radius, covariance, ends, first, second, corner_opening, corner_xy,
                  corner_yaw, shape):
    """
    Compiled twin of the frontend's ``_corner_starts`` (eq. D1).

    :param angle: the segments' normal angles, shape (N,), rad
    :param radius: their distances, shape (N,), m
    :param covariance: their (alpha, r) covariances, shape (N, 2, 2)
    :param ends: their (start x, start y, end x, end y), shape (N, 4), m
    :param first: each corner's first segment, shape (K,)
    :param second: its second segment, shape (K,)
    :param corner_opening: the corners' opening angles, shape (K,), rad
    :param corner_xy: the corners, shape (K, 2), m
    :param corner_yaw: their bisectors' directions, shape (K,), rad
    :param shape: as :func:`fit_returns`'s
    :return: the starts (x, y, yaw), shape (S, 3)
    """
    longest = max(shape[0], shape[1]) + shape[3] + BEYOND_M
    starts = np.empty((first.size, 3))
    count = 0
    for k in range(first.size):
        if not abs(corner_opening[k] - shape[2]) <= 2.0 * shape[4]:
            continue
        x, y = corner_xy[k, 0], corner_xy[k, 1]
        if _farther_than(ends, first[k], second[k], x, y, longest):
            continue
        count = _pair_start(angle, radius, covariance, ends, first[k], second[k], x, y,
                            _wrap_half_open(corner_yaw[k] + math.pi), shape[2], starts, count)
    return starts[:count]


@jit
def segment_pair_starts(angle, radius, covariance, ends, first, second, shape, full_turn):
    """
    Compiled twin of the frontend's ``_segment_pair_starts`` (eq. D1).

    :param angle: the segments' normal angles, shape (N,), rad
    :param radius: their distances, shape (N,), m
    :param covariance: their (alpha, r) covariances, shape (N, 2, 2)
    :param ends: their (start x, start y, end x, end y), shape (N, 4), m
    :param first: every corner's first segment (its pair was tried), shape (K,)
    :param second: its second segment, shape (K,)
    :param shape: as :func:`fit_returns`'s
    :param full_turn: the beams go all the way round (pairs across the seam)
    :return: the starts (x, y, yaw), shape (S, 3)
    """
    count = angle.size
    longest = max(shape[0], shape[1]) + shape[3] + BEYOND_M
    concave = shape[2] < math.pi
    starts = np.empty((2 * count, 3))
    made = 0
    for step in (1, 2):
        for i in range(count):
            j = i + step
            if full_turn:
                j %= count
                if j == i:
                    continue
            elif j >= count:
                continue
            between = abs(_wrap_half_open(angle[j] - angle[i]))
            if not abs(between - abs(math.pi - shape[2])) <= 2.0 * shape[4]:
                continue
            tried = False
            for k in range(first.size):
                tried = tried or (first[k] == i and second[k] == j) or (
                    first[k] == j and second[k] == i)
            if tried:
                continue
            det = math.sin(angle[j] - angle[i])
            if abs(det) < 1e-9:
                continue
            px = (radius[i] * math.sin(angle[j]) - radius[j] * math.sin(angle[i])) / det
            py = (radius[j] * math.cos(angle[i]) - radius[i] * math.cos(angle[j])) / det
            if _farther_than(ends, i, j, px, py, longest):
                continue
            bx = by = 0.0
            seen = True
            for wall in (i, j):
                mx = 0.5 * (ends[wall, 0] + ends[wall, 2]) - px
                my = 0.5 * (ends[wall, 1] + ends[wall, 3]) - py
                middle = math.hypot(mx, my)
                if not middle > 0.0:
                    seen = False
                    break
                bx, by = bx + mx / middle, by + my / middle
            if not seen or (bx * px + by * py < 0.0) != concave:
                continue
            yaw = math.atan2(-by, -bx) if concave else math.atan2(by, bx)
            made = _pair_start(angle, radius, covariance, ends, i, j, px, py, yaw, shape[2],
                               starts, made)
    return starts[:made]


@jit
def _other_face_seen(ranges, angle_min, increment, full_turn, range_limits, noise, ax, ay, ux,
                     uy, length):
    """Compiled twin of ``_other_face_seen``: half of the face's beams see it, 4 at least."""
    count = ranges.size
    apex_bearing = math.atan2(ay, ax)
    centre = (apex_bearing - angle_min) / increment
    if full_turn:
        centre %= count
    end = centre + _wrap(math.atan2(ay + length * uy, ax + length * ux)
                         - apex_bearing) / increment
    nx, ny = -uy, ux
    across = ON_FACE_SIGMAS ** 2 * (noise[0] * noise[0] + noise[2] * noise[2])
    seen = meeting = 0
    for beam in range(math.ceil(min(centre, end)), math.floor(max(centre, end)) + 1):
        if full_turn:
            beam %= count
        elif not 0 <= beam < count:
            continue
        bearing = angle_min + increment * beam
        cos_b, sin_b = math.cos(bearing), math.sin(bearing)
        cosine = nx * cos_b + ny * sin_b
        if cosine == 0.0:
            continue
        hit = (nx * ax + ny * ay) / cosine
        along = hit * (ux * cos_b + uy * sin_b) - (ux * ax + uy * ay)
        if not (hit > 0.0 and along >= 0.0 and along <= length):
            continue
        meeting += 1
        rho = ranges[beam]
        if not (math.isfinite(rho) and rho > 0.0 and rho >= range_limits[0]
                and rho <= range_limits[1]):
            continue
        offset = (rho - hit) * cosine
        spread = (ON_FACE_SIGMAS * noise[1]) ** 2 * rho * rho
        if offset * offset <= (across - spread) * cosine * cosine + spread:
            seen += 1
    return seen >= MIN_FACE_RETURNS and 2 * seen >= meeting


@jit
def segment_starts(ends, points, ranges, angle_min, increment, full_turn, range_limits, noise,
                   shape):
    """
    Compiled twin of the frontend's ``_segment_starts``: one segment as either face.

    :param ends: the segments' (start x, start y, end x, end y), shape (N, 4), m
    :param points: their returns, shape (N,)
    :param ranges: the scan's ranges, shape (M,), m
    :param angle_min: bearing of beam 0, rad
    :param increment: bearing step, rad
    :param full_turn: the beams go all the way round
    :param range_limits: (shortest, longest) valid range, m
    :param noise: as :func:`fit_returns`'s
    :param shape: as :func:`fit_returns`'s
    :return: the starts (x, y, yaw), shape (S, 3)
    """
    half = 0.5 * shape[2]
    concave = 1.0 if shape[2] < math.pi else -1.0
    face_x = np.array([-math.cos(half), -math.cos(half)])
    face_y = np.array([-math.sin(half), math.sin(half)])
    longest = max(shape[0], shape[1]) + shape[3] + BEYOND_M
    starts = np.empty((4 * ends.shape[0], 3))
    made = 0
    for wall in range(ends.shape[0]):
        sx, sy, ex, ey = ends[wall, 0], ends[wall, 1], ends[wall, 2], ends[wall, 3]
        length = math.hypot(ex - sx, ey - sy)
        if not (SINGLE_SEGMENT_M <= length and length <= longest
                and points[wall] >= SINGLE_SEGMENT_RETURNS):
            continue
        for flip in range(2):
            ax, ay, bx, by = (sx, sy, ex, ey) if flip == 0 else (ex, ey, sx, sy)
            dx, dy = (bx - ax) / length, (by - ay) / length
            for k in range(2):
                if length > shape[k] + shape[3] + BEYOND_M:
                    continue
                yaw = _wrap(math.atan2(dy, dx) - math.atan2(face_y[k], face_x[k]))
                c, s = math.cos(yaw), math.sin(yaw)
                ox, oy = face_x[1 - k], face_y[1 - k]
                ux, uy = c * ox - s * oy, s * ox + c * oy
                turn = dx * uy - dy * ux
                if not (concave * turn * (ax * dy - ay * dx) > 0.0
                        and concave * turn * (ay * ux - ax * uy) > 0.0):
                    continue
                if _other_face_seen(ranges, angle_min, increment, full_turn, range_limits,
                                    noise, ax, ay, ux, uy, shape[1 - k]):
                    starts[made, 0], starts[made, 1], starts[made, 2] = ax, ay, yaw
                    made += 1
    return starts[:made]
