# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Odometry from the features: the motion between two scans from their corners and line landmarks.

Per scan the estimator yields the step from the previous scan in the previous scan's frame
(dx_m, dy_m, dyaw_rad) with its 3x3 covariance, the pose in odom with its 3x3 covariance, and a
status (docs/odometry.md gives the equations):

- **tracking**: the landmarks were associated without a prior (a hypothesis search over pairs of
  corners and pairs of lines, gated on the invariants' covariances, each hypothesis scored by
  the landmarks it brings inside their gate), then the step is the weighted least-squares fit
  of the associated corners (point to point) and lines (line to line in normal form), its
  covariance the inverse of the fit's information (J^T S^-1 J)^-1 from the landmarks'
  covariances;
- **degenerate**: the landmarks constrain the step, but not along every direction (a corridor,
  one wall): the constant-velocity prior joins the fit as one more measurement, so the estimate
  along what the landmarks miss is the prior's, with the prior's grown covariance;
- **prior**: too few landmarks in one of the scans: the step is the constant-velocity prior with
  its grown covariance;
- **reinitialized**: landmarks on both sides, but no consistent association (a kidnap, a wrong
  association, a scene that changed): the step is the prior with the reinitialization's wide
  covariance, the velocity is forgotten, and the next scan is matched against this one.

All units SI: m, rad; covariances in m^2, m rad, rad^2. Pure numpy, no ROS.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Tuple

import numpy as np

from .frames import finite_only, Landmarks, overlapping, rotation, wrap_angle

STATUSES = ('tracking', 'degenerate', 'prior', 'reinitialized')
# 99 % points of the chi-square distribution with 1 and 2 degrees of freedom.
CHI2_1DOF_99 = 6.635
CHI2_2DOF_99 = 9.210
# The pairs a hypothesis is drawn from: corners at least this far apart, lines at least this far
# from parallel (a shorter baseline leaves the rotation to the corners' noise).
MIN_PAIR_DISTANCE_M = 0.3
MIN_PAIR_ANGLE_RAD = math.radians(20.0)
# The fit's Gauss-Newton iterations (it starts from the best hypothesis, within a gate).
FIT_ITERATIONS = 6
# The best-scored hypotheses refined by a fit each; the one with most landmarks associated wins.
REFINED_HYPOTHESES = 6
# The search's gates are wider by these (a hypothesis from two landmarks is itself uncertain).
SEARCH_SLACK_M = 0.05
SEARCH_SLACK_RAD = math.radians(2.0)
# A refined hypothesis that associates this share of the smaller scan's landmarks ends the search.
ENOUGH_SHARE = 0.9


@dataclass(frozen=True)
class OdometryConfig:
    """
    The estimator's settings.

    :ivar max_hypotheses: hypotheses scored per scan at most (drawn at random, seeded, from the
        gated pairs)
    :ivar min_matches: landmarks associated at least for a fit (fewer: prior or reinitialized)
    :ivar degenerate_sigma_m: a step whose features leave a std above this along a direction of
        translation (or above degenerate_sigma_rad in rotation) is degenerate, m
    :ivar degenerate_sigma_rad: the same in rotation, rad
    :ivar prior_sigma_m: the constant-velocity prior's growth per step, each axis, m
    :ivar prior_sigma_rad: its growth in yaw per step, rad
    :ivar reinit_sigma_m: the std of a reinitialized step, each axis, m
    :ivar reinit_sigma_rad: its std in yaw, rad
    :ivar consistency_probability: the fit's chi-square must lie below this quantile for its
        degrees of freedom (above: inconsistent, reinitialized)
    :ivar max_step_m: the largest step between two scans, m (hypotheses beyond it are not
        scored: a repeated structure shifted by its period is not a step)
    :ivar keyframe_m: match the scans against a keyframe until they lie this far from it, m
        (0 and keyframe_rad 0: scan to scan)
    :ivar keyframe_rad: ... or turned this far from it, rad
    :ivar seed: seed of the hypothesis draw
    """

    max_hypotheses: int = 200
    min_matches: int = 3
    degenerate_sigma_m: float = 0.1
    degenerate_sigma_rad: float = math.radians(3.0)
    prior_sigma_m: float = 0.1
    prior_sigma_rad: float = math.radians(10.0)
    reinit_sigma_m: float = 1.0
    reinit_sigma_rad: float = math.radians(60.0)
    consistency_probability: float = 0.999
    max_step_m: float = 2.0
    keyframe_m: float = 0.1
    keyframe_rad: float = math.radians(3.0)
    seed: int = 0


@dataclass(frozen=True)
class StepEstimate:
    """
    The motion between two scans.

    :ivar step: the current scan's pose in the previous scan's frame (dx m, dy m, dyaw rad),
        shape (3,)
    :ivar covariance: its covariance, shape (3, 3)
    :ivar status: one of STATUSES
    :ivar corners: corners associated
    :ivar lines: line landmarks associated
    :ivar chi2: the fit's chi-square over its degrees of freedom (NaN without a fit)
    """

    step: np.ndarray
    covariance: np.ndarray
    status: str
    corners: int = 0
    lines: int = 0
    chi2: float = math.nan


