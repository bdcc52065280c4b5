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
  one wall): the prior joins the fit as one more measurement, so the estimate along what the
  landmarks miss is the prior's, with the prior's grown covariance;
- **prior**: too few landmarks in one of the scans: the step is the prior with its covariance;
- **reinitialized**: landmarks on both sides, but no consistent association (a kidnap, a wrong
  association, a scene that changed): the step is the prior with the reinitialization's wide
  covariance, the velocity is forgotten, and the next scan is matched against this one.

The prior is the constant velocity of the last good step, or a step handed in per scan with its
covariance (:class:`Prior`: wheel odometry). A handed-in prior is independent of the
landmarks: it gates the hypothesis search and joins every fit by its information; a step the
landmarks fix and the prior contradicts rejects it (docs/odometry.md#wheel-odometry-as-the-prior).

All units SI: m, rad; covariances in m^2, m rad, rad^2. No ROS. These numpy steps are the
specification; the pairs' steps, the hypothesis search and the fit have a compiled twin (numba,
``core/numba_core/odometry.py``) that runs whenever the compiled core serves
(:func:`wctls_ros.core.runtime.compiled_kernels`; docs/odometry.md#time-per-scan).
"""

from dataclasses import dataclass, replace
from functools import lru_cache
import math
from typing import Any, List, Optional, Tuple

import numpy as np

from .frames import finite_only, Landmarks, overlapping, rotation, wrap_angle
from .local_map import fit_sensitivity, LocalMap, noise_covariance
from ..core import runtime

STATUSES = ('tracking', 'degenerate', 'prior', 'reinitialized')
# Where a step's prior came from: the constant velocity of the last good step, or handed in.
PRIOR_SOURCES = ('constant_velocity', 'wheel')
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
# A handed-in prior whose gate associates fewer than ENOUGH_SHARE of the landmarks is rejected
# when a search outside its gate associates this many times as many.
REJECTING_SHARE = 2.0
# The hypotheses are drawn from pairs of at most this many corners and as many lines of each scan,
# the best known: the pairs of pairs grow as the fourth power of the landmarks (at 32, 496 pairs
# of one scan against 992 of the other, per kind). No recording of data/ has more than 24.
PAIR_LANDMARKS = 32
# A refined hypothesis this far from the prior (its chi-square, 3 dof at 99.9 %) counts one
# associated landmark less: to win outside the prior's gate it must associate one more.
PRIOR_PAIR_CHI2 = 16.27
# Where :func:`_arrays` keeps a Landmarks object's arrays for the compiled twins.
_ARRAYS = '_compiled_arrays'


def _typed(values, shape: Tuple[int, ...]) -> np.ndarray:
    """
    Return values as the compiled twins were compiled for: contiguous, writable float64.

    numba compiles a function again for another layout or a read-only array (a message's
    buffer), seconds on the scan that meets it.
    """
    array = np.ascontiguousarray(values, dtype=float).reshape(shape)
    return array if array.flags.writeable else array.copy()


def _arrays(landmarks: Landmarks) -> Tuple[np.ndarray, ...]:
    """
    Return a scan's landmarks as the compiled twins take them (:func:`_typed`).

    Prepared once per Landmarks object and kept in its ``__dict__`` (as
    :func:`functools.cached_property` keeps its values; the dataclass is frozen, its fields
    untouched): a scan is matched against its keyframe on many scans, and each scan's search
    and fits take its arrays several times.
    """
    arrays = landmarks.__dict__.get(_ARRAYS)
    if arrays is None:
        arrays = (_typed(landmarks.corner_xy, (-1, 2)), _typed(landmarks.corner_cov, (-1, 2, 2)),
                  _typed(landmarks.line, (-1, 2)), _typed(landmarks.line_cov, (-1, 2, 2)),
                  _typed(landmarks.line_ends, (-1, 2, 2)))
        landmarks.__dict__[_ARRAYS] = arrays
    return arrays


@lru_cache(maxsize=256)
def _drawn(seed: int, count: int, size: int) -> np.ndarray:
    """
    Return the seeded draw of ``size`` of ``count`` hypotheses, without replacement.

    A generator seeded anew draws the same indices for the same counts: they are drawn once
    (read-only) and looked up on the scans after.
    """
    drawn = np.random.default_rng(seed).choice(count, size, replace=False)
    drawn.setflags(write=False)
    return drawn


def _pair_rows(pairs) -> np.ndarray:
    """Return (previous, current) pairs as the compiled twins take them, shape (K, 2)."""
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def _pair_list(rows: np.ndarray) -> List[Tuple[int, int]]:
    """Return a compiled twin's pairs (K, 2) as the numpy steps give them."""
    return [(int(p), int(c)) for p, c in rows.tolist()]


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
    :ivar map_memory_scans: match each scan against a local map of the landmarks seen in the
        last this many scans, fused (:mod:`.local_map`; the keyframes are then unused); 0 (the
        default: on the recordings of data/ the map did not beat the keyframe): no map
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
    map_memory_scans: int = 0
    seed: int = 0


@dataclass(frozen=True)
class Prior:
    """
    A step between two scans from a source other than the landmarks (wheel odometry).

    Independent of the landmarks, with its own covariance: it seeds and gates the hypothesis
    search and joins the fit by its information (docs/odometry.md#wheel-odometry-as-the-prior).

    :ivar step: the current scan's pose in the previous scan's frame, the laser's (dx m, dy m,
        dyaw rad), shape (3,)
    :ivar covariance: its covariance, shape (3, 3), positive definite
    :raises ValueError: on a step or covariance that is not finite, or a covariance that is not
        symmetric positive definite
    """

    step: np.ndarray
    covariance: np.ndarray

    def __post_init__(self):
        step = np.asarray(self.step, dtype=float).reshape(-1)
        covariance = np.asarray(self.covariance, dtype=float)
        if step.shape != (3,) or covariance.shape != (3, 3):
            raise ValueError(f'a prior is a step of 3 values and a 3x3 covariance, got shapes '
                             f'{step.shape} and {covariance.shape}')
        if not (np.isfinite(step).all() and np.isfinite(covariance).all()):
            raise ValueError('a prior must be finite')
        if not np.allclose(covariance, covariance.T, rtol=1e-9, atol=1e-15):
            raise ValueError('a prior covariance must be symmetric')
        try:
            np.linalg.cholesky(covariance)
        except np.linalg.LinAlgError:
            raise ValueError('a prior covariance must be positive definite') from None
        object.__setattr__(self, 'step', step)
        object.__setattr__(self, 'covariance', 0.5 * (covariance + covariance.T))


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
    :ivar prior_source: the prior the estimate took (one of PRIOR_SOURCES): a hypothesis, the
        step where the landmarks say nothing, and with 'wheel' one more measurement of the fit
    :ivar prior_rejected: a prior handed in that the landmarks contradict (the estimate is
        theirs, with the constant-velocity prior where they leave a direction free)
    :ivar prior_gain: d step / d prior step, shape (3, 3), where a handed-in prior joined the
        fit ((I + P^-1)^-1 P^-1), else None: what the step owes the prior, for its covariance
        with what the prior came from
    :ivar pairs: the fit's (corner pairs, line pairs), each (previous index, current index)
    """

    step: np.ndarray
    covariance: np.ndarray
    status: str
    corners: int = 0
    lines: int = 0
    chi2: float = math.nan
    prior_source: str = PRIOR_SOURCES[0]
    prior_rejected: bool = False
    prior_gain: Optional[np.ndarray] = None
    pairs: Tuple[Tuple[Tuple[int, int], ...], Tuple[Tuple[int, int], ...]] = ((), ())


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
    :ivar prior_source: as in :class:`StepEstimate`
    :ivar prior_rejected: as in :class:`StepEstimate`
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
    prior_source: str = PRIOR_SOURCES[0]
    prior_rejected: bool = False


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """
    Return the SE(2) composition a (+) b: b given in a's frame, expressed in a's parent.

    :param a: (x m, y m, yaw rad)
    :param b: (x m, y m, yaw rad)
    :return: shape (3,)
    """
    cos, sin = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + cos * b[0] - sin * b[1], a[1] + sin * b[0] + cos * b[1],
                     wrap_angle(a[2] + b[2])])


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
    out = np.empty(matrix.shape)
    with np.errstate(divide='ignore', invalid='ignore'):
        out[..., 0, 0] = d / det
        out[..., 0, 1] = -b / det
        out[..., 1, 0] = -c / det
        out[..., 1, 1] = a / det
    out[~np.isfinite(out)] = np.inf
    return out


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


def corner_line_hypotheses(previous: Landmarks, current: Landmarks) -> np.ndarray:
    """
    Return the steps that a corner and a line seen in both scans allow.

    A rigid motion keeps a corner's signed distance from a line, d = p . n - r: a corner and a
    line of the previous scan and of the current one are a pair when their distances agree
    within the 99 % gate of their variances, n^T C_p n + g^T C_line g with g = (p . n_perp,
    -1). The line's normals give the rotation (never flipped, as in :func:`line_hypotheses`),
    the corner the translation, t = p - R q (docs/odometry.md#hypotheses). Where the walls
    are parallel (a corridor), only such a pair fixes the motion along them.

    :param previous: the previous scan's landmarks
    :param current: the current scan's landmarks
    :return: steps (dx m, dy m, dyaw rad), shape (H, 3)
    """
    if not all(len(s.corner_xy) and len(s.line) for s in (previous, current)):
        return np.zeros((0, 3))

    def distances(landmarks):
        xy, angle = landmarks.corner_xy[:, None], landmarks.line[None, :, 0]
        normal = np.stack([np.cos(angle), np.sin(angle)], -1)
        lever = -xy[..., 0] * normal[..., 1] + xy[..., 1] * normal[..., 0]
        distance = (xy * normal).sum(-1) - landmarks.line[None, :, 1]
        cov, line_cov = landmarks.corner_cov[:, None], landmarks.line_cov[None]
        var = (np.einsum('...i,...ij,...j->...', normal, cov, normal) + lever ** 2
               * line_cov[..., 0, 0] - 2.0 * lever * line_cov[..., 0, 1] + line_cov[..., 1, 1])
        return distance.ravel(), var.ravel()

    d_prev, v_prev = distances(previous)
    d_cur, v_cur = distances(current)
    p, c = np.nonzero((d_prev[:, None] - d_cur[None, :]) ** 2
                      <= CHI2_1DOF_99 * (v_prev[:, None] + v_cur[None, :]))
    corner_p, line_p = np.divmod(p, len(previous.line))
    corner_c, line_c = np.divmod(c, len(current.line))
    yaw = wrap_angle(previous.line[line_p, 0] - current.line[line_c, 0])
    cos, sin = np.cos(yaw), np.sin(yaw)
    q = current.corner_xy[corner_c]
    moved = np.column_stack([cos * q[:, 0] - sin * q[:, 1], sin * q[:, 0] + cos * q[:, 1]])
    return np.column_stack([previous.corner_xy[corner_p] - moved, yaw])


def _quadratic_2x2(error_0, error_1, s00, s01, s10, s11):
    """
    Return e^T S^-1 e of 2-vectors and 2x2 matrices given by their components (any one shape).

    The closed form of the inverse, elementwise: one pass over arrays of any shape, with no
    (..., 2, 2) arrays built. A matrix that is not positive definite gives inf (outside any
    gate).
    """
    det = s00 * s11 - s01 * s10
    form = s11 * error_0 * error_0 - (s01 + s10) * error_0 * error_1 + s00 * error_1 * error_1
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(det > 0.0, form / det, np.inf)


def _corner_chi2(previous: Landmarks, current: Landmarks, steps: np.ndarray,
                 search: bool = False) -> np.ndarray:
    """
    Return the squared Mahalanobis distances of every corner pair under each step, (H, P, C).

    The error p - (R q + t) and its covariance C_p + R C_q R^T (+ the search's slack), by
    components: the (H, C) parts of the moved corners once, broadcast over the P previous ones.
    """
    cos, sin = np.cos(steps[:, 2:3]), np.sin(steps[:, 2:3])
    x, y = current.corner_xy[:, 0], current.corner_xy[:, 1]
    moved_x = steps[:, :1] + cos * x - sin * y
    moved_y = steps[:, 1:2] + sin * x + cos * y
    error_x = previous.corner_xy[None, :, None, 0] - moved_x[:, None, :]
    error_y = previous.corner_xy[None, :, None, 1] - moved_y[:, None, :]
    cov = current.corner_cov
    # R C, then (R C) R^T, each (H, C).
    rc00, rc01 = cos * cov[:, 0, 0] - sin * cov[:, 1, 0], cos * cov[:, 0, 1] - sin * cov[:, 1, 1]
    rc10, rc11 = sin * cov[:, 0, 0] + cos * cov[:, 1, 0], sin * cov[:, 0, 1] + cos * cov[:, 1, 1]
    slack = SEARCH_SLACK_M ** 2 if search else 0.0
    prev = previous.corner_cov[None, :, None]
    return _quadratic_2x2(
        error_x, error_y,
        prev[..., 0, 0] + (rc00 * cos - rc01 * sin + slack)[:, None],
        prev[..., 0, 1] + (rc00 * sin + rc01 * cos)[:, None],
        prev[..., 1, 0] + (rc10 * cos - rc11 * sin)[:, None],
        prev[..., 1, 1] + (rc10 * sin + rc11 * cos + slack)[:, None])


def _line_chi2(previous: Landmarks, current: Landmarks, steps: np.ndarray,
               search: bool = False) -> np.ndarray:
    """
    Return the squared Mahalanobis distances of every line pair under each step, (H, P, C).

    The current line moved into the previous frame is (angle + dyaw, r + t . n), n its moved
    normal, with covariance J C J^T, J = [[1, 0], [t . n_perp, 1]] (as :func:`.frames.to_world`
    with an exact pose); its normal is not flipped (:func:`line_hypotheses`). A pair inside the
    99 % gate whose segments do not overlap along the line is inf: two pieces of one infinite
    line metres apart are not one landmark. Values above the gate are left as they are (the
    overlap, the costly part, is tested only where it decides).
    """
    angle = current.line[None, :, 0] + steps[:, 2:3]
    cos, sin = np.cos(angle), np.sin(angle)
    lever = -steps[:, :1] * sin + steps[:, 1:2] * cos
    radius = current.line[None, :, 1] + steps[:, :1] * cos + steps[:, 1:2] * sin
    error_angle = wrap_angle(angle[:, None, :] - previous.line[None, :, None, 0])
    error_radius = radius[:, None, :] - previous.line[None, :, None, 1]
    cov = current.line_cov
    # J C, then (J C) J^T, each (H, C).
    jc10 = lever * cov[:, 0, 0] + cov[:, 1, 0]
    jc11 = lever * cov[:, 0, 1] + cov[:, 1, 1]
    slack_rad, slack_m = (SEARCH_SLACK_RAD ** 2, SEARCH_SLACK_M ** 2) if search else (0.0, 0.0)
    prev = previous.line_cov[None, :, None]
    chi2 = _quadratic_2x2(
        error_angle, error_radius,
        prev[..., 0, 0] + (cov[:, 0, 0] + slack_rad)[None, None],
        prev[..., 0, 1] + (cov[:, 0, 0] * lever + cov[:, 0, 1])[:, None],
        prev[..., 1, 0] + jc10[:, None],
        prev[..., 1, 1] + (jc10 * lever + jc11 + slack_m)[:, None])
    h, p, c = np.nonzero(chi2 <= CHI2_2DOF_99)
    if len(h):
        # Each moved segment that has a pair in the gate, against every previous segment.
        rows, row = np.unique(h * len(current.line) + c, return_inverse=True)
        hypothesis, segment = np.divmod(rows, len(current.line))
        step = steps[hypothesis]
        cos_h, sin_h = np.cos(step[:, 2:]), np.sin(step[:, 2:])
        x, y = current.line_ends[segment, :, 0], current.line_ends[segment, :, 1]
        moved = np.stack([step[:, :1] + cos_h * x - sin_h * y,
                          step[:, 1:2] + sin_h * x + cos_h * y], -1)
        shared = overlapping(moved, previous.line_ends)[row.ravel(), p]
        chi2[h[~shared], p[~shared], c[~shared]] = np.inf
    return chi2


def _best_known(landmarks: Landmarks) -> Landmarks:
    """
    Return the PAIR_LANDMARKS best-known corners and lines of a scan, for the hypotheses.

    Corners by the trace of their covariance, lines by their angle's variance (a hypothesis takes
    its rotation from the angles); the corners' walls are left out (-1), the hypotheses do not
    use them.
    """
    if len(landmarks.corner_xy) <= PAIR_LANDMARKS and len(landmarks.line) <= PAIR_LANDMARKS:
        return landmarks
    corners = np.sort(np.argsort(np.trace(landmarks.corner_cov, axis1=1, axis2=2),
                                 kind='stable')[:PAIR_LANDMARKS])
    lines = np.sort(np.argsort(landmarks.line_cov[:, 0, 0], kind='stable')[:PAIR_LANDMARKS])
    return Landmarks(landmarks.corner_xy[corners], landmarks.corner_cov[corners],
                     np.full((len(corners), 2), -1), landmarks.line[lines],
                     landmarks.line_cov[lines], landmarks.line_ends[lines])


def _search_chi2(previous: Landmarks, current: Landmarks, steps: np.ndarray):
    """Return the corner and the line pairs' chi2 in the search's gate, (H, P, C) each or None."""
    return (_corner_chi2(previous, current, steps, True)
            if len(previous.corner_xy) and len(current.corner_xy) else None,
            _line_chi2(previous, current, steps, True)
            if len(previous.line) and len(current.line) else None)


def score_hypotheses(chi2s, count: int) -> np.ndarray:
    """
    Return how many current landmarks each step brings inside the 99 % gate of one previous.

    :param chi2s: the corner and the line pairs' chi2 in the search's gate under each step,
        :func:`_search_chi2`
    :param count: the steps, H
    :return: per step, the landmarks in the gate, with the fraction of their summed chi2 below
        1 subtracted so that equal counts rank by their fit, shape (H,)
    """
    total = np.zeros(count)
    for chi2 in chi2s:
        if chi2 is None:
            continue
        best = np.min(chi2, axis=1)
        inside = best <= CHI2_2DOF_99
        total += inside.sum(axis=1) - np.where(inside, best, 0.0).sum(axis=1) / (
            CHI2_2DOF_99 * (1.0 + inside.sum(axis=1)))
    return total


def _one_to_one(chi2: Optional[np.ndarray]) -> Tuple[List[Tuple[int, int]], float]:
    """
    Return (previous, current) pairs inside the 99 % gate, best first, each landmark once.

    :param chi2: the pairs' chi2, shape (P, C), or None (no pairs)
    :return: (the pairs, the sum of their chi2)
    """
    if chi2 is None:
        return [], 0.0
    pairs = np.argwhere(chi2 <= CHI2_2DOF_99)
    values = chi2[pairs[:, 0], pairs[:, 1]]
    order = np.argsort(values, kind='stable')
    taken_p, taken_c, out, total = set(), set(), [], 0.0
    for (p, c), value in zip(pairs[order].tolist(), values[order].tolist()):
        if p not in taken_p and c not in taken_c:
            taken_p.add(p)
            taken_c.add(c)
            out.append((p, c))
            total += value
    return out, total


def _associate(previous: Landmarks, current: Landmarks, step: np.ndarray, search: bool):
    """Return :func:`associate`'s corner and line pairs and the sum of their chi2."""
    steps = np.asarray(step, dtype=float)[None]
    corners, corner_chi2 = _one_to_one(
        _corner_chi2(previous, current, steps, search)[0]
        if len(previous.corner_xy) and len(current.corner_xy) else None)
    lines, line_chi2 = _one_to_one(_line_chi2(previous, current, steps, search)[0]
                                   if len(previous.line) and len(current.line) else None)
    return corners, lines, corner_chi2 + line_chi2


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
    corners, lines, _ = _associate(previous, current, step, search)
    return corners, lines


@dataclass(frozen=True)
class _Pairs:
    """
    The associated landmarks' values, gathered once for a fit, each with its covariance.

    Corners: p of the previous scan, q of the current one, shape (Kc, 2); lines: (angle rad,
    radius m) of the previous and of the current scan, shape (Kl, 2).
    """

    corner_p: np.ndarray
    corner_p_cov: np.ndarray
    corner_q: np.ndarray
    corner_q_cov: np.ndarray
    line_p: np.ndarray
    line_p_cov: np.ndarray
    line_c: np.ndarray
    line_c_cov: np.ndarray


def _gather(previous: Landmarks, current: Landmarks, corners, lines) -> _Pairs:
    """Return the values of the pairs (previous index, current index) for :func:`_residuals`."""
    cp, cc = (np.array(corners, dtype=np.intp).reshape(-1, 2).T)
    lp, lc = (np.array(lines, dtype=np.intp).reshape(-1, 2).T)
    return _Pairs(previous.corner_xy[cp], previous.corner_cov[cp], current.corner_xy[cc],
                  current.corner_cov[cc], previous.line[lp], previous.line_cov[lp],
                  current.line[lc], current.line_cov[lc])


def _residuals(pairs: _Pairs, step: np.ndarray):
    """Return :func:`residuals` of gathered pairs."""
    corners, lines = len(pairs.corner_p), len(pairs.line_p)
    error = np.empty((corners + lines, 2))
    jac = np.zeros((corners + lines, 2, 3))
    cov = np.empty((corners + lines, 2, 2))
    cos, sin = math.cos(step[2]), math.sin(step[2])
    if corners:
        q = pairs.corner_q
        rot = rotation(step[2])
        error[:corners] = pairs.corner_p - (q @ rot.T + step[:2])
        jac[:corners, 0, 0] = jac[:corners, 1, 1] = -1.0
        jac[:corners, 0, 2] = sin * q[:, 0] + cos * q[:, 1]
        jac[:corners, 1, 2] = -cos * q[:, 0] + sin * q[:, 1]
        cov[:corners] = pairs.corner_p_cov + rot @ pairs.corner_q_cov @ rot.T
    if lines:
        angle = pairs.line_c[:, 0] + step[2]
        cos_n, sin_n = np.cos(angle), np.sin(angle)
        lever = -step[0] * sin_n + step[1] * cos_n
        error[corners:, 0] = wrap_angle(angle - pairs.line_p[:, 0])
        error[corners:, 1] = (pairs.line_c[:, 1] + step[0] * cos_n + step[1] * sin_n
                              - pairs.line_p[:, 1])
        jac[corners:, 0, 2] = 1.0
        jac[corners:, 1, 0] = cos_n
        jac[corners:, 1, 1] = sin_n
        jac[corners:, 1, 2] = lever
        # The moved line's covariance J C J^T, J = [[1, 0], [lever, 1]] (see _line_chi2).
        moved = np.zeros((lines, 2, 2))
        moved[:, 0, 0] = moved[:, 1, 1] = 1.0
        moved[:, 1, 0] = lever
        cov[corners:] = pairs.line_p_cov + moved @ pairs.line_c_cov @ moved.transpose(0, 2, 1)
    return error, jac, cov


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
    return _residuals(_gather(previous, current, corners, lines),
                      np.asarray(step, dtype=float))


def _normal_equations(pairs: _Pairs, step: np.ndarray):
    """Return the information J^T S^-1 J (3, 3), the gradient J^T S^-1 e (3,), e and S^-1."""
    error, jac, cov = _residuals(pairs, step)
    weight = _inverse_2x2(cov)
    return (np.einsum('kia,kij,kjb->ab', jac, weight, jac),
            np.einsum('kia,kij,kj->a', jac, weight, error), error, weight)


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
    pairs = _gather(previous, current, corners, lines)
    prior_information = np.linalg.inv(prior[1]) if prior is not None else np.zeros((3, 3))
    for _ in range(FIT_ITERATIONS):
        information, gradient, _, _ = _normal_equations(pairs, step)
        if prior is not None:
            difference = step - prior[0]
            difference[2] = wrap_angle(difference[2])
            gradient = gradient + prior_information @ difference
        try:
            update = -np.linalg.solve(information + prior_information, gradient)
        except np.linalg.LinAlgError:
            break
        if not np.isfinite(update).all():
            break
        step = step + update
        step[2] = wrap_angle(step[2])
        if np.abs(update).max() < 1e-6:
            break
    information, _, error, weight = _normal_equations(pairs, step)
    return step, information, float(np.einsum('ki,kij,kj->', error, weight, error))


def _fit(kernels: Any, previous: Landmarks, current: Landmarks, start: np.ndarray, corners,
         lines, prior: Optional[Tuple[np.ndarray, np.ndarray]] = None):
    """Return :func:`fit`, by its compiled twin where ``kernels`` (``compiled_kernels``)."""
    if kernels is None:
        return fit(previous, current, start, corners, lines, prior)
    corner_xy, corner_cov, line, line_cov, _ = _arrays(previous)
    current_xy, current_cov, current_line, current_line_cov, _ = _arrays(current)
    step, information, chi2 = kernels.fit(
        corner_xy, corner_cov, line, line_cov, current_xy, current_cov, current_line,
        current_line_cov, _pair_rows(corners), _pair_rows(lines),
        _typed(start, (3,)).copy(), np.zeros(3) if prior is None else _typed(prior[0], (3,)),
        np.zeros((3, 3)) if prior is None else np.linalg.inv(prior[1]), prior is not None)
    return step, information, float(chi2)


def _chi2(previous: Landmarks, current: Landmarks, step: np.ndarray, corners, lines) -> float:
    """Return the chi-square of the pairs' residuals at a step."""
    _, _, error, weight = _normal_equations(_gather(previous, current, corners, lines),
                                            np.asarray(step, dtype=float))
    return float(np.einsum('ki,kij,kj->', error, weight, error))


def _refine(previous: Landmarks, current: Landmarks, start: np.ndarray, chi2s, index: int,
            prior: Optional[Tuple[np.ndarray, np.ndarray]] = None):
    """
    Return a hypothesis refined: associated, fitted and associated again (twice), and the chi2.

    The first association is in the search's gate, whose chi2 the scoring computed for every
    hypothesis (``chi2s`` of :func:`_search_chi2`, ``index`` the start's). The pairs each later
    association returns lie inside the unwidened gate at the step of that association: no pair
    is left to prune, and their chi2 is the sum the association took. With a prior (step,
    covariance) the fits take it as a measurement: pairs that leave a direction free (two
    parallel walls) then do not send the step astray along it.
    """
    step = np.asarray(start, dtype=float)
    corners, _ = _one_to_one(None if chi2s[0] is None else chi2s[0][index])
    lines, _ = _one_to_one(None if chi2s[1] is None else chi2s[1][index])
    chi2 = math.nan
    for _ in range(2):
        if len(corners) + len(lines) < 2:
            break
        step, _, _ = fit(previous, current, step, corners, lines, prior)
        corners, lines, chi2 = _associate(previous, current, step, False)
    if math.isnan(chi2):
        # Not fitted: the pairs of the widened gate, their chi2 in the unwidened one.
        chi2 = _chi2(previous, current, step, corners, lines)
    return step, (corners, lines), chi2


def is_degenerate(information: np.ndarray, config: OdometryConfig) -> bool:
    """
    Return whether the landmarks leave some direction of the step poorly known.

    In units of the thresholds, D = diag(sigma_m, sigma_m, sigma_rad), the scaled information
    D I D must have every eigenvalue >= 1: every direction known to better than one threshold.

    :param information: the landmarks' information, shape (3, 3)
    :param config: the thresholds
    :return: True when degenerate
    """
    scale = np.array([config.degenerate_sigma_m, config.degenerate_sigma_m,
                      config.degenerate_sigma_rad])
    # D I D by elements, (D_ii I_ij) D_jj: what the products by a diagonal D give.
    scaled = scale[:, None] * information * scale
    if not np.isfinite(scaled).all():
        return True
    return bool(np.linalg.eigvalsh(0.5 * (scaled + scaled.T))[0] < 1.0)


def _search(previous: Landmarks, current: Landmarks, steps: np.ndarray, prior_step: np.ndarray,
            prior_covariance: np.ndarray, config: OdometryConfig, fused: bool = False,
            kernels: Any = None):
    """
    Return the best association of the hypotheses: (its step, corner pairs, line pairs).

    The best-scored hypotheses, one per motion, are each refined (with ``fused``, by fits that
    take the prior as a measurement); the one with most pairs less its chi-square from the
    prior over PRIOR_PAIR_CHI2 wins, on a tie the one nearer the prior by its covariance
    (docs/odometry.md#hypotheses). With ``kernels``
    (:func:`wctls_ros.core.runtime.compiled_kernels`) all of it but the prior's word in the
    scores is one call of the compiled twin.
    """
    fewest = min(len(previous.corner_xy) + len(previous.line),
                 len(current.corner_xy) + len(current.line))
    # Scored as they are ranked once refined: the landmarks less the prior's word.
    away = steps - prior_step
    away[:, 2] = wrap_angle(away[:, 2])
    prior_information = np.linalg.inv(prior_covariance)
    prior_term = np.einsum('hi,ij,hj->h', away, prior_information, away) / PRIOR_PAIR_CHI2
    if kernels is not None:
        step, corners, lines = kernels.search(
            *_arrays(previous), *_arrays(current), _typed(steps, (-1, 3)), prior_term,
            _typed(prior_step, (3,)), prior_information, bool(fused), float(config.max_step_m),
            int(fewest))
        return step, _pair_list(corners), _pair_list(lines)
    chi2s = _search_chi2(previous, current, steps)
    scores = score_hypotheses(chi2s, len(steps)) - prior_term
    best_rank, best_chi2 = -math.inf, math.inf
    step, corners, lines = prior_step, [], []
    # The best few hypotheses are each refined: a hypothesis from a short baseline can lie
    # outside the gate of landmarks that a fit from it brings in.
    starts: List[np.ndarray] = []
    for index in np.argsort(-scores, kind='stable'):
        start = steps[index]
        if len(starts) == REFINED_HYPOTHESES:
            break
        # Hypotheses of one motion from different pairs: refining one of them is enough.
        if any(abs(start[0] - other[0]) + abs(start[1] - other[1]) < SEARCH_SLACK_M
               and abs(wrap_angle(start[2] - other[2])) < SEARCH_SLACK_RAD
               for other in starts):
            continue
        starts.append(start)
        refined, pairs, fit_chi2 = _refine(previous, current, start, chi2s, index,
                                           (prior_step, prior_covariance) if fused else None)
        count = len(pairs[0]) + len(pairs[1]) if math.hypot(
            refined[0], refined[1]) <= config.max_step_m else 0
        # Ranked by the landmarks associated less the prior's word (PRIOR_PAIR_CHI2); equal
        # (a symmetric room): the motion the prior expects, then the better fit.
        away = refined - prior_step
        away[2] = wrap_angle(away[2])
        prior_chi2 = float(away @ np.linalg.solve(prior_covariance, away))
        chi2 = fit_chi2 + prior_chi2 if count else math.inf
        rank = count - prior_chi2 / PRIOR_PAIR_CHI2 if count else -1.0
        if rank > best_rank or (rank == best_rank and chi2 < best_chi2):
            best_rank, best_chi2 = rank, chi2
            step, (corners, lines) = refined, pairs
        if best_rank >= ENOUGH_SHARE * fewest:
            break                       # nothing else could rank much higher
    return step, corners, lines


def _hypotheses(previous: Landmarks, current: Landmarks, config: OdometryConfig,
                extra: np.ndarray, keep=None, kernels: Any = None) -> np.ndarray:
    """
    Return the steps to score: ``extra`` first, then those of the landmark pairs.

    The pairs' steps beyond ``max_step_m`` are dropped, and those ``keep`` (a function of the
    steps, shape (H, 3) -> (H,) bool) refuses; at most ``max_hypotheses`` of them, drawn at
    random (seeded). With ``kernels`` (:func:`wctls_ros.core.runtime.compiled_kernels`) the
    pairs' steps are one call of the compiled twin.
    """
    search_prev, search_cur = _best_known(previous), _best_known(current)
    if kernels is not None:
        steps = kernels.hypotheses(*_arrays(search_prev)[:4], *_arrays(search_cur)[:4])
    else:
        steps = np.concatenate([corner_hypotheses(search_prev, search_cur),
                                line_hypotheses(search_prev, search_cur),
                                corner_line_hypotheses(search_prev, search_cur)])
    # The rows kept, then taken once (take: a row index's copy without fancy indexing's cost).
    kept = np.flatnonzero(np.hypot(steps[:, 0], steps[:, 1]) <= config.max_step_m)
    if keep is not None and len(kept):
        kept = kept[keep(steps.take(kept, axis=0))]
    if len(kept) > config.max_hypotheses:
        kept = kept[_drawn(config.seed, len(kept), config.max_hypotheses)]
    return np.concatenate([np.asarray(extra, dtype=float).reshape(-1, 3),
                           steps.take(kept, axis=0)])


def prior_innovation(information: np.ndarray, step: np.ndarray, prior: Prior,
                     config: OdometryConfig = OdometryConfig()) -> float:
    """
    Return how far a prior lies from what the landmarks say, as a chi-square (3 dof at most).

    At the fused step x* (the landmarks' fit with the prior), r = x* - x_prior and W = P^-1:
    d^T (C_landmarks + P)^-1 d = r^T W r + (W r)^T I^+ (W r), I the landmarks' information
    and I^+ its pseudo-inverse (the directions the landmarks leave free count nothing); exact
    for a linear fit (docs/odometry.md#wheel-odometry-as-the-prior).

    :param information: the landmarks' information at the fused step, shape (3, 3)
    :param step: the fused step (dx m, dy m, dyaw rad)
    :param prior: the prior
    :param config: its degenerate thresholds scale the pseudo-inverse
    :return: the chi-square
    """
    away = np.asarray(step, dtype=float) - prior.step
    away[2] = wrap_angle(away[2])
    weighted = np.linalg.solve(prior.covariance, away)
    scale = np.diag([config.degenerate_sigma_m, config.degenerate_sigma_m,
                     config.degenerate_sigma_rad])
    scaled = scale @ information @ scale
    inverse_information = scale @ np.linalg.pinv(0.5 * (scaled + scaled.T), rcond=1e-9,
                                                 hermitian=True) @ scale
    return float(away @ weighted + weighted @ inverse_information @ weighted)


def _with_prior(previous: Landmarks, current: Landmarks, prior: Prior, config: OdometryConfig,
                kernels: Any = None) -> Tuple[Optional[StepEstimate], bool]:
    """
    Return the step from the hypotheses inside a handed-in prior's gate, fused with the prior.

    :return: (the estimate, or None when no association inside the gate is consistent with
        the landmarks and the prior; whether landmarks associated there contradict the prior)
    """
    gate = chi2_quantile(config.consistency_probability, 3)
    # The search's slack widens the prior's gate as it widens the landmarks'.
    spread = np.linalg.inv(prior.covariance + np.diag(
        [SEARCH_SLACK_M ** 2, SEARCH_SLACK_M ** 2, SEARCH_SLACK_RAD ** 2]))

    def inside(steps: np.ndarray) -> np.ndarray:
        away = steps - prior.step
        away[:, 2] = wrap_angle(away[:, 2])
        return np.einsum('hi,ij,hj->h', away, spread, away) <= gate

    steps = _hypotheses(previous, current, config, prior.step, inside, kernels)
    zero = np.zeros((1, 3))
    if inside(zero)[0]:
        steps = np.concatenate([steps[:1], zero, steps[1:]])
    step, corners, lines = _search(previous, current, steps, prior.step, prior.covariance,
                                   config, True, kernels)
    matched = len(corners) + len(lines)
    if not matched:
        return None, False
    step, information, chi2 = _fit(kernels, previous, current, step, corners, lines,
                                   (prior.step, prior.covariance))
    # The statuses are the landmarks' (their information at the fused step), as without it.
    degenerate = matched < config.min_matches or is_degenerate(information, config)
    if not np.isfinite(step).all() or not np.isfinite(information).all():
        return None, False
    prior_information = np.linalg.inv(prior.covariance)
    away = step - prior.step
    away[2] = wrap_angle(away[2])
    chi2 += float(away @ prior_information @ away)
    dof = 2 * matched
    if (chi2 > chi2_quantile(config.consistency_probability, dof)
            or prior_innovation(information, step, prior, config) > gate):
        return None, True
    covariance = np.linalg.inv(information + prior_information)
    covariance = 0.5 * (covariance + covariance.T)
    if not np.isfinite(covariance).all():
        return None, False
    return StepEstimate(step, covariance, 'degenerate' if degenerate else 'tracking',
                        len(corners), len(lines), chi2 / dof, PRIOR_SOURCES[1],
                        prior_gain=covariance @ prior_information,
                        pairs=(tuple(corners), tuple(lines))), False


def estimate_step(previous: Landmarks, current: Landmarks, prior_step: np.ndarray,
                  prior_covariance: np.ndarray, config: OdometryConfig = OdometryConfig(),
                  wheel: Optional[Prior] = None, compiled: Optional[bool] = None) -> StepEstimate:
    """
    Return the motion between two scans from their landmarks.

    With a prior handed in (``wheel``): the hypotheses inside its gate are searched first and
    the fit takes it as one more measurement; when nothing there is consistent, or what is
    associates fewer than ENOUGH_SHARE of the landmarks, the search also runs as without it,
    and a step the landmarks then find (associating REJECTING_SHARE times as many, in the
    second case) rejects it (docs/odometry.md#wheel-odometry-as-the-prior).

    :param previous: the previous scan's landmarks (its frame is the step's)
    :param current: the current scan's landmarks
    :param prior_step: the constant-velocity prediction (dx m, dy m, dyaw rad): a hypothesis
        among the others and the estimate where the landmarks say nothing
    :param prior_covariance: its covariance, shape (3, 3)
    :param config: the settings
    :param wheel: a step from another source with its covariance (wheel odometry), or None
    :param compiled: None: the search and the fits by their compiled twin while the compiled
        core serves, else by the numpy steps; True: the compiled twin; False: the numpy steps
        (:func:`wctls_ros.core.runtime.compiled_kernels`)
    :return: the estimate (never NaN)
    :raises wctls_ros.core.CoreUnavailable: with ``compiled`` True, when numba cannot give the
        compiled core
    """
    kernels = runtime.compiled_kernels('odometry', compiled)
    prior_step = np.asarray(prior_step, dtype=float)
    prior_covariance = np.asarray(prior_covariance, dtype=float)
    fewest = min(len(previous.corner_xy) + len(previous.line),
                 len(current.corner_xy) + len(current.line))
    if wheel is None:
        return _estimate(previous, current, prior_step, prior_covariance, config,
                         kernels=kernels)
    if fewest < 2:
        return StepEstimate(wheel.step.copy(), wheel.covariance.copy(), 'prior',
                            prior_source=PRIOR_SOURCES[1])
    fused, contradicted = _with_prior(previous, current, wheel, config, kernels)
    matched = 0 if fused is None else fused.corners + fused.lines
    if fused is not None and matched >= ENOUGH_SHARE * fewest:
        return fused
    # Refined with the constant velocity as a measurement: two parallel walls alone then
    # still say the turn and the distance across, against which the prior is judged.
    estimate = _estimate(previous, current, prior_step, prior_covariance, config, True,
                         kernels)
    if (estimate.status in ('tracking', 'degenerate') and (fused is None or (
            estimate.corners + estimate.lines >= max(REJECTING_SHARE * matched,
                                                     config.min_matches)))) or contradicted:
        # The landmarks found a step the prior's gate left out (or one that associates far
        # more of them), or those in its gate contradict it: the prior is wrong (a wheel that
        # slipped, a robot carried).
        return replace(estimate, prior_rejected=True)
    if fused is not None:
        return fused
    # Nothing associated either way: the handed-in step, independent of the scans, stands.
    covariance = wheel.covariance.copy()
    if estimate.status == 'reinitialized':
        covariance += np.diag([config.reinit_sigma_m ** 2, config.reinit_sigma_m ** 2,
                               config.reinit_sigma_rad ** 2])
    return replace(estimate, step=wheel.step.copy(), covariance=covariance,
                   prior_source=PRIOR_SOURCES[1])


def _estimate(previous: Landmarks, current: Landmarks, prior_step: np.ndarray,
              prior_covariance: np.ndarray, config: OdometryConfig,
              fused: bool = False, kernels: Any = None) -> StepEstimate:
    """
    Return :func:`estimate_step` with the constant-velocity prior alone.

    With ``fused`` the refinements' fits take the prior as a measurement (:func:`_search`);
    with ``kernels`` the search and the fits are the compiled twin's.
    """
    landmarks_prev = len(previous.corner_xy) + len(previous.line)
    landmarks_cur = len(current.corner_xy) + len(current.line)
    if min(landmarks_prev, landmarks_cur) < 2:
        return StepEstimate(prior_step.copy(), prior_covariance.copy(), 'prior')
    steps = _hypotheses(previous, current, config,
                        np.concatenate([prior_step[None], np.zeros((1, 3))]), kernels=kernels)
    step, corners, lines = _search(previous, current, steps, prior_step, prior_covariance,
                                   config, fused, kernels)
    matched = len(corners) + len(lines)

    def reinit() -> StepEstimate:
        return StepEstimate(prior_step.copy(), np.diag(
            [config.reinit_sigma_m ** 2, config.reinit_sigma_m ** 2,
             config.reinit_sigma_rad ** 2]) + prior_covariance, 'reinitialized', len(corners),
            len(lines))

    if not matched:
        # Landmarks on both sides that nothing associates: a kidnap or another scene; a scan
        # or two of them is only too little to say.
        return reinit() if min(landmarks_prev, landmarks_cur) >= config.min_matches else (
            StepEstimate(prior_step.copy(), prior_covariance.copy(), 'prior'))
    step, information, chi2 = _fit(kernels, previous, current, step, corners, lines)
    dof = 2 * matched - 3
    status = 'tracking'
    if matched < config.min_matches or is_degenerate(information, config):
        status = 'degenerate'
        step, information, chi2 = _fit(kernels, previous, current, step, corners, lines,
                                       (prior_step, prior_covariance))
        prior_information = np.linalg.inv(prior_covariance)
        difference = step - prior_step
        difference[2] = wrap_angle(difference[2])
        chi2 += float(difference @ prior_information @ difference)
        information = information + prior_information
        dof += 3
    if not np.isfinite(step).all() or (dof > 0 and chi2 > chi2_quantile(
            config.consistency_probability, dof)):
        return reinit()
    covariance = np.linalg.inv(information)
    covariance = 0.5 * (covariance + covariance.T)
    if not np.isfinite(covariance).all():
        return reinit()
    return StepEstimate(step, covariance, status, len(corners), len(lines),
                        chi2 / dof if dof > 0 else math.nan,
                        pairs=(tuple(corners), tuple(lines)))


class Odometry:
    """
    The odometry of one sensor: a step per scan, composed into a pose in odom.

    The reference is a keyframe: a scan whose landmarks the next scans are matched against
    until the motion from it exceeds ``keyframe_m`` or ``keyframe_rad`` (or a match fails);
    with both 0, every scan is the next one's reference (scan to scan). Matched against a
    keyframe, a still sensor does not drift, and its pose covariance does not grow, scan by
    scan (docs/odometry.md#keyframes). The constant-velocity prior is the last good step per
    second times the time since, its covariance that step's grown by the prior's growth; a
    step handed in with a scan (:class:`Prior`, wheel odometry) takes its place for that scan.
    """

    def __init__(self, config: OdometryConfig = OdometryConfig(),
                 pose: Tuple[float, float, float] = (0.0, 0.0, 0.0),
                 compiled: Optional[bool] = None):
        """
        Start at a pose.

        :param config: the settings
        :param pose: the starting pose in odom (x m, y m, yaw rad), known exactly
        :param compiled: None: the compiled twin of the search and the fits on every scan the
            compiled core serves, the numpy steps on the others; True: the compiled twin
            always (the compiled core is loaded, or compiled, first); False: the numpy steps
        :raises wctls_ros.core.CoreUnavailable: with ``compiled`` True, when numba cannot give
            the compiled core
        """
        if compiled:
            runtime.compiled_kernels('odometry', True)
        self._compiled = compiled
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
        self._velocity_dt_s = 0.0
        self._map: Optional[LocalMap] = None

    def _prior(self, dt_s: float) -> Tuple[np.ndarray, np.ndarray]:
        """Return the constant-velocity step over dt and its grown covariance."""
        config = self.config
        growth = np.diag([config.prior_sigma_m ** 2, config.prior_sigma_m ** 2,
                          config.prior_sigma_rad ** 2])
        if not self._velocity_known:
            # Before a first match the velocity is unknown: a motion of any size is as likely.
            growth = growth + np.diag([config.reinit_sigma_m ** 2, config.reinit_sigma_m ** 2,
                                       config.reinit_sigma_rad ** 2])
        elif self._velocity_dt_s > 0.0:
            growth = growth * max(1.0, dt_s / self._velocity_dt_s) ** 2
        return self._velocity * dt_s, self._velocity_covariance * dt_s ** 2 + growth

    def _unmatched(self, estimate: StepEstimate, prior_step: np.ndarray) -> np.ndarray:
        """
        Return the step of a scan nothing matched: the prior's, or none beyond ``max_step_m``.

        A constant velocity held so long that it would move further than any step still tells
        the search where the motion points, but as a step it is none (a keyframed log's gap of
        25 s extrapolated to 12 m); its covariance, grown with the gap, stays. A wheel's step
        is measured, whatever its length.
        """
        if (estimate.prior_source == PRIOR_SOURCES[0]
                and math.hypot(prior_step[0], prior_step[1]) > self.config.max_step_m):
            return np.zeros(3)
        return prior_step.copy()

    def _keyframe(self, landmarks: Landmarks) -> None:
        """Make the scan just taken the reference."""
        self._reference = landmarks
        self._reference_pose = self.pose.copy()
        self._reference_covariance = self.pose_covariance.copy()
        self._last = np.zeros(3)
        self._last_covariance = np.zeros((3, 3))

    def _relative(self, step: np.ndarray,
                  covariance: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return a step from the last scan as the pose in the keyframe's frame, covariance."""
        by_last, by_step = compose_jacobians(self._last, step)
        return compose(self._last, step), (by_last @ self._last_covariance @ by_last.T
                                           + by_step @ covariance @ by_step.T)

    def _step_covariance(self, estimate: StepEstimate, wheel: Optional[Prior]) -> np.ndarray:
        """
        Return the covariance of the step from the last scan, last^-1 (+) relative.

        The last scan's pose and this match are taken as independent, except through a
        handed-in prior, last (+) wheel, that joined the fit: the match owes it
        prior_gain, so cov(relative, last) = prior_gain d(last (+) wheel)/d last C_last
        (docs/odometry.md#keyframes). Along a corridor's axis, where the step is the wheel's
        alone, the step's covariance is then the wheel's.
        """
        by_inverse, by_relative = compose_jacobians(inverse(self._last), estimate.step)
        by_last = by_inverse @ inverse_jacobian(self._last)
        covariance = (by_last @ self._last_covariance @ by_last.T
                      + by_relative @ estimate.covariance @ by_relative.T)
        if estimate.prior_gain is not None and wheel is not None:
            through, _ = compose_jacobians(self._last, wheel.step)
            cross = by_relative @ estimate.prior_gain @ through @ self._last_covariance \
                @ by_last.T
            covariance = covariance + cross + cross.T
        return covariance

    def _velocity_from(self, status: str, step: np.ndarray, covariance: np.ndarray,
                       dt_s: float) -> None:
        """Take a matched step as the constant velocity; a reinitialization forgets it."""
        if status in ('tracking', 'degenerate') and dt_s > 0.0:
            self._velocity = step / dt_s
            self._velocity_dt_s = dt_s
            self._velocity_covariance = covariance / dt_s ** 2
            self._velocity_known = True
        elif status == 'reinitialized':
            self._velocity = np.zeros(3)
            self._velocity_covariance = np.zeros((3, 3))
            self._velocity_known = False

    def _update_map(self, stamp_s: float, dt_s: float, landmarks: Landmarks,
                    wheel: Optional[Prior], prior_step: np.ndarray,
                    prior_covariance: np.ndarray) -> OdometryUpdate:
        """
        Take one scan against the local map (docs/odometry.md#local-map).

        The scan is matched against the map moved into the last scan's frame; the step's and
        the pose's covariances come from the map's joint covariance (:class:`.LocalMap`).
        """
        memory = self.config.map_memory_scans
        if self._map is None:
            self._map = LocalMap(self.pose, self.pose_covariance, landmarks, memory)
            estimate = StepEstimate(np.zeros(3), np.zeros((3, 3)), 'prior')
            step, step_covariance = np.zeros(3), np.zeros((3, 3))
        else:
            frame, frame_jacobian = self._map.in_frame()
            estimate = estimate_step(frame, landmarks, prior_step, prior_covariance,
                                     self.config, wheel, self._compiled)
            step = estimate.step
            if estimate.status == 'reinitialized':
                # Nothing consistent associates: the map starts again from this scan.
                step, step_covariance = self._unmatched(estimate, step), estimate.covariance
                by_pose, by_step = compose_jacobians(self.pose, step)
                pose = compose(self.pose, step)
                covariance = (by_pose @ self.pose_covariance @ by_pose.T
                              + by_step @ step_covariance @ by_step.T)
                self._map = LocalMap(pose, covariance, landmarks, memory)
            else:
                by_map, by_noise, noise = _match_sensitivity(frame, landmarks, estimate,
                                                             prior_covariance, wheel)
                pairs = estimate.pairs if estimate.status != 'prior' else ((), ())
                moved = (compose(self._map.pose, step),
                         *compose_jacobians(self._map.pose, step))
                step_covariance = self._map.update(moved, by_map, by_noise, noise, landmarks,
                                                   pairs[0], pairs[1], frame, frame_jacobian)
        self.pose = self._map.pose.copy()
        self.pose_covariance = self._map.covariance[:3, :3].copy()
        self._velocity_from(estimate.status, step, step_covariance, dt_s)
        self._stamp_s = stamp_s if math.isfinite(stamp_s) else self._stamp_s
        return OdometryUpdate(stamp_s, dt_s, step.copy(), step_covariance.copy(),
                              self.pose.copy(), self.pose_covariance.copy(), estimate.status,
                              estimate.corners, estimate.lines, estimate.prior_source,
                              estimate.prior_rejected)

    def update(self, stamp_s: float, landmarks: Landmarks,
               wheel: Optional[Prior] = None) -> OdometryUpdate:
        """
        Take one scan's landmarks.

        :param stamp_s: the scan's stamp, s (a stamp not after the previous one: a step of 0 s)
        :param landmarks: its landmarks in the sensor frame (those with a value that is not
            finite are left out)
        :param wheel: the step since the previous scan from another source (wheel odometry),
            in the laser's frame, with its covariance; None: the constant-velocity prior
        :return: the odometry of this scan
        """
        landmarks = finite_only(landmarks)
        dt_s = stamp_s - self._stamp_s if math.isfinite(self._stamp_s) else 0.0
        dt_s = dt_s if math.isfinite(dt_s) and dt_s > 0.0 else 0.0
        prior_step, prior_covariance = self._prior(dt_s)
        if self.config.map_memory_scans > 0:
            return self._update_map(stamp_s, dt_s, landmarks, wheel, prior_step,
                                    prior_covariance)
        if self._reference is None:
            estimate = StepEstimate(np.zeros(3), np.zeros((3, 3)), 'prior')
        else:
            # The priors of the scan's pose in the keyframe's frame: the last one's, one step
            # on.
            prior_relative, prior_relative_covariance = self._relative(prior_step,
                                                                       prior_covariance)
            wheel_relative = None if wheel is None else Prior(
                *self._relative(wheel.step, wheel.covariance))
            estimate = estimate_step(self._reference, landmarks, prior_relative,
                                     prior_relative_covariance, self.config, wheel_relative,
                                     self._compiled)
        if estimate.prior_source == PRIOR_SOURCES[1] and wheel is not None:
            prior_step = wheel.step
        matched = estimate.status in ('tracking', 'degenerate')
        if not matched:
            # The prior or a reinitialization: its covariance is the step's own.
            step = self._unmatched(estimate, prior_step)
            step_covariance = estimate.covariance.copy()
            if estimate.status == 'prior' and self._reference is None:
                step_covariance = np.zeros((3, 3))
            by_pose, by_step = compose_jacobians(self.pose, step)
            self.pose = compose(self.pose, step)
            self.pose_covariance = (by_pose @ self.pose_covariance @ by_pose.T
                                    + by_step @ step_covariance @ by_step.T)
        else:
            # The step from the last scan: last^-1 (+) relative.
            step = compose(inverse(self._last), estimate.step)
            step_covariance = self._step_covariance(estimate, wheel)
            by_pose, by_step = compose_jacobians(self._reference_pose, estimate.step)
            self.pose = compose(self._reference_pose, estimate.step)
            self.pose_covariance = (by_pose @ self._reference_covariance @ by_pose.T
                                    + by_step @ estimate.covariance @ by_step.T)
        self._velocity_from(estimate.status, step, step_covariance, dt_s)
        far = (math.hypot(estimate.step[0], estimate.step[1]) > self.config.keyframe_m
               or abs(estimate.step[2]) > self.config.keyframe_rad)
        if not matched or far:
            self._keyframe(landmarks)
        else:
            self._last, self._last_covariance = estimate.step, estimate.covariance
        self._stamp_s = stamp_s if math.isfinite(stamp_s) else self._stamp_s
        return OdometryUpdate(stamp_s, dt_s, step, 0.5 * (step_covariance + step_covariance.T),
                              self.pose.copy(), self.pose_covariance.copy(), estimate.status,
                              estimate.corners, estimate.lines, estimate.prior_source,
                              estimate.prior_rejected)


def _match_sensitivity(frame: Landmarks, current: Landmarks, estimate: StepEstimate,
                       prior_covariance: np.ndarray, wheel: Optional[Prior]):
    """
    Return a match's step as a function of the map, the scan's noise and the prior, to first order.

    :return: (d step / d(the map's moved values), shape (3, 2 n); d step / d(the scan's
        corners, its lines, the prior), shape (3, 2 C + 2 L + 3); that noise's covariance)
    """
    by_map = np.zeros((3, 2 * (len(frame.corner_xy) + len(frame.line))))
    by_noise = np.zeros((3, 2 * (len(current.corner_xy) + len(current.line)) + 3))
    # The prior that joined the fit: the wheel's, or the constant velocity's where degenerate.
    prior = (wheel.covariance if estimate.prior_source == PRIOR_SOURCES[1] and wheel is not None
             else prior_covariance)
    if estimate.status not in ('tracking', 'degenerate'):
        # The step is the prior's, with the estimate's covariance.
        by_noise[:, -3:] = np.eye(3)
        return by_map, by_noise, noise_covariance(current, estimate.covariance)
    corners, lines = estimate.pairs
    step = estimate.step
    error, jacobian, cov = _residuals(_gather(frame, current, corners, lines), step)
    weight = _inverse_2x2(cov)
    information = np.einsum('kia,kij,kjb->ab', jacobian, weight, jacobian)
    joined = estimate.prior_gain is not None or estimate.status == 'degenerate'
    by_residual, by_prior = fit_sensitivity(jacobian, weight, information,
                                            np.linalg.inv(prior) if joined else None)
    turn = rotation(step[2])
    count = len(frame.corner_xy)
    for k, (m, c) in enumerate(corners):
        # r = p - (R q + t): dr/dp = I, dr/dq = -R.
        by_map[:, 2 * m:2 * m + 2] += by_residual[k]
        by_noise[:, 2 * c:2 * c + 2] -= by_residual[k] @ turn
    offset = len(corners)
    first_line = 2 * len(current.corner_xy)
    for k, (m, c) in enumerate(lines):
        # r = (alpha_c + dyaw, r_c + t . n) - (alpha_p, r_p): dr/dp = -I, dr/dc = [[1, 0],
        # [t . n_perp, 1]].
        angle = current.line[c, 0] + step[2]
        moved = np.array([[1.0, 0.0],
                          [-step[0] * math.sin(angle) + step[1] * math.cos(angle), 1.0]])
        by_map[:, 2 * (count + m):2 * (count + m) + 2] -= by_residual[offset + k]
        by_noise[:, first_line + 2 * c:first_line + 2 * c + 2] += by_residual[offset + k] @ moved
    by_noise[:, -3:] = by_prior
    return by_map, by_noise, noise_covariance(current, prior)


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
                          update.corners, update.lines, update.prior_source,
                          update.prior_rejected)
