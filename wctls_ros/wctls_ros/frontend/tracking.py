# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Landmark tracks with persistent ids: corners and line landmarks gated on their covariances.

Every track lives in the **current sensor frame** (robot-centric): before each scan it is moved
by the sensor's step since the previous scan, (dx_m, dy_m, dyaw_rad) in the previous scan's
frame, with the step's 3x3 covariance Q (from TF odom -> laser, from the odometry estimator, or
from a recording's poses; :class:`Motion`). With F and G the Jacobians of the move by the
landmark and by the step (:mod:`.frames`), a track's covariance becomes F P F^T + G Q G^T.

**Association.** An observation z with covariance R and a predicted track (m, P) are
compatible when e^T (P + R)^-1 e <= chi2(2, p) (e = z - m on the gated coordinates: a corner's
position, a line's angle and distance; p = ``gate_probability``, 0.99 by default). A line also
has to overlap the stretch of wall its track has seen, as in ``score``. Where an observation has
more than one compatible track, or a track more than one observation, the cluster of those
pairs is resolved by joint compatibility (JCBB, Neira and Tardos 2001): the most pairings whose
stacked innovation passes chi2(2 n, p), its covariance with the cross terms G_i Q G_j^T that the
shared step puts between every two tracks; the search is bounded by ``max_hypotheses`` nodes
per cluster and keeps the best hypothesis found by then (its first leaf is the nearest-first
one).

**Why the fused estimates stay honest.** Every observation of one scan shares the step's error,
and every track's prediction carries it. A world-frame tracker would put the pose's error into
each observation and then fuse observations whose errors are one and the same, shrinking the
covariance as if they were independent. Here the observation is taken where it was made, in
the sensor frame, so its error is the extractor's alone; the step's error enters the track once,
in the prediction, and successive steps' errors are independent. Each track alone is then a
linear-Gaussian system with white process noise (G Q G^T) and white measurement noise (R), and
its Kalman filter is exact for its own marginal: what is left out is the correlation between
tracks, which only makes the update of one track not use the others' observations (less
precise, never overconfident). The joint test uses the one correlation that matters for the
gate, the current step's.

**Life of a track.** A new track is ``tentative``; it is ``confirmed`` after ``confirm_hits``
observations; a tentative track missed ``drop_tentative_misses`` times in a row while in view is
dropped (a transient: a person, a door, clutter), a confirmed one missed ``lose_misses`` times in
a row while in view is ``lost``, and a lost one seen again is confirmed again under its id. In
view (:class:`View`): inside the scan's bearings and range, and not behind a return nearer than
the landmark by ``occlusion_margin_m``; without a view every landmark counts as in view. A track
unseen for ``memory_scans`` scans is forgotten. Ids start at 1 and are never reused.