@dataclass(frozen=True)
class OdometryUpdate:
    """
    One scan's odometry.

    :ivar stamp_s: the scan's stamp, s
    :ivar dt_s: the time since the previous scan, s (0 for the first)
    :ivar step: as in :class:`StepEstimate`
    :ivar step_covariance: its covariance, shape (3, 3)
    :ivar pose: the pose in odom (x m, y m, yaw rad), shape (3,)
    :ivar pose_covariance: its covariance, shape (3, 3)
    :ivar status: one of STATUSES
    :ivar corners: corners associated
    :ivar lines: line landmarks associated
    """

    stamp_s: float
    dt_s: float
    step: np.ndarray
    step_covariance: np.ndarray
    pose: np.ndarray
    pose_covariance: np.ndarray
    status: str
    corners: int
    lines: int


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """
    Return the SE(2) composition a (+) b: b given in a's frame, expressed in a's parent.

    :param a: (x m, y m, yaw rad)
    :param b: (x m, y m, yaw rad)
    :return: shape (3,)
    """
    cos, sin = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + cos * b[0] - sin * b[1], a[1] + sin * b[0] + cos * b[1],
                     float(wrap_angle(a[2] + b[2]))])


def compose_jacobians(a: np.ndarray, b: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return d(a (+) b)/da and d(a (+) b)/db (docs/odometry.md#composition).

    :param a: (x m, y m, yaw rad)
    :param b: (x m, y m, yaw rad)
    :return: two 3x3 matrices
    """
    cos, sin = math.cos(a[2]), math.sin(a[2])
    by_a = np.array([[1.0, 0.0, -sin * b[0] - cos * b[1]],
                     [0.0, 1.0, cos * b[0] - sin * b[1]],
                     [0.0, 0.0, 1.0]])
    by_b = np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])
    return by_a, by_b


def inverse(a: np.ndarray) -> np.ndarray:
    """
    Return the SE(2) inverse of a pose.

    :param a: (x m, y m, yaw rad)
    :return: shape (3,)
    """
    cos, sin = math.cos(a[2]), math.sin(a[2])
    return np.array([-cos * a[0] - sin * a[1], sin * a[0] - cos * a[1], -a[2]])


def inverse_jacobian(a: np.ndarray) -> np.ndarray:
    """
    Return d(a^-1)/da.

    :param a: (x m, y m, yaw rad)
    :return: 3x3
    """
    cos, sin = math.cos(a[2]), math.sin(a[2])
    return np.array([[-cos, -sin, sin * a[0] - cos * a[1]],
                     [sin, -cos, cos * a[0] + sin * a[1]],
                     [0.0, 0.0, -1.0]])


def change_frame(step: np.ndarray, covariance: np.ndarray,
                 mount: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return a step of the laser as the step of the robot that carries it.

    The robot's step is M (+) s (+) M^-1 for the laser's mount M on the robot (laser pose in
    the robot frame); its covariance J C J^T with J = d/ds, exact to first order.

    :param step: the laser's step (dx m, dy m, dyaw rad)
    :param covariance: its covariance, shape (3, 3)
    :param mount: the laser's pose in the robot frame (x m, y m, yaw rad)
    :return: (the robot's step, its covariance)
    """
    mount = np.asarray(mount, dtype=float)
    first = compose(mount, step)
    _, by_step = compose_jacobians(mount, step)
    by_first, _ = compose_jacobians(first, inverse(mount))
    jacobian = by_first @ by_step
    return compose(first, inverse(mount)), jacobian @ covariance @ jacobian.T


def chi2_quantile(probability: float, dof: int) -> float:
    """
    Return the chi-square quantile (Wilson-Hilferty; within 2 % for dof >= 3 at 0.999).

    :param probability: in (0, 1)
    :param dof: degrees of freedom (>= 1)
    :return: the quantile
    """
    # The normal quantile by the rational approximation of Abramowitz and Stegun, 26.2.23.
    tail = min(probability, 1.0 - probability)
    t = math.sqrt(-2.0 * math.log(tail))
    z = t - (2.515517 + 0.802853 * t + 0.010328 * t * t) / (
        1.0 + 1.432788 * t + 0.189269 * t * t + 0.001308 * t ** 3)
    z = z if probability > 0.5 else -z
    k = 2.0 / (9.0 * dof)
    return dof * (1.0 - k + z * math.sqrt(k)) ** 3


def _inverse_2x2(matrix: np.ndarray) -> np.ndarray:
    """Return the inverses of (..., 2, 2) matrices (singular ones: inf on the diagonal)."""
    a, b, c, d = matrix[..., 0, 0], matrix[..., 0, 1], matrix[..., 1, 0], matrix[..., 1, 1]
    det = a * d - b * c
    with np.errstate(divide='ignore', invalid='ignore'):
        out = np.stack([np.stack([d, -b], -1), np.stack([-c, a], -1)], -2) / det[..., None, None]
    return np.where(np.isfinite(out), out, np.inf)


def _pair_indices(count: int) -> Tuple[np.ndarray, np.ndarray]:
    """Return the unordered pairs (i < j) of count items."""
    i, j = np.triu_indices(count, 1)
    return i.astype(np.intp), j.astype(np.intp)


def _ordered_pairs(count: int) -> Tuple[np.ndarray, np.ndarray]:
    """Return the ordered pairs (i != j) of count items."""
    i, j = np.nonzero(~np.eye(count, dtype=bool))
    return i.astype(np.intp), j.astype(np.intp)


def corner_hypotheses(previous: Landmarks, current: Landmarks) -> np.ndarray:
    """
    Return the steps that pairs of corners seen in both scans allow.

    Two corners i, j of the previous scan and k, l of the current one are a pair when their
    distances agree within the 99 % gate of their variances (a rigid motion keeps the
    distance; docs/odometry.md#hypotheses); the pair gives the rotation of the direction i -> j
    from k -> l and the translation of the midpoints.

    :param previous: the previous scan's landmarks
    :param current: the current scan's landmarks
    :return: steps (dx m, dy m, dyaw rad), shape (H, 3)
    """
    if len(previous.corner_xy) < 2 or len(current.corner_xy) < 2:
        return np.zeros((0, 3))
    i, j = _pair_indices(len(previous.corner_xy))
    k, m = _ordered_pairs(len(current.corner_xy))

    def distances(landmarks, a, b):
        delta = landmarks.corner_xy[b] - landmarks.corner_xy[a]
        length = np.hypot(delta[:, 0], delta[:, 1])
        unit = delta / np.maximum(length, 1e-12)[:, None]
        var = np.einsum('ni,nij,nj->n', unit, landmarks.corner_cov[a] + landmarks.corner_cov[b],
                        unit)
        return delta, length, var

    d_prev, l_prev, v_prev = distances(previous, i, j)
    d_cur, l_cur, v_cur = distances(current, k, m)
    keep_prev = l_prev >= MIN_PAIR_DISTANCE_M
    keep_cur = l_cur >= MIN_PAIR_DISTANCE_M
    gated = ((l_prev[:, None] - l_cur[None, :]) ** 2
             <= CHI2_1DOF_99 * (v_prev[:, None] + v_cur[None, :]))
    gated &= keep_prev[:, None] & keep_cur[None, :]
    p, c = np.nonzero(gated)
    yaw = wrap_angle(np.arctan2(d_prev[p, 1], d_prev[p, 0]) - np.arctan2(d_cur[c, 1], d_cur[c, 0]))
    mid_prev = 0.5 * (previous.corner_xy[i[p]] + previous.corner_xy[j[p]])
    mid_cur = 0.5 * (current.corner_xy[k[c]] + current.corner_xy[m[c]])
    cos, sin = np.cos(yaw), np.sin(yaw)
    moved = np.column_stack([cos * mid_cur[:, 0] - sin * mid_cur[:, 1],
                             sin * mid_cur[:, 0] + cos * mid_cur[:, 1]])
    return np.column_stack([mid_prev - moved, yaw])


def line_hypotheses(previous: Landmarks, current: Landmarks) -> np.ndarray:
    """
    Return the steps that pairs of lines seen in both scans allow.

    A line's normal points from the sensor to the wall, and the sensor stays on the side of a
    wall it sees (it cannot cross the wall; the other face is another landmark): the normals
    of one line agree in both frames up to the rotation, never flipped. Two lines of each
    scan, not close to parallel, are a pair when the angle between their normals agrees
    within the 99 % gate; the rotation maps the first normal onto the previous scan's, and the
    radii give the translation, t . n_p = r_p - r_c for both lines
    (docs/odometry.md#hypotheses).

    :param previous: the previous scan's landmarks
    :param current: the current scan's landmarks
    :return: steps (dx m, dy m, dyaw rad), shape (H, 3)
    """
    if len(previous.line) < 2 or len(current.line) < 2:
        return np.zeros((0, 3))
    i, j = _pair_indices(len(previous.line))
    k, m = _ordered_pairs(len(current.line))

    def between(landmarks, a, b):
        angle = wrap_angle(landmarks.line[b, 0] - landmarks.line[a, 0])
        return angle, landmarks.line_cov[a, 0, 0] + landmarks.line_cov[b, 0, 0]

    a_prev, v_prev = between(previous, i, j)
    a_cur, v_cur = between(current, k, m)
    keep_prev = np.abs(np.sin(a_prev)) >= math.sin(MIN_PAIR_ANGLE_RAD)
    keep_cur = np.abs(np.sin(a_cur)) >= math.sin(MIN_PAIR_ANGLE_RAD)
    difference = wrap_angle(a_prev[:, None] - a_cur[None, :])
    gated = difference ** 2 <= CHI2_1DOF_99 * (v_prev[:, None] + v_cur[None, :])
    gated &= keep_prev[:, None] & keep_cur[None, :]
    p, c = np.nonzero(gated)
    yaw = wrap_angle(previous.line[i[p], 0] - current.line[k[c], 0])
    a1, b1 = np.cos(previous.line[i[p], 0]), np.sin(previous.line[i[p], 0])
    a2, b2 = np.cos(previous.line[j[p], 0]), np.sin(previous.line[j[p], 0])
    r1 = previous.line[i[p], 1] - current.line[k[c], 1]
    r2 = previous.line[j[p], 1] - current.line[m[c], 1]
    det = a1 * b2 - a2 * b1
    out = np.column_stack([(r1 * b2 - r2 * b1) / det, (a1 * r2 - a2 * r1) / det, yaw])
    return out[np.isfinite(out).all(axis=1)]


def _moved_corners(current: Landmarks, steps: np.ndarray) -> np.ndarray:
    """Return the current corners moved into the previous frame by each step, (H, C, 2)."""
    cos, sin = np.cos(steps[:, 2])[:, None], np.sin(steps[:, 2])[:, None]
    x, y = current.corner_xy[None, :, 0], current.corner_xy[None, :, 1]
    return np.stack([steps[:, :1] + cos * x - sin * y, steps[:, 1:2] + sin * x + cos * y], -1)


def _corner_chi2(previous: Landmarks, current: Landmarks, steps: np.ndarray,
                 search: bool = False) -> np.ndarray:
    """Return the squared Mahalanobis distances of every corner pair under each step, (H, P, C)."""
    moved = _moved_corners(current, steps)
    error = previous.corner_xy[None, :, None, :] - moved[:, None, :, :]
    rot = np.stack([np.stack([np.cos(steps[:, 2]), -np.sin(steps[:, 2])], -1),
                    np.stack([np.sin(steps[:, 2]), np.cos(steps[:, 2])], -1)], -2)
    cur_cov = rot[:, None] @ current.corner_cov[None] @ rot[:, None].transpose(0, 1, 3, 2)
    innovation = previous.corner_cov[None, :, None] + cur_cov[:, None]
    if search:
        innovation = innovation + SEARCH_SLACK_M ** 2 * np.eye(2)
    return np.einsum('hpci,hpcij,hpcj->hpc', error, _inverse_2x2(innovation), error)


def _line_errors(previous: Landmarks, current: Landmarks, steps: np.ndarray):
    """
    Return every line pair's error under each step and its covariance.

    The current line moved into the previous frame is (angle + dyaw, r + t . n), n its moved
    normal, with covariance J C J^T, J = [[1, 0], [t . n_perp, 1]] (as :func:`.frames.to_world`
    with an exact pose); its normal is not flipped (:func:`line_hypotheses`).

    :return: (error (H, P, C, 2) of (angle rad, radius m), innovation covariance
        (H, P, C, 2, 2))
    """
    angle = current.line[None, :, 0] + steps[:, 2:3]
    lever = -steps[:, :1] * np.sin(angle) + steps[:, 1:2] * np.cos(angle)
    radius = current.line[None, :, 1] + steps[:, :1] * np.cos(angle) + steps[:, 1:2] * np.sin(
        angle)
    jacobian = np.zeros(angle.shape + (2, 2))
    jacobian[..., 0, 0] = 1.0
    jacobian[..., 1, 0] = lever
    jacobian[..., 1, 1] = 1.0
    cur_cov = jacobian @ current.line_cov[None] @ jacobian.transpose(0, 1, 3, 2)
    error = np.stack([wrap_angle(angle[:, None, :] - previous.line[None, :, None, 0]),
                      radius[:, None, :] - previous.line[None, :, None, 1]], -1)
    return error, previous.line_cov[None, :, None] + cur_cov[:, None]


def _line_chi2(previous: Landmarks, current: Landmarks, steps: np.ndarray,
               search: bool = False) -> np.ndarray:
    """Return the squared Mahalanobis distances of every line pair under each step, (H, P, C)."""
    error, innovation = _line_errors(previous, current, steps)
    if search:
        innovation = innovation + np.diag([SEARCH_SLACK_RAD ** 2, SEARCH_SLACK_M ** 2])
    chi2 = np.einsum('hpci,hpcij,hpcj->hpc', error, _inverse_2x2(innovation), error)
    # Two pieces of one infinite line metres apart are not one landmark: the moved segment
    # must overlap the previous one along its line.
    ends = _moved_corners(Landmarks(current.line_ends.reshape(-1, 2), current.corner_cov[:0],
                                    current.corner_lines[:0], current.line, current.line_cov,
                                    current.line_ends), steps)
    shared = overlapping(ends.reshape(-1, 2, 2), previous.line_ends).reshape(
        len(steps), len(current.line), len(previous.line))
    return np.where(shared.transpose(0, 2, 1), chi2, np.inf)


def score_hypotheses(previous: Landmarks, current: Landmarks, steps: np.ndarray) -> np.ndarray:
    """
    Return how many current landmarks each step brings inside the 99 % gate of one previous.

    :param previous: the previous scan's landmarks
    :param current: the current scan's landmarks
    :param steps: candidate steps, shape (H, 3)
    :return: per step, the landmarks in the gate, with the fraction of their summed chi2 below
        1 subtracted so that equal counts rank by their fit, shape (H,)
    """
    total = np.zeros(len(steps))
    for chi2 in (_corner_chi2(previous, current, steps, True) if len(previous.corner_xy) and len(
            current.corner_xy) else None,
                 _line_chi2(previous, current, steps, True) if len(previous.line) and len(
            current.line) else None):
        if chi2 is None:
            continue
        best = np.min(chi2, axis=1)
        inside = best <= CHI2_2DOF_99
        total += inside.sum(axis=1) - np.where(inside, best, 0.0).sum(axis=1) / (
            CHI2_2DOF_99 * (1.0 + inside.sum(axis=1)))
    return total


def _one_to_one(chi2: np.ndarray, gate: float) -> List[Tuple[int, int]]:
    """Return (previous, current) pairs inside the gate, best first, each landmark once."""
    pairs = np.argwhere(chi2 <= gate)
    order = np.argsort(chi2[pairs[:, 0], pairs[:, 1]], kind='stable')
    taken_p, taken_c, out = set(), set(), []
    for p, c in pairs[order]:
        if p not in taken_p and c not in taken_c:
            taken_p.add(int(p))
            taken_c.add(int(c))
            out.append((int(p), int(c)))
    return out


def associate(previous: Landmarks, current: Landmarks, step: np.ndarray,
              search: bool = False):
    """
    Return the corner and line pairs inside the gate under one step, one to one.

    :param previous: the previous scan's landmarks
    :param current: the current scan's landmarks
    :param step: the step (dx m, dy m, dyaw rad)
    :param search: widen the gate by the search's slack (a hypothesis, not yet a fit)
    :return: (corner pairs, line pairs), each a list of (previous index, current index)
    """
    steps = np.asarray(step, dtype=float)[None]
    corners = (_one_to_one(_corner_chi2(previous, current, steps, search)[0], CHI2_2DOF_99)
               if len(previous.corner_xy) and len(current.corner_xy) else [])
    lines = (_one_to_one(_line_chi2(previous, current, steps, search)[0], CHI2_2DOF_99)
             if len(previous.line) and len(current.line) else [])
    return corners, lines


def residuals(previous: Landmarks, current: Landmarks, step: np.ndarray, corners, lines):
    """
    Return the fit's residuals, their Jacobians by the step and their covariances.

    Corners: e = p_prev - (R q_cur + t), S = C_prev + R C_cur R^T. Lines: the current line
    moved into the previous frame, (angle + dyaw, r + t . n), minus the previous line;
    S = C_prev + J C_cur J^T (docs/odometry.md#the-fit).

    :param previous: the previous scan's landmarks
    :param current: the current scan's landmarks
    :param step: (dx m, dy m, dyaw rad)
    :param corners: corner pairs (previous, current)
    :param lines: line pairs (previous, current)
    :return: (residuals (K, 2), Jacobians (K, 2, 3), covariances (K, 2, 2)), corners first
    """
    step = np.asarray(step, dtype=float)
    out_e, out_j, out_s = [], [], []
    if corners:
        p, c = np.array(corners).T
        rot = rotation(step[2])
        q = current.corner_xy[c]
        out_e.append(previous.corner_xy[p] - (q @ rot.T + step[:2]))
        jac = np.zeros((len(p), 2, 3))
        jac[:, :, :2] = -np.eye(2)
        jac[:, 0, 2] = math.sin(step[2]) * q[:, 0] + math.cos(step[2]) * q[:, 1]
        jac[:, 1, 2] = -math.cos(step[2]) * q[:, 0] + math.sin(step[2]) * q[:, 1]
        out_j.append(jac)
        out_s.append(previous.corner_cov[p] + rot @ current.corner_cov[c] @ rot.T)
    if lines:
        p, c = np.array(lines).T
        angle = current.line[c, 0] + step[2]
        cos, sin = np.cos(angle), np.sin(angle)
        lever = -step[0] * sin + step[1] * cos
        out_e.append(np.column_stack([wrap_angle(angle - previous.line[p, 0]),
                                      current.line[c, 1] + step[0] * cos + step[1] * sin
                                      - previous.line[p, 1]]))
        jac = np.zeros((len(p), 2, 3))
        jac[:, 0, 2] = 1.0
        jac[:, 1, 0] = cos
        jac[:, 1, 1] = sin
        jac[:, 1, 2] = lever
        out_j.append(jac)
        # The moved line's covariance J C J^T, J = [[1, 0], [lever, 1]] (see _line_errors).
        moved = np.zeros((len(p), 2, 2))
        moved[:, 0, 0] = 1.0
        moved[:, 1, 0] = lever
        moved[:, 1, 1] = 1.0
        out_s.append(previous.line_cov[p] + moved @ current.line_cov[c]
                     @ moved.transpose(0, 2, 1))
    if not out_e:
        return np.zeros((0, 2)), np.zeros((0, 2, 3)), np.zeros((0, 2, 2))
    return np.concatenate(out_e), np.concatenate(out_j), np.concatenate(out_s)


def fit(previous: Landmarks, current: Landmarks, start: np.ndarray, corners, lines,
        prior: Optional[Tuple[np.ndarray, np.ndarray]] = None):
    """
    Return the weighted least-squares step of associated landmarks, by Gauss-Newton.

    Minimises sum e_k^T S_k^-1 e_k (+ (x - x_prior)^T P^-1 (x - x_prior) with a prior); the
    covariance is the inverse information (sum J_k^T S_k^-1 J_k + P^-1)^-1, first order in the
    landmarks' noise (docs/odometry.md#the-fit).

    :param previous: the previous scan's landmarks
    :param current: the current scan's landmarks
    :param start: the first step (dx m, dy m, dyaw rad)
    :param corners: corner pairs (previous, current)
    :param lines: line pairs (previous, current)
    :param prior: (prior step, its covariance) or None
    :return: (step, the landmarks' information (3, 3) without the prior, chi2 of the landmarks)
    """
    step = np.asarray(start, dtype=float).copy()
    prior_information = np.linalg.inv(prior[1]) if prior is not None else np.zeros((3, 3))
    information = np.zeros((3, 3))
    for _ in range(FIT_ITERATIONS):
        error, jac, cov = residuals(previous, current, step, corners, lines)
        weight = _inverse_2x2(cov)
        information = np.einsum('kia,kij,kjb->ab', jac, weight, jac)
        gradient = np.einsum('kia,kij,kj->a', jac, weight, error)
        normal = information + prior_information
        if prior is not None:
            difference = step - prior[0]
            difference[2] = float(wrap_angle(difference[2]))
            gradient = gradient + prior_information @ difference
        try:
            update = -np.linalg.solve(normal, gradient)
        except np.linalg.LinAlgError:
            break
        if not np.isfinite(update).all():
            break
        step = step + update
        step[2] = float(wrap_angle(step[2]))
        if np.abs(update).max() < 1e-6:
            break
    error, jac, cov = residuals(previous, current, step, corners, lines)
    weight = _inverse_2x2(cov)
    information = np.einsum('kia,kij,kjb->ab', jac, weight, jac)
    chi2 = float(np.einsum('ki,kij,kj->', error, weight, error))
    return step, information, chi2


def _prune(previous: Landmarks, current: Landmarks, step: np.ndarray, corners, lines):
    """Return the pairs whose own residual lies inside the 99 % gate at the step."""
    error, _, cov = residuals(previous, current, step, corners, lines)
    chi2 = np.einsum('ki,kij,kj->k', error, _inverse_2x2(cov), error)
    inside = chi2 <= CHI2_2DOF_99
    return ([pair for pair, keep in zip(corners, inside[:len(corners)]) if keep],
            [pair for pair, keep in zip(lines, inside[len(corners):]) if keep])


def _chi2(previous: Landmarks, current: Landmarks, step: np.ndarray, corners, lines) -> float:
    """Return the chi-square of the pairs' residuals at a step."""
    error, _, cov = residuals(previous, current, step, corners, lines)
    return float(np.einsum('ki,kij,kj->', error, _inverse_2x2(cov), error))


def _refine(previous: Landmarks, current: Landmarks, start: np.ndarray):
    """Return a hypothesis refined: associated, fitted, associated again and pruned (twice)."""
    step = np.asarray(start, dtype=float)
    corners, lines = associate(previous, current, step, True)
    for _ in range(2):
        if len(corners) + len(lines) < 2:
            break
        step, _, _ = fit(previous, current, step, corners, lines)
        corners, lines = associate(previous, current, step)
        corners, lines = _prune(previous, current, step, corners, lines)
    return step, (corners, lines)


def is_degenerate(information: np.ndarray, config: OdometryConfig) -> bool:
    """
    Return whether the landmarks leave some direction of the step poorly known.

    In units of the thresholds, D = diag(sigma_m, sigma_m, sigma_rad), the scaled information
    D I D must have every eigenvalue >= 1: every direction known to better than one threshold.

    :param information: the landmarks' information, shape (3, 3)
    :param config: the thresholds
    :return: True when degenerate
    """
    scale = np.diag([config.degenerate_sigma_m, config.degenerate_sigma_m,
                     config.degenerate_sigma_rad])
    scaled = scale @ information @ scale
    if not np.isfinite(scaled).all():
        return True
    return bool(np.linalg.eigvalsh(0.5 * (scaled + scaled.T))[0] < 1.0)


def estimate_step(previous: Landmarks, current: Landmarks, prior_step: np.ndarray,
                  prior_covariance: np.ndarray,
                  config: OdometryConfig = OdometryConfig()) -> StepEstimate:
    """
    Return the motion between two scans from their landmarks.

    :param previous: the previous scan's landmarks (its frame is the step's)
    :param current: the current scan's landmarks
    :param prior_step: the constant-velocity prediction (dx m, dy m, dyaw rad): a hypothesis
        among the others and the estimate where the landmarks say nothing
    :param prior_covariance: its covariance, shape (3, 3)
    :param config: the settings
    :return: the estimate (never NaN)
    """
    prior_step = np.asarray(prior_step, dtype=float)
    prior_covariance = np.asarray(prior_covariance, dtype=float)
    landmarks_prev = len(previous.corner_xy) + len(previous.line)
    landmarks_cur = len(current.corner_xy) + len(current.line)
    if min(landmarks_prev, landmarks_cur) < 2:
        return StepEstimate(prior_step.copy(), prior_covariance.copy(), 'prior')
    steps = np.concatenate([corner_hypotheses(previous, current),
                            line_hypotheses(previous, current)])
    steps = steps[np.hypot(steps[:, 0], steps[:, 1]) <= config.max_step_m]
    if len(steps) > config.max_hypotheses:
        rng = np.random.default_rng(config.seed)
        steps = steps[rng.choice(len(steps), config.max_hypotheses, replace=False)]
    steps = np.concatenate([prior_step[None], np.zeros((1, 3)), steps])
    scores = score_hypotheses(previous, current, steps)
    best_count, best_chi2 = -1, math.inf
    step, corners, lines = prior_step, [], []
    # The best few hypotheses are each refined: a hypothesis from a short baseline can lie
    # outside the gate of landmarks that a fit from it brings in.
    starts: List[np.ndarray] = []
    for start in steps[np.argsort(-scores, kind='stable')]:
        if len(starts) == REFINED_HYPOTHESES:
            break
        # Hypotheses of one motion from different pairs: refining one of them is enough.
        if any(abs(start[0] - other[0]) + abs(start[1] - other[1]) < SEARCH_SLACK_M
               and abs(float(wrap_angle(start[2] - other[2]))) < SEARCH_SLACK_RAD
               for other in starts):
            continue
        starts.append(start)
        refined, pairs = _refine(previous, current, start)
        count = len(pairs[0]) + len(pairs[1]) if math.hypot(
            refined[0], refined[1]) <= config.max_step_m else 0
        # Equal support (a symmetric room): the motion the prior expects, then the better fit.
        away = refined - prior_step
        away[2] = float(wrap_angle(away[2]))
        chi2 = (_chi2(previous, current, refined, *pairs)
                + float(away @ np.linalg.solve(prior_covariance, away))) if count else math.inf
        if count > best_count or (count == best_count and chi2 < best_chi2):
            best_count, best_chi2 = count, chi2
            step, (corners, lines) = refined, pairs
        if best_count >= ENOUGH_SHARE * min(landmarks_prev, landmarks_cur):
            break                       # nothing else could associate much more
    matched = len(corners) + len(lines)
    reinit = StepEstimate(prior_step.copy(), np.diag(
        [config.reinit_sigma_m ** 2, config.reinit_sigma_m ** 2, config.reinit_sigma_rad ** 2])
        + prior_covariance, 'reinitialized', len(corners), len(lines))
    if not matched:
        # Landmarks on both sides that nothing associates: a kidnap or another scene; a scan
        # or two of them is only too little to say.
        return reinit if min(landmarks_prev, landmarks_cur) >= config.min_matches else (
            StepEstimate(prior_step.copy(), prior_covariance.copy(), 'prior'))
    step, information, chi2 = fit(previous, current, step, corners, lines)
    dof = 2 * matched - 3
    status = 'tracking'
    if matched < config.min_matches or is_degenerate(information, config):
        status = 'degenerate'
        step, information, chi2 = fit(previous, current, step, corners, lines,
                                      (prior_step, prior_covariance))
        prior_information = np.linalg.inv(prior_covariance)
        difference = step - prior_step
        difference[2] = float(wrap_angle(difference[2]))
        chi2 += float(difference @ prior_information @ difference)
        information = information + prior_information
        dof += 3
    if not np.isfinite(step).all() or (dof > 0 and chi2 > chi2_quantile(
            config.consistency_probability, dof)):
        return reinit
    covariance = np.linalg.inv(information)
    covariance = 0.5 * (covariance + covariance.T)
    if not np.isfinite(covariance).all():
        return reinit
    return StepEstimate(step, covariance, status, len(corners), len(lines),
                        chi2 / dof if dof > 0 else math.nan)


class Odometry:
    """
    The odometry of one sensor: a step per scan, composed into a pose in odom.

    The reference is a keyframe: a scan whose landmarks the next scans are matched against
    until the motion from it exceeds ``keyframe_m`` or ``keyframe_rad`` (or a match fails);
    with both 0, every scan is the next one's reference (scan to scan). Matched against a
    keyframe, a still sensor does not drift, and its pose covariance does not grow, scan by
    scan (docs/odometry.md#keyframes). The constant-velocity prior is the last good step per
    second times the time since, its covariance that step's grown by the prior's growth.
    """

    def __init__(self, config: OdometryConfig = OdometryConfig(),
                 pose: Tuple[float, float, float] = (0.0, 0.0, 0.0)):
        """
        Start at a pose.

        :param config: the settings
        :param pose: the starting pose in odom (x m, y m, yaw rad), known exactly
        """
        self.config = config
        self.pose = np.asarray(pose, dtype=float)
        self.pose_covariance = np.zeros((3, 3))
        self._reference: Optional[Landmarks] = None
        self._reference_pose = self.pose.copy()
        self._reference_covariance = np.zeros((3, 3))
        # The last scan's pose in the keyframe's frame, and its covariance.
        self._last = np.zeros(3)
        self._last_covariance = np.zeros((3, 3))
        self._stamp_s = math.nan
        self._velocity = np.zeros(3)            # per second
        self._velocity_covariance = np.zeros((3, 3))
        self._velocity_known = False

    def _prior(self, dt_s: float) -> Tuple[np.ndarray, np.ndarray]:
        """Return the constant-velocity step over dt and its grown covariance."""
        config = self.config
        growth = np.diag([config.prior_sigma_m ** 2, config.prior_sigma_m ** 2,
                          config.prior_sigma_rad ** 2])
        if not self._velocity_known:
            # Before a first match the velocity is unknown: a motion of any size is as likely.
            growth = growth + np.diag([config.reinit_sigma_m ** 2, config.reinit_sigma_m ** 2,
                                       config.reinit_sigma_rad ** 2])
        return self._velocity * dt_s, self._velocity_covariance * dt_s ** 2 + growth

    def _keyframe(self, landmarks: Landmarks) -> None:
        """Make the scan just taken the reference."""
        self._reference = landmarks
        self._reference_pose = self.pose.copy()
        self._reference_covariance = self.pose_covariance.copy()
        self._last = np.zeros(3)
        self._last_covariance = np.zeros((3, 3))

    def update(self, stamp_s: float, landmarks: Landmarks) -> OdometryUpdate:
        """
        Take one scan's landmarks.

        :param stamp_s: the scan's stamp, s (a stamp not after the previous one: a step of 0 s)
        :param landmarks: its landmarks in the sensor frame (those with a value that is not
            finite are left out)
        :return: the odometry of this scan
        """
        landmarks = finite_only(landmarks)
        dt_s = stamp_s - self._stamp_s if math.isfinite(self._stamp_s) else 0.0
        dt_s = dt_s if math.isfinite(dt_s) and dt_s > 0.0 else 0.0
        prior_step, prior_covariance = self._prior(dt_s)
        # The prior of the scan's pose in the keyframe's frame: the last one's, one step on.
        by_last, by_prior = compose_jacobians(self._last, prior_step)
        prior_relative = compose(self._last, prior_step)
        prior_relative_covariance = (by_last @ self._last_covariance @ by_last.T
                                     + by_prior @ prior_covariance @ by_prior.T)
        if self._reference is None:
            estimate = StepEstimate(np.zeros(3), np.zeros((3, 3)), 'prior')
        else:
            estimate = estimate_step(self._reference, landmarks, prior_relative,
                                     prior_relative_covariance, self.config)
        matched = estimate.status in ('tracking', 'degenerate')
        # The step from the last scan: last^-1 (+) relative (the two taken as independent).
        by_inverse, by_relative = compose_jacobians(inverse(self._last), estimate.step)
        by_last = by_inverse @ inverse_jacobian(self._last)
        step = compose(inverse(self._last), estimate.step)
        step_covariance = (by_last @ self._last_covariance @ by_last.T
                           + by_relative @ estimate.covariance @ by_relative.T)
        if not matched:
            # The prior or a reinitialization: its covariance is the step's own.
            step, step_covariance = prior_step.copy(), estimate.covariance.copy()
            if estimate.status == 'prior' and self._reference is None:
                step_covariance = np.zeros((3, 3))
            by_pose, by_step = compose_jacobians(self.pose, step)
            self.pose = compose(self.pose, step)
            self.pose_covariance = (by_pose @ self.pose_covariance @ by_pose.T
                                    + by_step @ step_covariance @ by_step.T)
        else:
            by_pose, by_step = compose_jacobians(self._reference_pose, estimate.step)
            self.pose = compose(self._reference_pose, estimate.step)
            self.pose_covariance = (by_pose @ self._reference_covariance @ by_pose.T
                                    + by_step @ estimate.covariance @ by_step.T)
        if matched and dt_s > 0.0:
            self._velocity = step / dt_s
            self._velocity_covariance = step_covariance / dt_s ** 2
            self._velocity_known = True
        elif estimate.status == 'reinitialized':
            self._velocity = np.zeros(3)
            self._velocity_covariance = np.zeros((3, 3))
            self._velocity_known = False
        far = (math.hypot(estimate.step[0], estimate.step[1]) > self.config.keyframe_m
               or abs(estimate.step[2]) > self.config.keyframe_rad)
        if not matched or far:
            self._keyframe(landmarks)
        else:
            self._last, self._last_covariance = estimate.step, estimate.covariance
        self._stamp_s = stamp_s if math.isfinite(stamp_s) else self._stamp_s
        return OdometryUpdate(stamp_s, dt_s, step, 0.5 * (step_covariance + step_covariance.T),
                              self.pose.copy(), self.pose_covariance.copy(), estimate.status,
                              estimate.corners, estimate.lines)


def on_robot(update: OdometryUpdate, mount: np.ndarray) -> OdometryUpdate:
    """
    Return a laser's odometry as the odometry of the robot that carries it.

    The laser's odometry starts at its mount M (the laser's pose in the robot frame, so that
    odom is the robot's first pose); the robot's pose is the laser's (+) M^-1 and its step
    M (+) s (+) M^-1 (:func:`change_frame`), covariances by the first-order Jacobians.

    :param update: the laser's odometry (started at the mount)
    :param mount: the laser's pose in the robot frame (x m, y m, yaw rad)
    :return: the robot's
    """
    mount = np.asarray(mount, dtype=float)
    by_pose, _ = compose_jacobians(update.pose, inverse(mount))
    step, step_covariance = change_frame(update.step, update.step_covariance, mount)
    return OdometryUpdate(update.stamp_s, update.dt_s, step, step_covariance,
                          compose(update.pose, inverse(mount)),
                          by_pose @ update.pose_covariance @ by_pose.T, update.status,
                          update.corners, update.lines)
