# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A docking station seen by a 2D LiDAR: two straight faces meeting at an apex, found among corners.

A dock is described by :class:`DockShape`: the length of its right and left faces and the
opening angle between them through the side the robot sees (below 180 deg a V the robot faces
into, above 180 deg a wedge pointing at the robot, 90 deg an L), with tolerances. Its pose is
the dock frame: origin at the apex, x along the bisector away from the robot's side (the way a
robot docking forwards faces), y to the left, moved to a stated reference point.
:func:`find_docks` starts from the corners and the pairs of segments near the dock's angle (and
from one segment alone where the other face is seen, eq. D11), fits the apex frame to the lines
knowing the opening angle (eq. D1), then to the scan's returns themselves (:func:`fit_returns`,
eq. D5-D7), and keeps the fits whose faces reach their ends and no farther, are straight and
meet at the angle (eq. D8-D10); without the returns, the corners that match, with their line
fit. The pose is moved to the reference point with its covariance (eq. D2-D3; docs/docking.md).
:func:`track_dock` keeps the candidates that agree with the last ones (a chi2 gate over the
pose difference, with the motion allowed in between, eq. D4) and confirms a dock only after a
few agreeing scans.

Everything is in the scan's frame: m, rad. Pure numpy; no ROS.
"""

from dataclasses import dataclass
import math
from typing import Any, List, NamedTuple, Optional, Tuple

import numpy as np

from ..core import CornerSet, FeatureConfig, runtime, SegmentSet

# P(chi2 with 3 dof <= 16.27) = 99.9 %: the gate of a pose difference.
CHI2_3DOF_999 = 16.266


@dataclass(frozen=True)
class DockShape:
    """
    What a dock looks like, and where its frame is.

    :ivar right_face_m: length of the face on the robot's right (the dock's -y side), apex to
        its outer end, m
    :ivar left_face_m: length of the face on the robot's left (+y), m
    :ivar opening_angle_rad: angle between the faces through the robot's side, rad in
        (0, 2 pi), not pi: below pi a V, above pi a wedge
    :ivar face_tolerance_m: how much longer than its length a seen face may be, m
    :ivar face_shortfall_m: how much shorter a seen face may be, beyond the spacing of its
        returns (its outer end lies up to one return short of the edge, and the extraction
        may leave a few returns by the edge out), m
    :ivar angle_tolerance_rad: how much the seen opening angle may differ, rad
    :ivar reference_xy_m: the dock frame's origin in the apex frame, shape (2,), m
    :ivar reference_yaw_rad: the dock frame's yaw in the apex frame, rad
    """

    right_face_m: float = 0.30
    left_face_m: float = 0.30
    opening_angle_rad: float = math.radians(120.0)
    face_tolerance_m: float = 0.03
    face_shortfall_m: float = 0.10
    angle_tolerance_rad: float = math.radians(10.0)
    reference_xy_m: Tuple[float, float] = (0.0, 0.0)
    reference_yaw_rad: float = 0.0

    def __post_init__(self):
        problems = shape_errors(self)
        if problems:
            raise ValueError('; '.join(problems))


def shape_errors(shape: DockShape) -> List[str]:
    """
    Return why a dock description is unusable (empty when it is fine).

    :param shape: the description
    :return: one sentence per problem
    """
    problems = []
    for name in ('right_face_m', 'left_face_m'):
        if not getattr(shape, name) > 0.0:
            problems.append(f'{name} must be > 0, got {getattr(shape, name)}')
    for name in ('face_tolerance_m', 'face_shortfall_m'):
        if not getattr(shape, name) >= 0.0:
            problems.append(f'{name} must be >= 0, got {getattr(shape, name)}')
    if not shape.face_shortfall_m < min(shape.right_face_m, shape.left_face_m):
        problems.append(f'face_shortfall_m ({shape.face_shortfall_m:g} m) must be shorter than '
                        'the faces')
    angle, tolerance = shape.opening_angle_rad, shape.angle_tolerance_rad
    if not 0.0 < angle < 2.0 * math.pi:
        problems.append(f'the opening angle must be in (0, 360) deg, got {math.degrees(angle)}')
    elif not 0.0 <= tolerance < min(abs(angle - math.pi), angle, 2.0 * math.pi - angle):
        # A tolerance reaching 180 deg would take a straight wall for a dock.
        problems.append(f'the opening angle tolerance ({math.degrees(tolerance):g} deg) must be '
                        f'>= 0 and leave the opening angle ({math.degrees(angle):g} deg) short '
                        'of 0, 180 and 360 deg')
    if not all(math.isfinite(v) for v in (*shape.reference_xy_m, shape.reference_yaw_rad)):
        problems.append('the reference point must be finite')
    return problems


@dataclass(frozen=True)
class DockPose:
    """
    One detection of the dock: its frame in the scan's frame.

    :ivar x_m: origin x, m
    :ivar y_m: origin y, m
    :ivar yaw_rad: x axis direction, rad in (-pi, pi]
    :ivar covariance: of (x, y, yaw), shape (3, 3): m^2, m rad, rad^2
    :ivar misfit: how far the seen shape is from the description, in tolerances (the largest
        of the three ratios; <= 1 for every candidate)
    """

    x_m: float
    y_m: float
    yaw_rad: float
    covariance: np.ndarray
    misfit: float

    @property
    def vector(self) -> np.ndarray:
        """
        Return (x, y, yaw).

        :return: shape (3,), m, m, rad
        """
        return np.array([self.x_m, self.y_m, self.yaw_rad])


def wrap_angle(angle_rad):
    """
    Return an angle (or an array of them) wrapped into (-pi, pi].

    :param angle_rad: rad
    :return: rad
    """
    return np.pi - np.mod(np.pi - np.asarray(angle_rad, dtype=float), 2.0 * np.pi)


def reference_pose(apex_xy_m: np.ndarray, apex_yaw_rad: float, apex_covariance: np.ndarray,
                   shape: DockShape) -> Tuple[np.ndarray, np.ndarray]:
    """
    Move a pose at the apex to the dock's reference point, with its covariance (eq. D2-D3).

    p = a + R(yaw_a) r,  yaw = yaw_a + yaw_r; J = d(p, yaw)/d(a, yaw_a), C = J C_a J^T.

    :param apex_xy_m: the apex, shape (2,), m
    :param apex_yaw_rad: the apex frame's yaw, rad
    :param apex_covariance: of (x, y, yaw) at the apex, shape (3, 3)
    :param shape: the dock (its reference point)
    :return: (x, y, yaw) shape (3,) and its covariance shape (3, 3)
    """
    c, s = math.cos(apex_yaw_rad), math.sin(apex_yaw_rad)
    rx, ry = shape.reference_xy_m
    pose = np.array([apex_xy_m[0] + c * rx - s * ry, apex_xy_m[1] + s * rx + c * ry,
                     float(wrap_angle(apex_yaw_rad + shape.reference_yaw_rad))])
    jacobian = np.array([[1.0, 0.0, -s * rx - c * ry],
                         [0.0, 1.0, c * rx - s * ry],
                         [0.0, 0.0, 1.0]])
    return pose, jacobian @ apex_covariance @ jacobian.T


def fit_apex(segments: SegmentSet, right: int, left: int, apex_xy_m: np.ndarray,
             yaw_rad: float, shape: DockShape) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """
    Fit the apex frame to the two faces' lines, knowing the dock's opening angle (eq. D1).

    The faces' lines (alpha_i, r_i), covariances C_i, are modelled from the apex frame
    s = (x, y, yaw): alpha_i = yaw + c_i, r_i = (cos alpha_i, sin alpha_i) . (x, y), c_i the
    normal of face i in the apex frame (towards the face from the sensor's side). Gauss-Newton
    on sum_i e_i^T C_i^-1 e_i from the corner's pose (two steps); Cov(s) = (J^T W J)^-1.
    Unlike the corner, whose walls' angles are free, the opening angle is the dock's: its
    error no longer moves the apex. In plain floats: numpy's small-matrix calls would cost
    more than the whole fit.

    :param segments: the scan's segments
    :param right: index of the right face's segment
    :param left: index of the left face's segment
    :param apex_xy_m: the corner, shape (2,), m (the start)
    :param yaw_rad: the apex frame's yaw from the corner, rad (the start)
    :param shape: the dock (its opening angle)
    :return: (x, y, yaw) shape (3,) and its covariance shape (3, 3); None when a line's
        covariance is not positive definite or the fit is not finite
    """
    half = 0.5 * shape.opening_angle_rad
    x, y, yaw = float(apex_xy_m[0]), float(apex_xy_m[1]), yaw_rad
    c, s = math.cos(yaw), math.sin(yaw)
    # The sensor in the apex frame, to orient each face's normal from the sensor's side.
    sensor_x, sensor_y = -(c * x + s * y), s * x - c * y
    faces = []
    for side, wall in ((-1.0, right), (1.0, left)):
        normal_x, normal_y = math.sin(half), side * math.cos(half)
        if normal_x * sensor_x + normal_y * sensor_y > 0.0:
            normal_x, normal_y = -normal_x, -normal_y
        (caa, car), (_, crr) = segments.covariance[wall].tolist()
        det = caa * crr - car * car
        if not (caa > 0.0 and det > 0.0):          # NaN included
            return None
        faces.append((math.atan2(normal_y, normal_x), float(segments.angle_rad[wall]),
                      float(segments.radius_m[wall]), crr / det, -car / det, caa / det))
    for _ in range(2):
        # The normal matrix J^T W J (its upper triangle) and J^T W e, summed over the faces;
        # J's rows: d alpha / d s = (0, 0, 1), d r / d s = (ca, sa, q), q = -sa x + ca y.
        nxx = nxy = nyy = nxt = nyt = ntt = gx = gy = gt = 0.0
        for offset, alpha_seen, radius_seen, waa, war, wrr in faces:
            alpha = yaw + offset
            ca, sa = math.cos(alpha), math.sin(alpha)
            q = ca * y - sa * x
            error_alpha = _wrap(alpha_seen - alpha)
            error_radius = radius_seen - (ca * x + sa * y)
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
        covariance = _inverse3([[nxx, nxy, nxt], [nxy, nyy, nyt], [nxt, nyt, ntt]])
        if covariance is None:
            return None
        (pxx, pxy, pxt), (_, pyy, pyt), (_, _, ptt) = covariance
        x += pxx * gx + pxy * gy + pxt * gt
        y += pxy * gx + pyy * gy + pyt * gt
        yaw += pxt * gx + pyt * gy + ptt * gt
    # Plain floats checked first: numpy's calls on a 3-vector cost more than the fit's steps.
    if covariance is None or not all(math.isfinite(value) for value in (
            x, y, yaw, *covariance[0], *covariance[1], *covariance[2])):
        return None
    return np.array([x, y, _wrap(yaw)]), np.array(covariance)


def _wrap(angle_rad: float) -> float:
    """Return a scalar angle wrapped into [-pi, pi]."""
    return math.remainder(angle_rad, 2.0 * math.pi)


def _inverse3(matrix: list) -> Optional[list]:
    """Return the inverse of a 3x3 matrix (lists of floats) by its adjugate; None if singular."""
    (a, b, c), (d, e, f), (g, h, i) = matrix
    cofactors = [[e * i - f * h, c * h - b * i, b * f - c * e],
                 [f * g - d * i, a * i - c * g, c * d - a * f],
                 [d * h - e * g, b * g - a * h, a * e - b * d]]
    det = a * cofactors[0][0] + b * cofactors[1][0] + c * cofactors[2][0]
    if not abs(det) > 0.0:
        return None
    return [[value / det for value in row] for row in cofactors]


# A return lies on a face (or its extension) within this many standard deviations of its
# deciding noise (eq. D19 of derivation.md): the fit's gate and a face's reach (eq. D8).
ON_FACE_SIGMAS = 3.0
# The returns of a face must count at least this many to be fitted.
MIN_FACE_RETURNS = 4
# How far beyond a face's outer end (and its tolerance) its returns are looked at, m.
BEYOND_M = 0.05
# A start's window also holds the faces of a fit this much farther out, m.
WINDOW_MARGIN_M = 0.05
# The walk of a straight face's residuals from its own line, less its share of their total,
# exceeds this times sqrt(N) once in a thousand (Monte Carlo: 1.08 at N = 15 returns, 1.14 at
# 50, 1.18 at 150; eq. D10).
STRAIGHT_BRIDGE = 1.2
# Two fits whose apexes are closer than this are one dock, m.
SAME_DOCK_M = 0.05
# A segment this long or longer may start the fit alone, as one face (at 0.3 m), m.
SINGLE_SEGMENT_M = 0.1
# ... and of this many returns or more: the faces merged at the apex are seen close by (55-206
# returns on a face's segment at 0.3 m); faces of 8-16 returns (3 m) have look-alikes that
# pass the fit's tests, and there the core gives each face a segment of its own.
SINGLE_SEGMENT_RETURNS = 30


@dataclass(frozen=True)
class DockReturns:
    """
    One scan's returns and the noise model the core processed it with.

    What the fit of the dock to its returns needs (docs/docking.md, eq. D5-D9).

    :ivar ranges_m: the scan's ranges, shape (N,), m (NaN, inf or outside the limits: none)
    :ivar angle_min_rad: bearing of beam 0, rad
    :ivar angle_increment_rad: bearing step, rad (either sign)
    :ivar range_sigma_m: the scan's range noise (``Features.range_sigma_m``), m
    :ivar bearing_sigma_rad: bearing noise, rad
    :ivar model_error_sigma_m: how far a return may stray from the model beyond its noise
        (the decisions' widening, eq. D19 of derivation.md), m
    :ivar common_range_sigma_m: std of the scan's common range offset (eq. D16 there), m
    :ivar flatness_sigma_m: each end of a face may lie this far off its line (as eq. D18
        there), m; 0: the faces are flat
    :ivar residual_scaling: scale the covariance by the fit's excess chi2 (eq. D17 there)
    :ivar range_min_m: shortest valid range, m
    :ivar range_max_m: longest valid range, m
    """

    ranges_m: np.ndarray
    angle_min_rad: float
    angle_increment_rad: float
    range_sigma_m: float
    bearing_sigma_rad: float
    model_error_sigma_m: float = 0.0
    common_range_sigma_m: float = 0.0
    flatness_sigma_m: float = 0.0
    residual_scaling: bool = True
    range_min_m: float = 0.0
    range_max_m: float = math.inf

    @property
    def full_turn(self) -> bool:
        """Tell whether the beams go all the way round (the window may cross the seam)."""
        return len(self.ranges_m) * abs(self.angle_increment_rad) >= 2.0 * math.pi - 1e-6


def dock_returns(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                 config: FeatureConfig, range_sigma_m: float, range_min_m: float = 0.0,
                 range_max_m: float = math.inf) -> DockReturns:
    """
    Bundle a scan's returns with the noise model of the configuration it was processed with.

    The faces are taken as flat: ``wall_flatness_sigma_m`` is the building's walls', not a
    dock's (set ``flatness_sigma_m`` of the result for a dock of bowed faces).

    :param ranges_m: the ranges, shape (N,), m
    :param angle_min_rad: bearing of beam 0, rad
    :param angle_increment_rad: bearing step, rad
    :param config: the core's configuration (its noise model)
    :param range_sigma_m: the scan's range noise (``Features.range_sigma_m``; NaN: the
        configuration's ``range_sigma_m``), m
    :param range_min_m: the scan's range_min, m
    :param range_max_m: the scan's range_max, m
    :return: the bundle
    """
    sigma = range_sigma_m if math.isfinite(range_sigma_m) else config.range_sigma_m
    return DockReturns(np.asarray(ranges_m, dtype=float), float(angle_min_rad),
                       float(angle_increment_rad), float(sigma), config.bearing_sigma_rad,
                       config.model_error_sigma_m, config.common_range_sigma_m, 0.0,
                       config.residual_scaling, max(float(range_min_m), config.range_min_m),
                       min(float(range_max_m), config.range_max_m))


@dataclass(frozen=True)
class ReturnsFit:
    """
    The dock fitted to the returns of a scan (eq. D5-D9), in the apex frame.

    :ivar pose: (x, y, yaw) of the apex frame, shape (3,), m, m, rad
    :ivar covariance: its covariance, shape (3, 3)
    :ivar returns: returns fitted on the right and the left face
    :ivar reach_m: how far from the apex each face (right, left) is seen without a break, m
        (NaN: not at all)
    :ivar spacing_m: the returns' spacing along each face at its outer end, m
    :ivar past_end: per face, the returns past its end and ``face_tolerance_m`` (up to
        BEYOND_M farther) that lie on its line, and those farther than it or none
    :ivar opening_angle_rad: the opening angle of the two faces' own lines, rad
    :ivar bends: per face, the largest excursion of the running sum of its returns' residuals
        from its own line (over their deciding noise), less its share of their total, over
        sqrt(N) (eq. D10; a straight face's exceeds STRAIGHT_BRIDGE once in a thousand)
    :ivar chi2: the fit's weighted squared residuals
    """

    pose: np.ndarray
    covariance: np.ndarray
    returns: Tuple[int, int]
    reach_m: Tuple[float, float]
    spacing_m: Tuple[float, float]
    past_end: Tuple[Tuple[int, int], Tuple[int, int]]
    opening_angle_rad: float
    bends: Tuple[float, float]
    chi2: float


def _faces(x: float, y: float, yaw: float, shape: DockShape) -> list:
    """Return each face's (outward direction, normal, length): right then left (eq. D5)."""
    half = 0.5 * shape.opening_angle_rad
    c, s = math.cos(yaw), math.sin(yaw)
    faces = []
    for side, length in ((-1.0, shape.right_face_m), (1.0, shape.left_face_m)):
        dx, dy = -math.cos(half), side * math.sin(half)
        ux, uy = c * dx - s * dy, s * dx + c * dy
        faces.append((ux, uy, -uy, ux, length))
    return faces


class _Beams(NamedTuple):
    """The returns of a start's window, and what every pass over them reads."""

    rho: np.ndarray          # ranges, (M,), m (1 where there is no return)
    directions: np.ndarray   # (2, M): cos, sin of the bearings
    valid: np.ndarray        # (M,): a return
    inverse: np.ndarray      # (M,): 1 / rho
    gate_cos2: np.ndarray    # (M,): the squared gate on a return's offset is
    gate: np.ndarray         # gate_cos2 cos^2 + gate, cos that of the beam on the face, m^2


def _beams(returns: DockReturns, pose: Tuple[float, float, float], shape: DockShape,
           beyond_m: float) -> Optional[_Beams]:
    """Return the beams that may see the dock at ``pose``, its faces extended by beyond_m."""
    x, y, yaw = pose
    points = [(x, y)]
    for ux, uy, _, _, length in _faces(x, y, yaw, shape):
        points.append((x + (length + beyond_m) * ux, y + (length + beyond_m) * uy))
    apex_bearing = math.atan2(y, x)
    offsets = [_wrap(math.atan2(py, px) - apex_bearing) for px, py in points]
    increment, count = returns.angle_increment_rad, len(returns.ranges_m)
    centre = (apex_bearing - returns.angle_min_rad) / increment
    if returns.full_turn:
        centre %= count
    ends = [centre + offset / increment for offset in offsets]
    first, last = math.floor(min(ends)) - 1, math.ceil(max(ends)) + 1
    if last - first > count:
        return None
    index = np.arange(first, last + 1)
    index = index % count if returns.full_turn else index[(index >= 0) & (index < count)]
    if len(index) < 2 * MIN_FACE_RETURNS:
        return None
    rho = returns.ranges_m[index]
    bearing = returns.angle_min_rad + increment * index
    with np.errstate(invalid='ignore'):
        valid = (np.isfinite(rho) & (rho > 0.0) & (rho >= returns.range_min_m)
                 & (rho <= returns.range_max_m))
    rho = np.where(valid, rho, 1.0)
    across = ON_FACE_SIGMAS ** 2 * (returns.range_sigma_m ** 2
                                    + returns.model_error_sigma_m ** 2)
    along = (ON_FACE_SIGMAS * returns.bearing_sigma_rad) ** 2 * rho * rho
    return _Beams(rho, np.stack([np.cos(bearing), np.sin(bearing)]), valid, 1.0 / rho,
                  across - along, along)


class _Pass(NamedTuple):
    """What one pass over the window's returns gives (:func:`_assign`)."""

    sums: np.ndarray        # (2, 2, J): per face, sum w u_i column_j (u: cos, sin of a beam)
    scalars: np.ndarray     # (2, 2): per face, sum w and sum w inverse^2
    counts: np.ndarray      # (2,): returns fitted per face
    reach: list             # per face, m (NaN: not seen); empty unless final
    spans: list             # per face, (first, last) position of its fitted returns, m
    past_end: list          # per face, returns past its end on its line, and farther
    own_sums: np.ndarray    # (2, 2, 3): the sums of each face's own line (eq. D9)
    bends: list             # per face, its residuals' bridge over sqrt(N) (eq. D10)


def _assign(beams: _Beams, returns: DockReturns, pose: Tuple[float, float, float],
            shape: DockShape, beyond_m: float, final: bool) -> Optional[_Pass]:
    """
    Assign the window's returns to the faces the dock at ``pose`` predicts they hit.

    Then sum what the fit needs (eq. D5-D8); both faces at once, as rows 0 (right) and 1
    (left).

    :return: the pass; None when a face has fewer than MIN_FACE_RETURNS returns on it
    """
    x, y, yaw = pose
    (ux0, uy0, nx0, ny0, length0), (ux1, uy1, nx1, ny1, length1) = _faces(x, y, yaw, shape)
    projected = np.array([[nx0, ny0], [nx1, ny1], [ux0, uy0], [ux1, uy1]]) @ beams.directions
    cosine = projected[:2]                               # cos(bearing - normal), (2, M)
    with np.errstate(divide='ignore', invalid='ignore'):
        hit = np.array([[nx0 * x + ny0 * y], [nx1 * x + ny1 * y]]) / cosine   # its range, m
        along = hit * projected[2:] - np.array([[ux0 * x + uy0 * y], [ux1 * x + uy1 * y]])
        cos2 = cosine * cosine
        offset = (beams.rho - hit) * cosine              # a return across the line, m
        gate2 = beams.gate_cos2 * cos2 + beams.gate
        on = (offset * offset <= gate2) & beams.valid
        length = np.array([[length0], [length1]])
        meets = (hit > 0.0) & (along >= 0.0) & (along <= length)
    # Each beam sees the nearer face that its ray meets within the face's length.
    both, nearer_right = meets[0] & meets[1], hit[0] <= hit[1]
    sees = meets & np.stack([~both | nearer_right, ~both | ~nearer_right])
    used = sees & on
    counts = np.count_nonzero(used, axis=1)
    if counts.min() < MIN_FACE_RETURNS:
        return None
    sigma2 = returns.range_sigma_m ** 2
    h2 = np.where(sees, hit * hit, 1.0)
    c2 = np.where(sees, cos2, 1.0)
    # The inverse range, its second-order bias removed, and its weight (eq. D6).
    inverse = beams.inverse - sigma2 / (h2 * np.sqrt(h2))
    weights = h2 * h2 / (sigma2 + returns.bearing_sigma_rad ** 2 * h2 * (1.0 - c2) / c2)
    weight = np.where(used, weights, 0.0)
    columns = [np.broadcast_to(beams.directions, (2, 2, beams.rho.size)), inverse[:, None]]
    if final:
        ranged = 1.0 / h2                                # -d(1/rho)/d(rho)
        shifted = ranged / np.where(used, cosine, 1.0)   # ... per shift of the face
        columns += [ranged[:, None], shifted[:, None], (shifted * along)[:, None]]
    # sums[k, i, j]: over face k, the sum of w u_i column_j.
    sums = (weight[:, None, :] * beams.directions) @ np.concatenate(columns, axis=1).transpose(
        0, 2, 1)
    scalars = np.stack([weight.sum(axis=1), (weight * inverse * inverse).sum(axis=1)], axis=1)
    if not final:
        return _Pass(sums, scalars, counts, [], [], [], sums, [])
    # Each face's own line (eq. D9), from its returns within the gate widened by the
    # opening angle's tolerance: gated at the dock's line alone, it would lean towards it.
    with np.errstate(invalid='ignore'):
        own = sees & beams.valid & (np.abs(offset) <= np.sqrt(gate2) + np.maximum(along, 0.0)
                                    * math.sin(shape.angle_tolerance_rad))
    own_sums = (np.where(own, weights, 0.0)[:, None, :] * beams.directions) @ np.concatenate(
        columns[:2], axis=1).transpose(0, 2, 1)
    # Their residuals from that line over the deciding noise, for the test of straightness.
    own_p = np.linalg.solve(own_sums[:, :, :2], own_sums[:, :, 2:])      # (2, 2, 1)
    deciding = returns.range_sigma_m ** 2 + returns.model_error_sigma_m ** 2
    standard = (inverse - (own_p * beams.directions).sum(axis=1)) * h2 / np.sqrt(
        deciding + returns.bearing_sigma_rad ** 2 * h2 * (1.0 - c2) / c2)
    tolerated = length + shape.face_tolerance_m
    with np.errstate(invalid='ignore'):
        beyond = (along > length) & (along <= tolerated + beyond_m) & ~sees[::-1] & (hit > 0.0)
        # Past the end and its tolerance (eq. D8): on the face's line, or farther (none).
        past = beyond & (along > tolerated)
        farther = ~beams.valid | (~on & (beams.rho > hit))
    past_end = np.stack([np.count_nonzero(past & on, axis=1),
                         np.count_nonzero(past & farther, axis=1)], axis=1).tolist()
    looked_at = (sees | beyond) & beams.valid
    reach, spans, bends = [], [], []
    for k in range(2):
        # The face's reach (eq. D8): its returns along it and beyond its outer end, in the
        # order of the position their rays meet it (monotonic over the window), up to the
        # first two in a row off its line.
        where = np.flatnonzero(looked_at[k])
        if len(where) > 1 and along[k, where[0]] > along[k, where[-1]]:
            where = where[::-1]
        seen = on[k, where]
        breaks = np.flatnonzero(~(seen[:-1] | seen[1:]))
        if len(breaks):
            where, seen = where[:breaks[0]], seen[:breaks[0]]
        reach.append(float(along[k, where[seen]].max()) if seen.any() else math.nan)
        fitted = along[k, used[k]]
        spans.append((float(fitted.min()), float(fitted.max())))
        # A face is straight (eq. D10): the running sum of its residuals, less its share of
        # their total, stays within STRAIGHT_BRIDGE sqrt(N).
        walk = np.cumsum(standard[k, own[k]])
        if len(walk) > 2:
            bridge = walk - walk[-1] * np.arange(1, len(walk) + 1) / len(walk)
            bends.append(float(np.abs(bridge).max()) / math.sqrt(len(walk)))
        else:
            bends.append(math.inf)
    return _Pass(sums, scalars, counts, reach, spans, past_end, own_sums, bends)


def _face_sums(taken: _Pass) -> list:
    """Return per face (sum w u u^T: xx, xy, yy; sum w u / rho: x, y; sum w / rho^2)."""
    sums, scalars = taken.sums.tolist(), taken.scalars.tolist()
    return [(s[0][0], s[0][1], s[1][1], s[0][2], s[1][2], c[1]) for s, c in zip(sums, scalars)]


def _face_line(normal_offset: float, x: float, y: float, yaw: float):
    """Return p = n / r of a face (eq. D6) and dp / d(x, y, yaw), 2 x 3; None through (0, 0)."""
    nx, ny = math.cos(yaw + normal_offset), math.sin(yaw + normal_offset)
    radius = nx * x + ny * y
    if abs(radius) < 1e-9:
        return None
    inverse2 = 1.0 / (radius * radius)
    turn = (nx * y - ny * x) * inverse2                  # (n_perp . a) / r^2
    return ((nx / radius, ny / radius),
            ((-nx * nx * inverse2, -nx * ny * inverse2, -ny / radius - nx * turn),
             (-ny * nx * inverse2, -ny * ny * inverse2, nx / radius - ny * turn)))


def _normal_equations(face_sums: list, normal_offsets: Tuple[float, float], x: float,
                      y: float, yaw: float):
    """
    Return J^T W J, J^T W e and chi2 of the two faces' returns at the apex frame (eq. D6).

    The residual of a return is 1/rho - p_k . u (u its beam's direction, p_k = n_k / r_k of
    its face): linear in p_k, so each face's weighted sums of u u^T, u / rho and 1 / rho^2
    give its share, and J = -u^T dp_k/ds. None when a face's line passes through the sensor.
    """
    h00 = h01 = h02 = h11 = h12 = h22 = g0 = g1 = g2 = chi2 = 0.0
    for (axx, axy, ayy, bx, by, cc), offset in zip(face_sums, normal_offsets):
        line = _face_line(offset, x, y, yaw)
        if line is None:
            return None
        (px, py), ((j0, j1, j2), (k0, k1, k2)) = line
        # A p - b is half the gradient of chi2 = p^T A p - 2 p^T b + c in p.
        rx, ry = axx * px + axy * py - bx, axy * px + ayy * py - by
        chi2 += px * (rx - bx) + py * (ry - by) + cc
        a0, a1, a2 = axx * j0 + axy * k0, axx * j1 + axy * k1, axx * j2 + axy * k2
        b0, b1, b2 = axy * j0 + ayy * k0, axy * j1 + ayy * k1, axy * j2 + ayy * k2
        h00 += j0 * a0 + k0 * b0
        h01 += j0 * a1 + k0 * b1
        h02 += j0 * a2 + k0 * b2
        h11 += j1 * a1 + k1 * b1
        h12 += j1 * a2 + k1 * b2
        h22 += j2 * a2 + k2 * b2
        g0 += j0 * rx + k0 * ry
        g1 += j1 * rx + k1 * ry
        g2 += j2 * rx + k2 * ry
    return [[h00, h01, h02], [h01, h11, h12], [h02, h12, h22]], [g0, g1, g2], chi2


def _gauss_newton(face_sums: list, normal_offsets, pose, steps: int = 4):
    """Minimise the faces' chi2 over the apex frame from ``pose`` (eq. D6); None if singular."""
    x, y, yaw = pose
    for _ in range(steps):
        equations = _normal_equations(face_sums, normal_offsets, x, y, yaw)
        inverse = None if equations is None else _inverse3(equations[0])
        if inverse is None:
            return None
        (i0, i1, i2), g = inverse, equations[1]
        dx = -(i0[0] * g[0] + i0[1] * g[1] + i0[2] * g[2])
        dy = -(i1[0] * g[0] + i1[1] * g[1] + i1[2] * g[2])
        dt = -(i2[0] * g[0] + i2[1] * g[1] + i2[2] * g[2])
        x, y, yaw = x + dx, y + dy, yaw + dt
        if abs(dx) + abs(dy) < 1e-6 and abs(dt) < 1e-6:
            break
    return x, y, yaw


def _own_lines_angle(own_sums: np.ndarray, pose: Tuple[float, float, float],
                     shape: DockShape) -> float:
    """Return the opening angle between the faces' own lines, p = A^-1 b (eq. D9)."""
    directions = []
    for ((axx, axy, bx), (_, ayy, by)), (ux, uy, _, _, _) in zip(
            own_sums.tolist(), _faces(pose[0], pose[1], pose[2], shape)):
        px, py = ayy * bx - axy * by, axx * by - axy * bx     # det A times p
        dx, dy = -py, px                                 # along the line
        directions.append((dx, dy) if dx * ux + dy * uy >= 0.0 else (-dx, -dy))
    (ax, ay), (bx, by) = directions
    norm = math.hypot(ax, ay) * math.hypot(bx, by)
    if not norm > 0.0:
        return math.nan
    between = math.acos(max(-1.0, min(1.0, (ax * bx + ay * by) / norm)))
    return between if shape.opening_angle_rad < math.pi else 2.0 * math.pi - between


def _spacing(returns: DockReturns, pose, shape: DockShape) -> Tuple[float, float]:
    """Return the returns' spacing along each face at its outer end, m."""
    x, y, yaw = pose
    spacing = []
    for ux, uy, nx, ny, length in _faces(x, y, yaw, shape):
        tip_x, tip_y = x + length * ux, y + length * uy
        tip_range = math.hypot(tip_x, tip_y)
        cosine = abs(nx * tip_x + ny * tip_y) / max(tip_range, 1e-12)
        spacing.append(abs(returns.angle_increment_rad) * tip_range / max(cosine, 1e-3))
    return spacing[0], spacing[1]


def fit_returns(returns: DockReturns, start: Tuple[float, float, float], shape: DockShape,
                compiled: Optional[bool] = None) -> Optional[ReturnsFit]:
    """
    Fit the dock's two faces, at its opening angle, to the scan's returns (eq. D5-D9).

    From the start (x, y, yaw) of the apex frame, each return of the window is assigned to the
    face its ray meets first within the face's length (eq. D5) and kept when it lies on that
    face within ON_FACE_SIGMAS of its deciding noise; Gauss-Newton on the weighted squared
    residuals of the inverse ranges, from the weighted sums of each face's returns (eq. D6);
    the assignment is made again at that pose and the fit repeated. Cov = f (J^T W J)^-1 plus
    the common range offset (and the faces' flatness, when set) carried through the fit (eq.
    D7). Each face's reach (eq. D8) and the two faces' own opening angle (eq. D9) are what
    :func:`find_docks` tests.

    These numpy steps are the specification; their compiled twin (numba,
    ``core/numba_core/dock.py``) gives the same fit within 1e-9 relative in one compiled call,
    and runs whenever the compiled core serves (:func:`wctls_ros.core.runtime.compiled_kernels`).

    :param returns: the scan's returns and noise model
    :param start: the apex frame's start (x, y, yaw), m, m, rad
    :param shape: the dock
    :param compiled: None: the compiled twin while the compiled core serves, else the numpy
        steps; True: the compiled twin (the compiled core is loaded, or compiled, first);
        False: the numpy steps
    :return: the fit; None when a face has fewer than MIN_FACE_RETURNS returns on it or the
        equations are singular
    :raises wctls_ros.core.CoreUnavailable: with ``compiled`` True, when numba cannot give the
        compiled core
    """
    kernels = runtime.compiled_kernels('dock', compiled)
    if kernels is not None:
        return _fit_returns_compiled(kernels, returns, start, shape)
    return _fit_returns_numpy(returns, start, shape)


def _fit_returns_numpy(returns: DockReturns, start: Tuple[float, float, float],
                       shape: DockShape) -> Optional[ReturnsFit]:
    """Run :func:`fit_returns` by its numpy steps, the specification."""
    beyond = shape.face_tolerance_m + BEYOND_M           # the window's extent past the ends
    (_, _, nx0, ny0, _), (_, _, nx1, ny1, _) = _faces(0.0, 0.0, 0.0, shape)
    normal_offsets = (math.atan2(ny0, nx0), math.atan2(ny1, nx1))
    pose = (float(start[0]), float(start[1]), float(start[2]))
    beams = _beams(returns, pose, shape, beyond + WINDOW_MARGIN_M)
    if beams is None:
        return None
    taken: Optional[_Pass] = None
    for final in (False, True):
        taken = _assign(beams, returns, pose, shape, BEYOND_M, final)
        if taken is None:
            return None
        face_sums = _face_sums(taken)
        # The first pass only gives the second its assignment: two steps do.
        fitted = _gauss_newton(face_sums, normal_offsets, pose, 4 if final else 2)
        if fitted is None or not all(math.isfinite(v) for v in fitted):
            return None
        pose = fitted
    x, y, yaw = pose
    equations = _normal_equations(face_sums, normal_offsets, x, y, yaw)
    inverse = None if equations is None else _inverse3(equations[0])
    if inverse is None or taken is None or equations is None:
        return None
    chi2 = equations[2]
    dof = int(taken.counts.sum()) - 3
    scale = 1.0
    if returns.residual_scaling and dof > 0:
        scale = max(1.0, chi2 / dof - math.sqrt(2.0 / dof))
    # What moves the fit besides the returns' own noise, as gradients of J^T W e (eq. D7):
    # the scan's common range offset, and each face's two ends off its line.
    moves, variances = [np.zeros(3)], [returns.common_range_sigma_m ** 2]
    for sums, (first, last), offset in zip(taken.sums.tolist(), taken.spans, normal_offsets):
        _, (jx, jy) = _face_line(offset, x, y, yaw)
        jacobian = np.array([jx, jy]).T                  # (3, 2): dp / ds transposed
        moves[0] = moves[0] + jacobian @ (sums[0][3], sums[1][3])
        if returns.flatness_sigma_m > 0.0 and last > first:
            # A face's end moves each return by its weight lambda along the face (0 at the
            # first return, 1 at the last): sum w u lambda / (rho^2 cos) from two sums.
            far = [(sums[i][5] - first * sums[i][4]) / (last - first) for i in range(2)]
            moves += [jacobian @ (sums[0][4] - far[0], sums[1][4] - far[1]), jacobian @ far]
            variances += [returns.flatness_sigma_m ** 2] * 2
    information = np.array(inverse)
    moved = information @ np.array(moves).T               # (3, K): d pose / d disturbance
    covariance = scale * information + (moved * variances) @ moved.T
    covariance = 0.5 * (covariance + covariance.T)
    if not np.isfinite(covariance).all():
        return None
    return ReturnsFit(np.array([x, y, _wrap(yaw)]), covariance,
                      (int(taken.counts[0]), int(taken.counts[1])),
                      (taken.reach[0], taken.reach[1]), _spacing(returns, pose, shape),
                      (tuple(taken.past_end[0]), tuple(taken.past_end[1])),
                      _own_lines_angle(taken.own_sums, pose, shape),
                      (taken.bends[0], taken.bends[1]), chi2)


def _fit_returns_compiled(kernels: Any, returns: DockReturns,
                          start: Tuple[float, float, float],
                          shape: DockShape) -> Optional[ReturnsFit]:
    """Run :func:`fit_returns` by its compiled twin (``numba_core/dock.py``)."""
    values = kernels.fit_returns(*_twin_returns(returns),
                                 (float(start[0]), float(start[1]), float(start[2])),
                                 _shape_tuple(shape))
    if not len(values):
        return None
    v = values.tolist()
    return ReturnsFit(values[:3].copy(), values[3:12].reshape(3, 3).copy(),
                      (int(v[12]), int(v[13])), (v[14], v[15]), (v[16], v[17]),
                      ((int(v[18]), int(v[19])), (int(v[20]), int(v[21]))), v[22],
                      (v[23], v[24]), v[25])


def find_docks(segments: SegmentSet, corners: CornerSet, shape: DockShape,
               returns: Optional[DockReturns] = None,
               compiled: Optional[bool] = None) -> List[DockPose]:
    """
    Return every place of a scan that has the dock's shape, as a dock pose.

    With the scan's returns (the node's and ``process_bag``'s way), the dock is fitted to them
    (:func:`fit_returns`, eq. D5-D9) from starts: the corners whose opening angle is within
    twice the tolerance of the dock's, and when none of them is the dock, every two segments
    neighbouring in scan order, or with one between them, whose lines meet at that angle near
    their facing ends (the corner need not have been found), and when those give no dock
    either, each segment alone as one face where the other face is seen (eq. D11; its fit
    made twice). A fit is kept when each face's reach (its returns on its line from the apex
    outward, the ones the extraction left out of its segment too) is as long as the face, at
    most ``face_tolerance_m`` longer and at most ``face_shortfall_m`` plus one return spacing
    shorter, and the faces' own lines meet at the dock's angle within
    ``angle_tolerance_rad``.

    Without the returns, from the corners alone (eq. D1): a corner matches when both its
    walls are seen up to it, its opening angle is within the tolerance of the dock's, its
    walls lie on either side of its bisector, and each wall, from the apex to its outer end,
    is as long as its face in the same sense; its pose is :func:`fit_apex`'s.

    Either way, which wall is the right face follows from the side of the apex frame its outer
    end lies on, not from the scan order (the seam of a turn), and the pose is moved to the
    reference point (:func:`reference_pose`, eq. D2-D3).

    :param segments: the scan's segments
    :param corners: the scan's corners (their segment indices point into ``segments``)
    :param shape: the dock
    :param returns: the scan's returns and noise model (:func:`dock_returns`); None: the
        corners alone
    :param compiled: which implementation of the starts and the fit to the returns runs:
        None: their compiled twins (``core/numba_core/dock.py``) while the compiled core
        serves, else the numpy steps; True: the compiled twins; False: the numpy steps
    :return: the candidates, best fitting first (usually none or one)
    """
    if returns is None:
        return _docks_of_corners(segments, corners, shape)
    kernels = runtime.compiled_kernels('dock', compiled)
    if kernels is not None:
        # The compiled twins of the starts too: numpy's calls on a few segments would cost
        # more than the fit.
        arrays = _twin_arrays(segments, corners)
        docks = _docks_of_returns(returns, kernels.corner_starts(
            *arrays, _shape_tuple(shape)).tolist(), shape, kernels)
        if not docks:
            docks = _docks_of_returns(returns, kernels.segment_pair_starts(
                *arrays[:6], _shape_tuple(shape), bool(returns.full_turn)).tolist(), shape,
                kernels)
        if not docks:
            docks = _docks_of_returns(returns, kernels.segment_starts(
                arrays[3], np.ascontiguousarray(segments.num_points, dtype=np.int64),
                *_twin_returns(returns)[:6], _shape_tuple(shape)).tolist(), shape, kernels,
                refit=True)
        return sorted(docks, key=lambda dock: dock.misfit)
    tried: set = set()
    docks = _docks_of_returns(returns, _corner_starts(segments, corners, shape, tried), shape,
                              None)
    if not docks:
        docks = _docks_of_returns(
            returns, _segment_pair_starts(segments, shape, returns.full_turn, tried), shape,
            None)
    if not docks:
        docks = _docks_of_returns(returns, _segment_starts(segments, returns, shape), shape,
                                  None, refit=True)
    return sorted(docks, key=lambda dock: dock.misfit)


def _twin_returns(returns: DockReturns) -> tuple:
    """
    Return the returns as the compiled twins take them (``numba_core/dock.py``).

    The ranges, angle_min, increment, full turn, (range_min, range_max), the noise (range,
    bearing, model error, common range, flatness sigmas) and the residual scaling; always the
    same argument types: numba compiles one version, the precompiled one.
    """
    return (np.ascontiguousarray(returns.ranges_m, dtype=float), float(returns.angle_min_rad),
            float(returns.angle_increment_rad), bool(returns.full_turn),
            (float(returns.range_min_m), float(returns.range_max_m)),
            (float(returns.range_sigma_m), float(returns.bearing_sigma_rad),
             float(returns.model_error_sigma_m), float(returns.common_range_sigma_m),
             float(returns.flatness_sigma_m)), bool(returns.residual_scaling))


def _twin_arrays(segments: SegmentSet, corners: CornerSet) -> tuple:
    """
    Return the features as the compiled starts take them (``numba_core/dock.py``).

    The segments' angles, radii, (alpha, r) covariances and ends (start x, y, end x, y), the
    corners' segments (all six for both twins), their opening angles, apexes and yaws.
    """
    def floats(values):
        return np.ascontiguousarray(values, dtype=float)
    return (floats(segments.angle_rad), floats(segments.radius_m), floats(segments.covariance),
            floats(np.concatenate([segments.start_xy_m, segments.end_xy_m], axis=1)),
            np.ascontiguousarray(corners.first_segment, dtype=np.int64),
            np.ascontiguousarray(corners.second_segment, dtype=np.int64),
            floats(corners.opening_angle_rad), floats(corners.xy_m), floats(corners.yaw_rad))


def _shape_tuple(shape: DockShape) -> Tuple[float, float, float, float, float]:
    """Return the dock as the compiled twins take it (``numba_core/dock.py``)."""
    return (float(shape.right_face_m), float(shape.left_face_m), float(shape.opening_angle_rad),
            float(shape.face_tolerance_m), float(shape.angle_tolerance_rad))


def _docks_of_returns(returns: DockReturns, starts: list, shape: DockShape,
                      kernels: Any, refit: bool = False) -> List[DockPose]:
    """
    Return the fits from the starts that have the dock's shape, one per dock.

    With ``refit``, each fit is made again from its own pose (the one segment's starts, eq.
    D11: 6-10 cm and up to 20 deg off, their first assignment of the returns is partly wrong).
    """
    docks: List[DockPose] = []
    apexes: List[Tuple[float, float]] = []
    for start in starts:
        fit = None
        for _ in range(2 if refit else 1):
            fit = (_fit_returns_numpy(returns, start, shape) if kernels is None
                   else _fit_returns_compiled(kernels, returns, start, shape))
            if fit is None:
                break
            start = tuple(fit.pose.tolist())
        if fit is None:
            continue
        misfit = returns_misfit(fit, shape)
        if not misfit <= 1.0:
            continue
        # Two starts (a face in two segments) that found the same dock: the better one.
        apex = (float(fit.pose[0]), float(fit.pose[1]))
        same = [k for k, (ax, ay) in enumerate(apexes)
                if math.hypot(ax - apex[0], ay - apex[1]) < SAME_DOCK_M]
        if same and docks[same[0]].misfit <= misfit:
            continue
        pose, covariance = reference_pose(fit.pose[:2], float(fit.pose[2]), fit.covariance,
                                          shape)
        dock = DockPose(float(pose[0]), float(pose[1]), float(pose[2]), covariance,
                        float(misfit))
        if same:
            docks[same[0]], apexes[same[0]] = dock, apex
        else:
            docks.append(dock)
            apexes.append(apex)
    return docks


def returns_misfit(fit: ReturnsFit, shape: DockShape) -> float:
    """
    Return how far a fit's faces are from the dock's, in tolerances (<= 1: the dock; eq. D8-D9).

    The largest of: each face's shortfall, its length less its reach less one return spacing,
    over ``face_shortfall_m``; twice the share of the returns past its end and tolerance that
    lie on its line, among those on it and those farther (the face goes on when they are
    more; nearer ones hide it); the faces' own opening angle's error over
    ``angle_tolerance_rad``.

    :param fit: the fit
    :param shape: the dock
    :return: the misfit
    """
    misfits = [abs(fit.opening_angle_rad - shape.opening_angle_rad)
               / max(shape.angle_tolerance_rad, 1e-12)]
    for reach, spacing, (on, farther), face_m in zip(
            fit.reach_m, fit.spacing_m, fit.past_end, (shape.right_face_m, shape.left_face_m)):
        if not math.isfinite(reach):
            return math.inf
        misfits.append(max(face_m - reach - spacing, 0.0) / max(shape.face_shortfall_m, 1e-9))
        misfits.append(2.0 * on / max(on + farther, 1))
    misfits += [bend / STRAIGHT_BRIDGE for bend in fit.bends]
    return max(misfits)


def _corner_starts(segments: SegmentSet, corners: CornerSet, shape: DockShape,
                   tried: set) -> List[Tuple[float, float, float]]:
    """Return the starts of the corners near the dock's angle (their pairs go into tried)."""
    # Every corner's pair is tried here or not at all: the core saw its angle.
    tried.update(zip(corners.first_segment.tolist(), corners.second_segment.tolist()))
    angle_error = np.abs(corners.opening_angle_rad - shape.opening_angle_rad)
    longest = max(shape.right_face_m, shape.left_face_m) + shape.face_tolerance_m + BEYOND_M
    starts = []
    near = np.flatnonzero(angle_error <= 2.0 * shape.angle_tolerance_rad).tolist()
    ends = _segment_ends(segments) if near else []
    for k in near:
        pair = (int(corners.first_segment[k]), int(corners.second_segment[k]))
        if _farther_than(ends, pair, corners.xy_m[k].tolist(), longest):
            continue
        start = _pair_start(segments, ends, pair, corners.xy_m[k].tolist(),
                            float(wrap_angle(corners.yaw_rad[k] + math.pi)), shape)
        if start is not None:
            starts.append(start)
    return starts


def _segment_ends(segments: SegmentSet) -> list:
    """Return each segment's (start x, start y, end x, end y), m, as plain floats."""
    # The starts' loops read a few of them each: numpy's indexing would cost more than that.
    return np.concatenate([segments.start_xy_m, segments.end_xy_m], axis=1).tolist()


def _farther_than(ends: list, pair: Tuple[int, int], apex: list, distance_m: float) -> bool:
    """Tell whether either segment of a pair (its ends: _segment_ends) reaches farther."""
    for wall in pair:
        sx, sy, ex, ey = ends[wall]
        if (math.hypot(sx - apex[0], sy - apex[1]) > distance_m
                or math.hypot(ex - apex[0], ey - apex[1]) > distance_m):
            return True
    return False


def _pair_start(segments: SegmentSet, ends: list, pair: Tuple[int, int], apex: list,
                yaw: float, shape: DockShape) -> Optional[Tuple[float, float, float]]:
    """Return fit_apex's start of two segments meeting at apex (eq. D1); None if not a V."""
    c, s = math.cos(yaw), math.sin(yaw)
    sides = []
    for wall in pair:
        sx, sy, ex, ey = ends[wall]
        sides.append(c * (0.5 * (sy + ey) - apex[1]) - s * (0.5 * (sx + ex) - apex[0]))
    if not sides[0] * sides[1] < 0.0:
        return None
    right, left = pair if sides[0] < 0.0 else pair[::-1]
    fit = fit_apex(segments, right, left, np.array(apex), yaw, shape)
    return (apex[0], apex[1], yaw) if fit is None else tuple(fit[0].tolist())


def _segment_pair_starts(segments: SegmentSet, shape: DockShape, full_turn: bool,
                         tried: set) -> List[Tuple[float, float, float]]:
    """
    Return the apex frames where two segments near in scan order meet at the dock's angle.

    Pairs of neighbours and of segments one apart (a piece split off a face, or a short
    segment between the faces), across the seam on a full turn, not yet tried; their lines'
    opening angle within twice the tolerance, of the dock's kind (a V or a wedge), both
    segments going out from the intersection no farther than the longer face and its
    tolerance plus BEYOND_M, one on each side of the bisector. The start is
    :func:`fit_apex`'s pose of the two lines (eq. D1).
    """
    count = len(segments)
    if count < 2:
        return []
    first = np.arange(count)
    pairs = []
    for step in (1, 2):
        second = first + step
        keep = second < count
        if full_turn:
            second, keep = second % count, second % count != first
        pairs.append(np.stack([first[keep], second[keep]], axis=1))
    pair = np.concatenate(pairs)
    angles = segments.angle_rad
    between = np.abs(wrap_angle(angles[pair[:, 1]] - angles[pair[:, 0]]))
    pair = pair[np.abs(between - abs(math.pi - shape.opening_angle_rad))
                <= 2.0 * shape.angle_tolerance_rad]
    longest = max(shape.right_face_m, shape.left_face_m) + shape.face_tolerance_m + BEYOND_M
    concave = shape.opening_angle_rad < math.pi
    starts: List[Tuple[float, float, float]] = []
    if not len(pair):
        return starts
    ends, angle, radius = _segment_ends(segments), angles.tolist(), segments.radius_m.tolist()
    for i, j in pair.tolist():
        if (i, j) in tried or (j, i) in tried:
            continue
        ai, aj = angle[i], angle[j]
        det = math.sin(aj - ai)
        if abs(det) < 1e-9:
            continue
        ri, rj = radius[i], radius[j]
        px = (ri * math.sin(aj) - rj * math.sin(ai)) / det
        py = (rj * math.cos(ai) - ri * math.cos(aj)) / det
        if _farther_than(ends, (i, j), [px, py], longest):
            continue
        bx = by = 0.0
        for wall in (i, j):
            sx, sy, ex, ey = ends[wall]
            mx, my = 0.5 * (sx + ex) - px, 0.5 * (sy + ey) - py
            middle = math.hypot(mx, my)
            if not middle > 0.0:
                break
            bx, by = bx + mx / middle, by + my / middle    # the bisector
        else:
            if (bx * px + by * py < 0.0) != concave:
                continue
            # The apex frame's x axis points away from the robot's side (eq. D1).
            yaw = math.atan2(-by, -bx) if concave else math.atan2(by, bx)
            start = _pair_start(segments, ends, (i, j), [px, py], yaw, shape)
            if start is not None:
                starts.append(start)
    return starts


def _segment_starts(segments: SegmentSet, returns: DockReturns,
                    shape: DockShape) -> List[Tuple[float, float, float]]:
    """
    Return the apex frames where one segment alone may be a face of the dock.

    At 0.3 m the core often gives one face no segment of its own (merged with the apex of the
    other, or split): each segment of SINGLE_SEGMENT_M up to its face's length, tolerance and
    BEYOND_M, of SINGLE_SEGMENT_RETURNS returns or more, is tried as either face, either end
    the apex, along its line; the sensor must see both faces' fronts. A start is kept when the
    other face, where it predicts it, is seen (:func:`_other_face_seen`): the cheap test that
    spares most of them the fit (eq. D11 of docs/docking.md).
    """
    starts: List[Tuple[float, float, float]] = []
    half = 0.5 * shape.opening_angle_rad
    concave = 1.0 if shape.opening_angle_rad < math.pi else -1.0
    faces = ((-math.cos(half), -math.sin(half), shape.right_face_m),
             (-math.cos(half), math.sin(half), shape.left_face_m))
    for (sx, sy, ex, ey), points in zip(_segment_ends(segments), segments.num_points.tolist()):
        length = math.hypot(ex - sx, ey - sy)
        if not (SINGLE_SEGMENT_M <= length <= max(shape.right_face_m, shape.left_face_m) + (
                shape.face_tolerance_m + BEYOND_M) and points >= SINGLE_SEGMENT_RETURNS):
            continue
        for ax, ay, bx, by in ((sx, sy, ex, ey), (ex, ey, sx, sy)):
            dx, dy = (bx - ax) / length, (by - ay) / length       # outward along the face
            for k in range(2):
                fx, fy, face_m = faces[k]
                if length > face_m + shape.face_tolerance_m + BEYOND_M:
                    continue
                yaw = _wrap(math.atan2(dy, dx) - math.atan2(fy, fx))
                c, s = math.cos(yaw), math.sin(yaw)
                ox, oy, other_m = faces[1 - k]
                ux, uy = c * ox - s * oy, s * ox + c * oy         # the other face, outward
                # Both faces' fronts towards the sensor: on the inner side of both lines for
                # a V, the outer for a wedge (cross products with the sensor at (0, 0)).
                turn = dx * uy - dy * ux
                if not (concave * turn * (ax * dy - ay * dx) > 0.0
                        and concave * turn * (ay * ux - ax * uy) > 0.0):
                    continue
                if _other_face_seen(returns, ax, ay, ux, uy, other_m):
                    starts.append((ax, ay, yaw))
    return starts


def _other_face_seen(returns: DockReturns, ax: float, ay: float, ux: float, uy: float,
                     length_m: float) -> bool:
    """
    Tell whether a face from (ax, ay) along (ux, uy) is seen by at least half of its beams.

    The beams between the bearings of its two ends whose rays meet it: their returns within
    D5's gate of it (eq. D5), MIN_FACE_RETURNS at least.
    """
    increment, count = returns.angle_increment_rad, len(returns.ranges_m)
    apex_bearing = math.atan2(ay, ax)
    centre = (apex_bearing - returns.angle_min_rad) / increment
    if returns.full_turn:
        centre %= count
    end = centre + _wrap(math.atan2(ay + length_m * uy, ax + length_m * ux)
                         - apex_bearing) / increment
    index = np.arange(math.ceil(min(centre, end)), math.floor(max(centre, end)) + 1)
    index = index % count if returns.full_turn else index[(index >= 0) & (index < count)]
    bearing = returns.angle_min_rad + increment * index
    cos_b, sin_b = np.cos(bearing), np.sin(bearing)
    nx, ny = -uy, ux
    cosine = nx * cos_b + ny * sin_b
    rho = returns.ranges_m[index]
    with np.errstate(divide='ignore', invalid='ignore'):
        hit = (nx * ax + ny * ay) / cosine
        along = hit * (ux * cos_b + uy * sin_b) - (ux * ax + uy * ay)
        meets = (hit > 0.0) & (along >= 0.0) & (along <= length_m)
        valid = (np.isfinite(rho) & (rho > 0.0) & (rho >= returns.range_min_m)
                 & (rho <= returns.range_max_m))
        rho = np.where(valid, rho, 1.0)
        offset = (rho - hit) * cosine
        across = ON_FACE_SIGMAS ** 2 * (returns.range_sigma_m ** 2
                                        + returns.model_error_sigma_m ** 2)
        spread = (ON_FACE_SIGMAS * returns.bearing_sigma_rad) ** 2 * rho * rho
        on = meets & valid & (offset * offset <= (across - spread) * cosine * cosine + spread)
    seen = int(np.count_nonzero(on))
    return seen >= MIN_FACE_RETURNS and 2 * seen >= int(np.count_nonzero(meets))


def _docks_of_corners(segments: SegmentSet, corners: CornerSet,
                      shape: DockShape) -> List[DockPose]:
    """Return the corners that have the dock's shape, as dock poses (eq. D1-D3)."""
    # Most scans hold no corner of the dock's angle: one vectorised test, then a loop over few.
    # The tolerance alone, not widened by the angle's own std: a right-angle corner seen at a
    # grazing angle scatters by 5 deg and more, and would pass for a 120 deg dock.
    angle_error = np.abs(corners.opening_angle_rad - shape.opening_angle_rad)
    keep = np.flatnonzero((angle_error <= shape.angle_tolerance_rad)
                          & corners.end_seen.all(axis=1))
    docks = []
    for k in keep.tolist():
        # The apex frame's x axis points away from the robot's side: the corner's bisector
        # points into the side the sensor sees.
        yaw = float(wrap_angle(corners.yaw_rad[k] + math.pi))
        apex = corners.xy_m[k]
        faces = [_seen_face(segments, int(wall), apex, yaw)
                 for wall in (corners.first_segment[k], corners.second_segment[k])]
        ((right_side, right, right_step, right_wall),
         (left_side, left, left_step, left_wall)) = sorted(faces)
        if not right_side < 0.0 < left_side:
            continue
        misfits = [_face_misfit(right, right_step, shape.right_face_m, shape),
                   _face_misfit(left, left_step, shape.left_face_m, shape)]
        if max(misfits) > 1.0:
            continue
        misfit = max(*misfits, angle_error[k] / max(shape.angle_tolerance_rad, 1e-12))
        fit = fit_apex(segments, right_wall, left_wall, apex, yaw, shape)
        if fit is None:            # degenerate lines: no pose rather than a NaN one
            continue
        pose, covariance = reference_pose(fit[0][:2], float(fit[0][2]), fit[1], shape)
        docks.append(DockPose(float(pose[0]), float(pose[1]), float(pose[2]), covariance,
                              float(misfit)))
    return sorted(docks, key=lambda dock: dock.misfit)


def _seen_face(segments: SegmentSet, wall: int, apex: np.ndarray,
               yaw_rad: float) -> Tuple[float, float, float, int]:
    """Return a wall's outer end's side (+ left) in the apex frame, length, spacing, index."""
    (start_x, start_y), (end_x, end_y) = segments.start_xy_m[wall].tolist(), segments.end_xy_m[
        wall].tolist()
    apex_x, apex_y = apex.tolist()
    start_m = math.hypot(start_x - apex_x, start_y - apex_y)
    end_m = math.hypot(end_x - apex_x, end_y - apex_y)
    outer_x, outer_y, length = ((start_x, start_y, start_m) if start_m > end_m
                                else (end_x, end_y, end_m))
    side = math.cos(yaw_rad) * (outer_y - apex_y) - math.sin(yaw_rad) * (outer_x - apex_x)
    spacing = math.hypot(end_x - start_x, end_y - start_y) / max(
        int(segments.num_points[wall]) - 1, 1)
    return side, length, spacing, wall


def _face_misfit(seen_m: float, spacing_m: float, face_m: float, shape: DockShape) -> float:
    """Return how far a seen face is from its length, in its tolerance (<= 1 fits)."""
    if seen_m > face_m:
        return (seen_m - face_m) / max(shape.face_tolerance_m, 1e-9)
    return max(face_m - seen_m - spacing_m, 0.0) / max(shape.face_shortfall_m, 1e-9)


@dataclass(frozen=True)
class TrackSettings:
    """
    How detections are checked against the last ones.

    :ivar max_speed_m_s: the fastest the dock may move in the scan's frame (the robot's
        speed while docking, plus the turn rate times the dock's distance), m/s
    :ivar max_turn_rate_rad_s: the fastest the dock's yaw may change (the robot's turn), rad/s
    :ivar confirm_detections: agreeing detections in a row before a dock is reported
    :ivar timeout_s: a dock not seen for this long is forgotten: the next one starts again, s
    :ivar gate: the chi2 bound of an agreeing pose difference (3 dof)
    """

    max_speed_m_s: float = 0.3
    max_turn_rate_rad_s: float = math.radians(30.0)
    confirm_detections: int = 3
    timeout_s: float = 1.0
    gate: float = CHI2_3DOF_999


@dataclass(frozen=True)
class Track:
    """
    A dock seen over consecutive scans.

    :ivar pose: its last detection
    :ivar stamp_s: when, s
    :ivar detections: agreeing detections in a row
    """

    pose: DockPose
    stamp_s: float
    detections: int


@dataclass(frozen=True)
class TrackerState:
    """
    What :func:`track_dock` remembers between scans.

    :ivar track: the dock being followed, or None
    :ivar rival: a detection that disagrees with the track, followed in case the track was a
        mistake (it replaces the track once it is confirmed and the track is not seen)
    """

    track: Optional[Track] = None
    rival: Optional[Track] = None


def pose_chi2(new: DockPose, old: DockPose, elapsed_s: float, settings: TrackSettings) -> float:
    """
    Return the Mahalanobis distance squared between two detections (eq. D4).

    d = (x, y, yaw)_new - (x, y, yaw)_old (yaw wrapped); S = C_new + C_old + Q,
    Q = diag((v dt)^2, (v dt)^2, (w dt)^2) the motion allowed in between; chi2 = d^T S^-1 d.

    :param new: the newer detection
    :param old: the older one
    :param elapsed_s: the time between them, s
    :param settings: the motion allowed
    :return: chi2 (3 dof)
    """
    step2 = (settings.max_speed_m_s * elapsed_s) ** 2
    turn2 = (settings.max_turn_rate_rad_s * elapsed_s) ** 2
    innovation = (new.covariance + old.covariance).tolist()
    for k, allowed in enumerate((step2, step2, turn2)):
        innovation[k][k] += allowed
    difference = (new.x_m - old.x_m, new.y_m - old.y_m, _wrap(new.yaw_rad - old.yaw_rad))
    inverse = _inverse3(innovation)
    if inverse is None:                    # two exact poses, no motion allowed: only equal agree
        return 0.0 if not any(difference) else math.inf
    return sum(difference[i] * inverse[i][k] * difference[k] for i in range(3) for k in range(3))


def _follow(track: Optional[Track], candidates: List[DockPose], stamp_s: float,
            settings: TrackSettings) -> Tuple[Optional[Track], List[DockPose]]:
    """Extend a track with its best agreeing candidate; return it and the others."""
    # A scan older than the track's (a bag played again) starts the tracking afresh.
    if track is None or not 0.0 <= stamp_s - track.stamp_s <= settings.timeout_s:
        return None, candidates
    chi2 = [pose_chi2(c, track.pose, stamp_s - track.stamp_s, settings) for c in candidates]
    if not chi2 or min(chi2) > settings.gate:
        return track, candidates
    best = min(range(len(chi2)), key=chi2.__getitem__)   # the first least, as np.argmin
    rest = candidates[:best] + candidates[best + 1:]
    return Track(candidates[best], stamp_s, track.detections + 1), rest


def track_dock(state: TrackerState, candidates: List[DockPose], stamp_s: float,
               settings: TrackSettings) -> Tuple[TrackerState, Optional[DockPose]]:
    """
    Take one scan's candidates; return the new state and the dock to report, if any.

    The candidate that agrees with the track (chi2 within the gate) extends it; a track seen
    ``confirm_detections`` times in a row is reported, with this scan's detection (never a
    blend: its covariance stays the detection's own). A disagreeing candidate starts or
    extends a rival; a confirmed rival whose track is not seen replaces it. A track or rival
    not seen for ``timeout_s`` (or older than this scan) is dropped.

    :param state: the state after the previous scan
    :param candidates: this scan's detections (:func:`find_docks`), best fitting first
    :param stamp_s: this scan's time, s
    :param settings: gate, motion and confirmation
    :return: (the new state, the dock pose to report or None)
    """
    before = state.track
    track, rest = _follow(state.track, candidates, stamp_s, settings)
    rival, rest = _follow(state.rival, rest, stamp_s, settings)
    extended = track is not None and track is not before
    if track is None and candidates:
        track, rival = Track(candidates[0], stamp_s, 1), None
        extended = True
    elif rest and (rival is None or rival is state.rival):
        rival = Track(rest[0], stamp_s, 1)
    if (not extended and rival is not None and rival is not state.rival
            and rival.detections >= settings.confirm_detections):
        track, rival, extended = rival, None, True
    report = (track.pose if track is not None and extended
              and track.detections >= settings.confirm_detections else None)
    return TrackerState(track, rival), report