**Two implementations.** The numpy steps of :class:`Tracker` are the specification; compiled
twins of them (numba, ``core/numba_core/tracking.py``) take one compiled call per kind of
landmark and scan, with the same ids and estimates within 1e-9. The tracker runs the compiled
one whenever the compiled feature pipeline serves (:func:`wctls_ros.core.runtime.compiled_kernels`:
numba installed, the core loaded), the numpy one otherwise; ``Tracker(compiled=...)`` forces
either. No rclpy, and no numba import here.
"""

from dataclasses import dataclass, field
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .frames import (overlapping, relative_step, spanned, step_corners, step_lines, step_points,
                     wrap_angle)
from ..core import line_landmarks, runtime
from ..core.records import TrackRules
from ..core.rules import CONFIRMED, LOST, TENTATIVE

CORNER = 'corner'
LINE = 'line'
KINDS = (CORNER, LINE)
# A state's name by its code.
STATES = ('tentative', 'confirmed', 'lost')
# The tested share of re-observations: the 95 % gate (chi2, 2 dof).
TEST_GATE_PROBABILITY = 0.95


def chi2_quantile_even(probability: float, dof: int) -> float:
    """
    Return the chi-square quantile of an even number of degrees of freedom.

    For 2 k degrees of freedom P(chi2 <= x) = 1 - exp(-x/2) sum_{i<k} (x/2)^i / i! (an Erlang
    distribution); solved by bisection, so the node path needs no scipy.

    :param probability: in (0, 1)
    :param dof: the degrees of freedom, even and >= 2
    :return: x with P(chi2_dof <= x) = probability
    :raises ValueError: on a probability outside (0, 1) or an odd or non-positive dof
    """
    if not 0.0 < probability < 1.0 or dof < 2 or dof % 2:
        raise ValueError(f'need a probability in (0, 1) and an even dof >= 2, got '
                         f'{probability}, {dof}')

    def cdf(x: float) -> float:
        term, total = 1.0, 1.0
        for i in range(1, dof // 2):
            term *= (x / 2.0) / i
            total += term
        return 1.0 - math.exp(-x / 2.0) * total

    low, high = 0.0, float(dof)
    while cdf(high) < probability:
        high *= 2.0
    for _ in range(100):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if cdf(middle) < probability else (low, middle)
    return 0.5 * (low + high)


@dataclass(frozen=True)
class TrackerConfig:
    """
    The tracker's rules.

    :ivar gate_probability: probability of the association gate (chi2 of 2 dof per pairing)
    :ivar confirm_hits: observations that confirm a track
    :ivar drop_tentative_misses: misses in a row, in view, that drop a tentative track
    :ivar lose_misses: misses in a row, in view, that make a confirmed track lost
    :ivar memory_scans: scans unseen after which a track is forgotten
    :ivar max_hypotheses: nodes of the joint-compatibility search per ambiguous cluster
    :ivar occlusion_margin_m: a return nearer than a landmark by this hides it, m
    :ivar persistent_share: the share of an observation's covariance that repeats from scan to
        scan (the extractor's bias for one landmark seen from nearly one place), in [0, 1)
    """

    gate_probability: float = 0.99
    confirm_hits: int = 3
    drop_tentative_misses: int = 1
    lose_misses: int = 3
    memory_scans: int = 50
    max_hypotheses: int = 200
    occlusion_margin_m: float = 0.2
    persistent_share: float = 0.05

    def __post_init__(self):
        """Refuse rules that cannot work, with the reason."""
        problems = []
        if not 0.0 < self.gate_probability < 1.0:
            problems.append(f'gate_probability {self.gate_probability} is not in (0, 1)')
        for name in ('confirm_hits', 'drop_tentative_misses', 'lose_misses', 'memory_scans',
                     'max_hypotheses'):
            if int(getattr(self, name)) < 1:
                problems.append(f'{name} {getattr(self, name)} is below 1')
        if not 0.0 <= self.persistent_share < 1.0:
            problems.append(f'persistent_share {self.persistent_share} is not in [0, 1)')
        if not self.occlusion_margin_m >= 0.0:
            problems.append(f'occlusion_margin_m {self.occlusion_margin_m} is negative')
        if problems:
            raise ValueError('; '.join(problems))


@dataclass(frozen=True)
class Motion:
    """
    The sensor's step since the previous scan, in the previous scan's sensor frame.

    :ivar step: (dx m, dy m, dyaw rad), shape (3,)
    :ivar covariance: its covariance, shape (3, 3)
    """

    step: np.ndarray
    covariance: np.ndarray

    def __post_init__(self):
        """Refuse a step or covariance that is not finite, of the wrong shape or not PSD."""
        step = np.asarray(self.step, dtype=float)
        covariance = np.asarray(self.covariance, dtype=float)
        if step.shape != (3,) or covariance.shape != (3, 3):
            raise ValueError(f'a motion needs a step of shape (3,) and a (3, 3) covariance, got '
                             f'{step.shape} and {covariance.shape}')
        if not (np.isfinite(step).all() and np.isfinite(covariance).all()):
            raise ValueError('the motion step or its covariance is not finite')
        if np.linalg.eigvalsh(0.5 * (covariance + covariance.T)).min() < -1e-12:
            raise ValueError('the motion covariance is not positive semi-definite')
        object.__setattr__(self, 'step', step)
        object.__setattr__(self, 'covariance', 0.5 * (covariance + covariance.T))

    @staticmethod
    def still() -> 'Motion':
        """
        Return the motion of a sensor that does not move.

        :return: a zero step with a zero covariance
        """
        return Motion(np.zeros(3), np.zeros((3, 3)))


def steps_from_poses(poses: np.ndarray, step_sigma_m: float,
                     step_sigma_rad: float) -> List[Motion]:
    """
    Return the steps between consecutive sensor poses, each with a stated covariance.

    :param poses: the sensor pose of each scan (x m, y m, yaw rad) in a fixed frame, shape (T, 3)
    :param step_sigma_m: the sigma of each step's dx and dy, m
    :param step_sigma_rad: the sigma of each step's dyaw, rad
    :return: T motions; the first is still (nothing before it)
    """
    covariance = np.diag([step_sigma_m ** 2, step_sigma_m ** 2, step_sigma_rad ** 2])
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    return [Motion.still()] + [Motion(relative_step(before, after), covariance)
                               for before, after in zip(poses[:-1], poses[1:])]


@dataclass(frozen=True)
class Detections:
    """
    One scan's corners and line landmarks in the sensor frame, as the tracker takes them.

    :ivar corner_pose: each corner's x m, y m and bisector yaw rad, shape (C, 3)
    :ivar corner_cov: their covariances, shape (C, 3, 3)
    :ivar line: each line landmark's normal angle rad and distance m, shape (L, 2)
    :ivar line_cov: their covariances, shape (L, 2, 2)
    :ivar line_ends: each line landmark's first and last end, shape (L, 2, 2), m
    """

    corner_pose: np.ndarray
    corner_cov: np.ndarray
    line: np.ndarray
    line_cov: np.ndarray
    line_ends: np.ndarray

    def __post_init__(self):
        """Refuse detections whose arrays do not agree in shape or hold non-finite values."""
        shapes = [np.shape(self.corner_pose)[1:], np.shape(self.corner_cov)[1:],
                  np.shape(self.line)[1:], np.shape(self.line_cov)[1:],
                  np.shape(self.line_ends)[1:]]
        if (shapes != [(3,), (3, 3), (2,), (2, 2), (2, 2)]
                or len(self.corner_pose) != len(self.corner_cov)
                or not len(self.line) == len(self.line_cov) == len(self.line_ends)):
            raise ValueError(f'detections of inconsistent shapes: {shapes}')
        for name in ('corner_pose', 'corner_cov', 'line', 'line_cov', 'line_ends'):
            if not np.isfinite(getattr(self, name)).all():
                raise ValueError(f'detections with non-finite {name}')

    @staticmethod
    def empty() -> 'Detections':
        """
        Return a scan with no landmarks.

        :return: empty detections
        """
        return Detections(np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 2)),
                          np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))


def detections_of(features, max_landmark_angle_sigma_rad: float) -> Detections:
    """
    Return a scan's corners and line landmarks (:func:`~wctls_ros.core.line_landmarks`).

    :param features: the core's Features of the scan
    :param max_landmark_angle_sigma_rad: the bound of the line landmark rule, rad
    :return: the detections
    """
    segments = features.segments.select(line_landmarks(features.segments,
                                                       max_landmark_angle_sigma_rad))
    corners = features.corners
    return Detections(np.column_stack([corners.xy_m, corners.yaw_rad]).reshape(-1, 3),
                      np.asarray(corners.covariance, dtype=float).reshape(-1, 3, 3),
                      np.column_stack([segments.angle_rad, segments.radius_m]).reshape(-1, 2),
                      np.asarray(segments.covariance, dtype=float).reshape(-1, 2, 2),
                      np.stack([segments.start_xy_m, segments.end_xy_m], axis=1
                               ).reshape(-1, 2, 2))


def observation_poses(detections: Detections) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return every detection as a planar pose with covariance: corners first, then lines.

    A corner is its position and bisector yaw. A line (alpha, r) is its point closest to the
    sensor, (r cos alpha, r sin alpha), with yaw alpha; its covariance J C J^T with
    J = d(x, y, yaw) / d(alpha, r) = [[-r sin alpha, cos alpha], [r cos alpha, sin alpha],
    [1, 0]] (rank 2).

    :param detections: one scan's detections
    :return: (poses (C + L, 3): x m, y m, yaw rad; covariances (C + L, 3, 3))
    """
    angle, radius = detections.line[:, 0], detections.line[:, 1]
    cos, sin = np.cos(angle), np.sin(angle)
    line_pose = np.column_stack([radius * cos, radius * sin, angle])
    jacobian = np.zeros((len(angle), 3, 2))
    jacobian[:, 0] = np.column_stack([-radius * sin, cos])
    jacobian[:, 1] = np.column_stack([radius * cos, sin])
    jacobian[:, 2, 0] = 1.0
    line_cov = jacobian @ detections.line_cov @ jacobian.transpose(0, 2, 1)
    return (np.concatenate([detections.corner_pose, line_pose.reshape(-1, 3)]),
            np.concatenate([detections.corner_cov, line_cov.reshape(-1, 3, 3)]))


@dataclass(frozen=True)
class View:
    """
    What the scan could see: its bearings, its ranges and its reach.

    :ivar angle_min_rad: bearing of beam 0, rad
    :ivar angle_increment_rad: bearing step, rad (negative for a clockwise scan)
    :ivar ranges_m: the ranges, shape (N,), m (invalid ones: NaN, inf or outside the reach)
    :ivar range_max_m: the reach, m
    """

    angle_min_rad: float
    angle_increment_rad: float
    ranges_m: np.ndarray
    range_max_m: float

    def sees(self, xy: np.ndarray, margin_m: float) -> np.ndarray:
        """
        Return which points the scan would have seen.

        :param xy: points in the sensor frame, shape (K, 2), m
        :param margin_m: a return nearer than a point by more than this hides it, m
        :return: shape (K,): inside the bearings and the reach, and not hidden
        """
        count = len(self.ranges_m)
        step = abs(self.angle_increment_rad)
        bearing = np.arctan2(xy[:, 1], xy[:, 0])
        turned = np.sign(self.angle_increment_rad) * (bearing - self.angle_min_rad)
        index = np.rint(np.mod(turned, 2 * np.pi) / step).astype(np.intp)
        full_turn = count * step >= 2 * np.pi - 1.5 * step
        if full_turn:
            index %= count
        inside = index < count
        distance = np.hypot(xy[:, 0], xy[:, 1])
        measured = np.asarray(self.ranges_m, dtype=float)[np.minimum(index, count - 1)]
        with np.errstate(invalid='ignore'):
            hidden = np.isfinite(measured) & (measured < distance - margin_m)
        return inside & (distance <= self.range_max_m) & ~hidden


@dataclass(frozen=True)
class Identified:
    """
    One kind of landmark of one scan with its tracks, in the order of the detections.

    :ivar ids: each detection's track id (>= 1), shape (N,)
    :ivar states: its track's state code (TENTATIVE or CONFIRMED), shape (N,)
    :ivar hits: its track's observations, this one included, shape (N,)
    :ivar age_scans: scans since its track began (0: new), shape (N,)
    :ivar squared_distance: e^T (P + R)^-1 e against its track's prediction, NaN for a new
        track, shape (N,)
    """

    ids: np.ndarray
    states: np.ndarray
    hits: np.ndarray
    age_scans: np.ndarray
    squared_distance: np.ndarray


@dataclass(frozen=True)
class TrackedScan:
    """
    A scan's detections with their ids.

    :ivar corners: the corners' tracks
    :ivar lines: the line landmarks' tracks
    """

    corners: Identified
    lines: Identified


@dataclass(frozen=True)
class Landmark:
    """
    One track's fused estimate in the current sensor frame.

    :ivar track_id: its id (>= 1)
    :ivar kind: CORNER or LINE
    :ivar state: its state code
    :ivar mean: a corner's x m, y m, yaw rad; a line's normal angle rad and distance m
    :ivar covariance: its covariance, (3, 3) or (2, 2)
    :ivar hits: its observations
    :ivar age_scans: scans since it began
    """

    track_id: int
    kind: str
    state: int
    mean: np.ndarray
    covariance: np.ndarray
    hits: int
    age_scans: int


@dataclass
class _Tracks:
    """The tracks of one kind: arrays, one row per track."""

    dims: int
    angle_index: int                          # the coordinate that is an angle
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    mean: np.ndarray = field(init=False)
    cov: np.ndarray = field(init=False)
    ends: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    persistent: np.ndarray = field(init=False)  # the persistent part of the last observation
    state: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    hits: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    misses: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    first_scan: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    last_scan: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self):
        self.mean = np.zeros((0, self.dims))
        self.cov = np.zeros((0, self.dims, self.dims))
        self.persistent = np.zeros((0, self.dims, self.dims))

    def keep(self, rows: np.ndarray) -> None:
        for name in ('ids', 'mean', 'cov', 'persistent', 'ends', 'state', 'hits', 'misses',
                     'first_scan', 'last_scan'):
            setattr(self, name, getattr(self, name)[rows])


