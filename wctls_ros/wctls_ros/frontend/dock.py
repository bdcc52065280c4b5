# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A docking station seen by a 2D LiDAR: two straight faces meeting at an apex, found among corners.

A dock is described by :class:`DockShape`: the length of its right and left faces and the
opening angle between them through the side the robot sees (below 180 deg a V the robot faces
into, above 180 deg a wedge pointing at the robot, 90 deg an L), with tolerances. Each corner
of a scan whose opening angle and faces' lengths match is a candidate (:func:`find_docks`);
its pose is the dock frame: origin at the apex, x along the bisector away from the robot's
side (the way a robot docking forwards faces), y to the left, moved to a stated reference
point. The apex frame is fitted to the corner's two walls knowing the dock's opening angle,
with the covariance of the fit from the walls' own, and moved to the reference point with it
(docs/docking.md, eq. D1-D3). :func:`track_dock` keeps the candidates that agree with the
last ones (a chi2 gate over the pose difference, with the motion allowed in between, eq. D4)
and confirms a dock only after a few agreeing scans.

Everything is in the scan's frame: m, rad. Pure numpy; no ROS.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple

import numpy as np

from ..core import CornerSet, SegmentSet

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
    pose = np.array([x, y, _wrap(yaw)])
    if covariance is None or not (np.isfinite(pose).all()
                                  and np.isfinite(np.array(covariance)).all()):
        return None
    return pose, np.array(covariance)


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


def find_docks(segments: SegmentSet, corners: CornerSet, shape: DockShape) -> List[DockPose]:
    """
    Return every corner of a scan that has the dock's shape, as a dock pose (eq. D1-D3).

    A corner matches when both its walls are seen up to it, its opening angle is within the
    tolerance of the dock's, its walls lie on either side of its bisector, and each wall, from
    the apex to its outer end, is as long as its face: at most ``face_tolerance_m`` longer,
    and at most ``face_shortfall_m`` plus one return spacing shorter (the edge lies between
    the last return on the face and the next; the extraction may leave a few returns by a
    dock's edge out). Which wall is the right face follows from the side of the apex frame
    its outer end lies on, not from the scan order (the seam of a turn). The pose is
    :func:`fit_apex`'s, moved to the reference point (:func:`reference_pose`).

    :param segments: the scan's segments
    :param corners: the scan's corners (their segment indices point into ``segments``)
    :param shape: the dock
    :return: the candidates, best fitting first (usually none or one)
    """
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
    best = int(np.argmin(chi2))
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