class Tracker:
    """
    Corner and line landmark tracks with persistent ids (see the module's docstring).

    Call :meth:`update` once per scan, in order.
    """

    def __init__(self, config: Optional[TrackerConfig] = None,
                 compiled: Optional[bool] = None):
        """
        Start with no tracks.

        :param config: the rules (defaults: :class:`TrackerConfig`)
        :param compiled: None: the compiled twin on every scan the compiled core serves
            (:func:`~wctls_ros.core.runtime.compiled_kernels`), the numpy steps on the others;
            True: the compiled twin always (the compiled core is loaded, or compiled, first);
            False: the numpy steps always
        :raises wctls_ros.core.CoreUnavailable: with ``compiled`` True, when numba cannot give
            the compiled core (not installed, too old, ``WCTLS_ROS_CORE=numpy``)
        """
        self.config = config or TrackerConfig()
        self._tracks = {CORNER: _Tracks(3, 2), LINE: _Tracks(2, 0)}
        self._scan = -1
        self._next_id = 1
        self._joint_gates: Dict[int, float] = {}
        # The share of an observation's covariance that is new in every scan.
        self._white = 1.0 - self.config.persistent_share
        self._compiled = compiled
        self._forced_kernels: Any = None
        if compiled is not None:
            self._forced_kernels = runtime.compiled_kernels('tracking', compiled)
        rules = self.config
        self._rules = TrackRules(float(self._white), int(rules.confirm_hits),
                                 int(rules.drop_tentative_misses), int(rules.lose_misses),
                                 int(rules.memory_scans), int(rules.max_hypotheses),
                                 float(rules.occlusion_margin_m))
        self._gates = np.array([math.nan, self._joint_gate(1)])

    def _joint_gate(self, pairs: int) -> float:
        """Return the chi2 gate of ``pairs`` pairings (2 dof each)."""
        if pairs not in self._joint_gates:
            self._joint_gates[pairs] = chi2_quantile_even(self.config.gate_probability,
                                                          2 * pairs)
        return self._joint_gates[pairs]

    def _gate_table(self, pairs: int) -> np.ndarray:
        """Return the joint gates of 0 (NaN) to at least ``pairs`` pairings, for the kernels."""
        if len(self._gates) <= pairs:
            self._gates = np.array([math.nan] + [self._joint_gate(size)
                                                 for size in range(1, pairs + 1)])
        return self._gates

    def _kernels(self) -> Any:
        """Return the compiled tracker's kernels for this scan, or None for the numpy steps."""
        if self._compiled is None:
            return runtime.compiled_kernels('tracking')
        return self._forced_kernels

    def update(self, detections: Detections, motion: Motion,
               view: Optional[View] = None) -> TrackedScan:
        """
        Predict every track by the motion, associate the scan's detections, update the tracks.

        :param detections: the scan's corners and line landmarks in its sensor frame
        :param motion: the sensor's step since the previous scan (ignored on the first scan)
        :param view: what the scan could see (None: every landmark counts as in view)
        :return: the detections' ids, states, hits and ages
        """
        self._scan += 1
        corner_ends = np.repeat(detections.corner_pose[:, None, :2], 2, axis=1)
        kernels = self._kernels()
        if kernels is not None:
            return self._update_compiled(kernels, detections, corner_ends, motion, view)
        corner_step = self._predict(CORNER, motion)
        line_step = self._predict(LINE, motion)
        corners = self._associate(CORNER, detections.corner_pose, detections.corner_cov,
                                  corner_ends, corner_step, motion.covariance, view)
        lines = self._associate(LINE, detections.line, detections.line_cov,
                                detections.line_ends, line_step, motion.covariance, view)
        return TrackedScan(corners, lines)

    def _update_compiled(self, kernels: Any, detections: Detections, corner_ends: np.ndarray,
                         motion: Motion, view: Optional[View]) -> TrackedScan:
        """Run :meth:`update`'s steps by the compiled kernels (``numba_core/tracking.py``)."""
        if view is None:
            seen, ranges, angle_min, increment, reach = False, np.zeros(1), 0.0, 1.0, 0.0
        else:
            seen, ranges = True, np.ascontiguousarray(view.ranges_m, dtype=float)
            angle_min, increment, reach = (float(view.angle_min_rad),
                                           float(view.angle_increment_rad),
                                           float(view.range_max_m))
        step = np.ascontiguousarray(motion.step)
        step_cov = np.ascontiguousarray(motion.covariance)
        identified = []
        for kind, value, cov, ends in ((CORNER, detections.corner_pose, detections.corner_cov,
                                        corner_ends),
                                       (LINE, detections.line, detections.line_cov,
                                        detections.line_ends)):
            # The kernels' argument types, so that nothing compiles again for another layout.
            value, cov, ends = (np.ascontiguousarray(array, dtype=float)
                                for array in (value, cov, ends))
            tracks = self._tracks[kind]
            matched, squared_distance, keep = kernels.update_tracks(
                kind == LINE, value, cov, ends, tracks.mean, tracks.cov, tracks.persistent,
                tracks.ends, tracks.state, tracks.hits, tracks.misses, tracks.last_scan, step,
                step_cov, self._gate_table(min(len(value), len(tracks.ids))), self._rules,
                self._scan, seen, ranges, angle_min, increment, reach)
            matched_ids = np.where(matched >= 0, tracks.ids[np.maximum(matched, 0)]
                                   if len(tracks.ids) else 0, 0)
            if not keep.all():
                tracks.keep(keep)
            identified.append(self._identify(kind, value, cov, ends, matched_ids,
                                             squared_distance))
        return TrackedScan(*identified)

    def _predict(self, kind: str, motion: Motion) -> np.ndarray:
        """Move one kind's tracks by the step; return d track / d step, shape (K, d, 3)."""
        tracks = self._tracks[kind]
        move = step_corners if kind == CORNER else step_lines
        tracks.mean, by_track, by_step = move(tracks.mean, motion.step)
        tracks.cov = (by_track @ tracks.cov @ by_track.transpose(0, 2, 1)
                      + by_step @ motion.covariance @ by_step.transpose(0, 2, 1))
        tracks.persistent = by_track @ tracks.persistent @ by_track.transpose(0, 2, 1)
        tracks.ends = step_points(tracks.ends, motion.step)
        return by_step

    def _innovation(self, kind: str, value: np.ndarray, cov: np.ndarray):
        """Return the gated innovations (N, K, 2), their covariances (N, K, 2, 2) and d2."""
        tracks = self._tracks[kind]
        error = value[:, None, :2] - tracks.mean[None, :, :2]
        if kind == LINE:
            error[..., 0] = wrap_angle(error[..., 0])
        innovation = (self._white * cov[:, None, :2, :2]) + tracks.cov[None, :, :2, :2]
        # e^T S^-1 e by the 2x2 inverse: a tenth of a batched solve's time over 1,500 pairs.
        s00, s01 = innovation[..., 0, 0], innovation[..., 0, 1]
        s10, s11 = innovation[..., 1, 0], innovation[..., 1, 1]
        e0, e1 = error[..., 0], error[..., 1]
        with np.errstate(divide='ignore', invalid='ignore'):
            squared = (e0 * (s11 * e0 - s01 * e1) + e1 * (s00 * e1 - s10 * e0)) / (
                s00 * s11 - s01 * s10)
        return error, innovation, squared

    def _associate(self, kind: str, value: np.ndarray, cov: np.ndarray, ends: np.ndarray,
                   by_step: np.ndarray, step_cov: np.ndarray,
                   view: Optional[View]) -> Identified:
        """Associate one kind's detections to its tracks and update them."""
        tracks = self._tracks[kind]
        count = len(value)
        matched = np.full(count, -1, dtype=np.intp)
        squared_distance = np.full(count, np.nan)
        if count and len(tracks.ids):
            error, innovation, squared = self._innovation(kind, value, cov)
            with np.errstate(invalid='ignore'):
                gated = squared <= self._joint_gate(1)
            if kind == LINE:
                gated &= overlapping(ends, tracks.ends)
            matched = self._resolve(gated, squared, error, innovation, by_step, step_cov)
            pairs = np.flatnonzero(matched >= 0)
            squared_distance[pairs] = squared[pairs, matched[pairs]]
        matched_ids = np.where(matched >= 0, tracks.ids[np.maximum(matched, 0)]
                               if len(tracks.ids) else 0, 0)
        self._correct(kind, value, cov, ends, matched)
        self._age(kind, matched, view)
        return self._identify(kind, value, cov, ends, matched_ids, squared_distance)

    def _resolve(self, gated: np.ndarray, squared: np.ndarray, error: np.ndarray,
                 innovation: np.ndarray, by_step: np.ndarray, step_cov: np.ndarray
                 ) -> np.ndarray:
        """Return each detection's track (-1: none): clusters of gated pairs, JCBB in each."""
        matched = np.full(len(gated), -1, dtype=np.intp)
        # A pair alone in its row and its column is a cluster of its own: matched as it is.
        alone = gated & (gated.sum(axis=1) == 1)[:, None] & (gated.sum(axis=0) == 1)
        detections, tracks = np.nonzero(alone)
        matched[detections] = tracks
        for detections_of_cluster, tracks_of_cluster in _clusters(gated & ~alone):
            search = _JointSearch(gated, squared, error, innovation, by_step[:, :2], step_cov,
                                  tracks_of_cluster, self._joint_gate,
                                  self.config.max_hypotheses)
            for n, k in search.best(detections_of_cluster):
                matched[n] = k
        return matched

    def _correct(self, kind: str, value: np.ndarray, cov: np.ndarray, ends: np.ndarray,
                 matched: np.ndarray) -> None:
        """Fuse each matched detection into its track (a Kalman update of the track alone)."""
        tracks = self._tracks[kind]
        pairs = np.flatnonzero(matched >= 0)
        if not len(pairs):
            return
        rows = matched[pairs]
        angle = tracks.angle_index
        error = value[pairs] - tracks.mean[rows]
        error[:, angle] = wrap_angle(error[:, angle])
        prior = tracks.cov[rows]
        white = self._white * cov[pairs]
        gain = np.linalg.solve(prior + white, prior).transpose(0, 2, 1)   # P (P + R)^-1
        tracks.mean[rows] += np.einsum('kij,kj->ki', gain, error)
        tracks.mean[rows, angle] = wrap_angle(tracks.mean[rows, angle])
        # P - P (P + R)^-1 P, written P (P + R)^-1 R: no difference of two nearly equal terms
        # where a track far less certain than its observation (a lost odometry's step) shrinks
        # to about R, which would lose digits to rounding (1e-9 of 1e3 m^2 down to 1e-4).
        updated = gain @ white
        tracks.cov[rows] = 0.5 * (updated + updated.transpose(0, 2, 1))
        tracks.persistent[rows] = cov[pairs] - white
        if kind == LINE:
            tracks.ends[rows] = spanned(ends[pairs], tracks.ends[rows])
        tracks.hits[rows] += 1
        tracks.misses[rows] = 0
        tracks.last_scan[rows] = self._scan
        confirm = (tracks.state[rows] == LOST) | (tracks.hits[rows] >= self.config.confirm_hits)
        tracks.state[rows[confirm]] = CONFIRMED

    def _age(self, kind: str, matched: np.ndarray, view: Optional[View]) -> None:
        """Count the misses of the tracks in view, lose and drop tracks by the rules."""
        tracks = self._tracks[kind]
        missed = np.ones(len(tracks.ids), dtype=bool)
        missed[matched[matched >= 0]] = False
        if view is not None and missed.any():
            where = (tracks.mean[:, :2] if kind == CORNER else tracks.ends.mean(axis=1))
            in_view = view.sees(where, self.config.occlusion_margin_m)
            missed &= in_view
        tracks.misses[missed] += 1
        rules = self.config
        lose = (tracks.state == CONFIRMED) & (tracks.misses >= rules.lose_misses)
        tracks.state[lose] = LOST
        drop = ((tracks.state == TENTATIVE) & (tracks.misses >= rules.drop_tentative_misses)
                | (self._scan - tracks.last_scan > rules.memory_scans))
        if drop.any():
            tracks.keep(~drop)

    def _identify(self, kind: str, value: np.ndarray, cov: np.ndarray, ends: np.ndarray,
                  matched_ids: np.ndarray, squared_distance: np.ndarray) -> Identified:
        """Start a track for every unmatched detection (id 0); return every detection's."""
        tracks = self._tracks[kind]
        new = matched_ids == 0
        fresh = np.arange(self._next_id, self._next_id + int(new.sum()), dtype=np.int64)
        self._next_id += len(fresh)
        ids = matched_ids.copy()
        ids[new] = fresh
        if len(fresh):
            self._start_tracks(tracks, fresh, value[new], cov[new], ends[new])
        # A matched track is never dropped: every id has its row.
        rows = np.searchsorted(tracks.ids, ids) if len(ids) else np.zeros(0, dtype=np.intp)
        return Identified(ids, tracks.state[rows].copy(), tracks.hits[rows].copy(),
                          self._scan - tracks.first_scan[rows], squared_distance)

    def _start_tracks(self, tracks: _Tracks, fresh: np.ndarray, value: np.ndarray,
                      cov: np.ndarray, ends: np.ndarray) -> None:
        """Append a track of ids ``fresh`` for each of the unmatched detections given."""
        first_state = CONFIRMED if self.config.confirm_hits <= 1 else TENTATIVE
        tracks.ids = np.concatenate([tracks.ids, fresh])
        tracks.mean = np.concatenate([tracks.mean, value])
        tracks.cov = np.concatenate([tracks.cov, self._white * cov])
        tracks.persistent = np.concatenate([tracks.persistent,
                                            (1.0 - self._white) * cov])
        tracks.ends = np.concatenate([tracks.ends, ends])
        tracks.state = np.concatenate([tracks.state, np.full(len(fresh), first_state,
                                                             dtype=np.int8)])
        tracks.hits = np.concatenate([tracks.hits, np.ones(len(fresh), dtype=np.int64)])
        tracks.misses = np.concatenate([tracks.misses, np.zeros(len(fresh), dtype=np.int64)])
        now = np.full(len(fresh), self._scan, dtype=np.int64)
        tracks.first_scan = np.concatenate([tracks.first_scan, now])
        tracks.last_scan = np.concatenate([tracks.last_scan, now])

    def landmarks(self, kind: Optional[str] = None) -> List[Landmark]:
        """
        Return the fused estimate of every track, in the current sensor frame.

        :param kind: CORNER or LINE, or None for both
        :return: the tracks (corners first), each with its state
        """
        out = []
        for name in (KINDS if kind is None else (kind,)):
            tracks = self._tracks[name]
            out += [Landmark(int(tracks.ids[k]), name, int(tracks.state[k]),
                             tracks.mean[k].copy(), tracks.cov[k] + tracks.persistent[k],
                             int(tracks.hits[k]),
                             int(self._scan - tracks.first_scan[k]))
                    for k in range(len(tracks.ids))]
        return out


def _clusters(gated: np.ndarray) -> List[Tuple[List[int], List[int]]]:
    """
    Return the connected clusters of gated (detection, track) pairs.

    :param gated: shape (N, K): which pairs pass the individual gate
    :return: (detections, in ascending order, and tracks) of each cluster with at least one pair
    """
    pairs = np.argwhere(gated).tolist()
    parent = list(range(gated.shape[0] + gated.shape[1]))

    def root(node: int) -> int:
        while parent[node] != node:
            parent[node] = parent[parent[node]]
            node = parent[node]
        return node

    offset = gated.shape[0]
    for n, k in pairs:
        parent[root(n)] = root(offset + k)
    clusters: Dict[int, Tuple[List[int], List[int]]] = {}
    for n, k in pairs:
        cluster = clusters.setdefault(root(n), ([], []))
        if n not in cluster[0]:
            cluster[0].append(n)
        if k not in cluster[1]:
            cluster[1].append(k)
    return list(clusters.values())


class _JointSearch:
    """Joint compatibility branch and bound over one cluster (Neira and Tardos 2001)."""

    def __init__(self, gated, squared, error, innovation, by_step, step_cov, tracks,
                 joint_gate, max_nodes: int):
        self.gated, self.squared, self.error = gated, squared, error
        self.innovation = innovation
        # The shared step's cross covariance of every two of the cluster's tracks: G_k Q G_j^T,
        # by their place in ``tracks``.
        self.place = np.full(gated.shape[1], -1, dtype=np.intp)
        self.place[tracks] = np.arange(len(tracks))
        by_step = by_step[tracks]
        self.shared = (by_step @ step_cov)[:, None] @ by_step[None].transpose(0, 1, 3, 2)
        self.joint_gate, self.nodes_left = joint_gate, max_nodes
        self.best_pairs: List[Tuple[int, int]] = []
        self.best_squared = math.inf
        self.fallback: List[Tuple[int, int]] = []

    def joint_squared(self, pairs: Sequence[Tuple[int, int]]) -> float:
        """Return the stacked innovation's squared Mahalanobis distance of a hypothesis."""
        detections, tracks = np.array(pairs, dtype=np.intp).reshape(-1, 2).T
        size = len(tracks)
        # Off the diagonal the shared step: cov(track k, track j) = G_k Q G_j^T.
        place = self.place[tracks]
        blocks = self.shared[place[:, None], place[None, :]]
        blocks[np.arange(size), np.arange(size)] = self.innovation[detections, tracks]
        stacked = blocks.transpose(0, 2, 1, 3).reshape(2 * size, 2 * size)
        vector = self.error[detections, tracks].reshape(-1)
        return float(vector @ np.linalg.solve(stacked, vector))

    def best(self, detections: List[int]) -> List[Tuple[int, int]]:
        """
        Return the largest jointly compatible pairing of the cluster's detections.

        :param detections: the cluster's detections
        :return: its (detection, track) pairs; among as many pairs the lowest joint distance
        """
        self._start(detections)
        order = sorted(detections, key=lambda n: int(self.gated[n].sum()))
        self._descend(order, 0, [], 0.0)
        # A search cut short before any leaf keeps the nearest-first pairing.
        return self.best_pairs or (self.fallback if self.nodes_left <= 0 else [])

    def _start(self, detections: List[int]) -> None:
        """Take the nearest-first pairing as the best so far when it is jointly compatible."""
        pairs: List[Tuple[int, int]] = []
        candidates = [(self.squared[n, k], n, int(k)) for n in detections
                      for k in np.flatnonzero(self.gated[n])]
        for _, n, k in sorted(candidates):
            if all(n != m and k != j for m, j in pairs):
                pairs.append((n, k))
        self.fallback = pairs
        squared = self.joint_squared(pairs)
        if squared <= self.joint_gate(len(pairs)):
            self.best_pairs, self.best_squared = pairs, squared

    def _descend(self, order: List[int], depth: int, pairs: List[Tuple[int, int]],
                 joint: float) -> None:
        if self.nodes_left <= 0:
            return
        self.nodes_left -= 1
        if depth == len(order):
            if (len(pairs), -joint) > (len(self.best_pairs), -self.best_squared):
                self.best_pairs, self.best_squared = list(pairs), joint
            return
        n = order[depth]
        used = {k for _, k in pairs}
        for k in sorted(np.flatnonzero(self.gated[n]), key=lambda k: self.squared[n, k]):
            if int(k) in used:
                continue
            if self.nodes_left <= 0:      # out of nodes: nothing below can change the best
                return
            candidate = pairs + [(n, int(k))]
            squared = self.joint_squared(candidate)
            if squared <= self.joint_gate(len(candidate)):
                self._descend(order, depth + 1, candidate, squared)
        # Leaving this detection unpaired can still win only with enough detections left.
        if len(pairs) + len(order) - depth - 1 > len(self.best_pairs):
            self._descend(order, depth + 1, pairs, joint)
