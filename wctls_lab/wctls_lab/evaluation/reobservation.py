# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Re-observation consistency of corners and lines from a moving sensor, as a SLAM front end sees it.

A landmark seen again from another viewpoint should move no more than its covariance says.
Three measures, for corners and for lines (a segment's infinite line, normal angle and
distance; only the line landmarks, the segments feature_node flags ``landmark``,
:func:`~wctls_ros.core.line_landmarks`, as a SLAM front end gates only those):

- **pose-free** (no poses needed): landmarks of consecutive scans are associated nearest first,
  one to one (:func:`.rules.assign`), within the widest gate of the shared rule, 25 cm, since
  the sensor moved between the scans (lines within 25 cm and 5 deg). For every two landmarks
  seen in both scans, a quantity a rigid motion does not change is compared: the distance of
  two corners, the angle between two lines, the distance of a corner from a line (not one of
  its own). Its change over its propagated variance (each
  landmark's covariance, the two scans independent) is a chi-square with 1 degree of freedom:
  the share inside the 95 % gate (3.84) is 0.95 when the covariances are honest;
- **with poses** (a pose per scan and a stated pose covariance): every landmark is moved into the
  world frame (its covariance with the pose's), associated to the track whose last observation
  is nearest (Mahalanobis, within the 99.99 % gate; tracks unseen for 50 scans are closed), and
  the innovation against that observation is tested in the 95 % gate (chi-square, 2 degrees of
  freedom: 5.99). A line joins a track only when its segment overlaps the stretch of wall the
  track has seen (the union of its segments along its line): the infinite lines of two pieces
  of wall metres apart, or of a wall and a cabinet before it, are alike within the pose's wide
  gate, but they are not one landmark;
- **tracks and landmarks**: how many scans each track lasts (median and 90th percentile) and how
  many landmarks (corners + line landmarks) each scan gives.

The within-scan correlation of landmarks (the common-mode range offset) is left out of the
variances of the pose-free quantities; the pose-based test compares one landmark at a time.
Pure numpy.
"""

from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from wctls_ros.core import FeatureConfig
from wctls_ros.frontend.frames import (Landmarks, landmarks_from_features, overlapping, spanned,
                                       to_world, to_world_points, wrap_angle)

from .analysis import features_per_scan
from .rules import assign, ASSOCIATION_GATE_MAX_M
from .samples import ScanCorners
from .scans import StaticScans

# 95 % points of the chi-square distribution with 1 and 2 degrees of freedom.
GATE_1DOF = 3.841
GATE_2DOF = 5.991
# Tracks take an observation within this Mahalanobis distance squared (chi2, 2 dof, 99.99 %):
# wider than the tested gate, so that the test measures the covariances, not the association.
TRACK_GATE_2DOF = 18.42
# A track not seen for more than this many scans takes no more observations.
TRACK_MEMORY_SCANS = 50
# Lines of consecutive scans are one line within these (the corners' widest gate).
LINE_GATE_M = ASSOCIATION_GATE_MAX_M
LINE_GATE_RAD = math.radians(5.0)
# The figures :meth:`Reobservation.summary` gives (score's table columns).
REOBSERVATION_KEYS = (
    'landmarks_per_scan', 'lines_per_scan', 'corner_distance_in_gate', 'line_angle_in_gate',
    'corner_line_distance_in_gate', 'corner_tracks_in_gate', 'line_tracks_in_gate',
    'corner_track_median', 'corner_track_p90', 'line_track_median', 'line_track_p90')


@dataclass(frozen=True)
class GateShare:
    """
    How many tested re-observations fell inside the 95 % gate.

    :ivar tested: re-observations (or pairs) tested
    :ivar inside: of those, inside the gate
    """

    tested: int
    inside: int

    @property
    def share(self) -> float:
        """
        Return inside / tested.

        :return: the share (0.95 when the covariances are honest; NaN when nothing was tested)
        """
        return self.inside / self.tested if self.tested else math.nan

    def describe(self) -> str:
        """
        Return the share in words.

        :return: e.g. '94.8 % of 1234'
        """
        return f'{100 * self.share:.1f} % of {self.tested}' if self.tested else 'none tested'


@dataclass(frozen=True)
class Reobservation:
    """
    The re-observation figures of one configuration on one recording.

    :ivar scans: scans measured (the tracks use those with a pose)
    :ivar corners_per_scan: mean corners per scan
    :ivar lines_per_scan: mean line landmarks per scan
    :ivar corner_distance: pose-free test of corner-corner distances
    :ivar line_angle: pose-free test of line-line angles
    :ivar corner_line_distance: pose-free test of corner-line distances
    :ivar corner_tracks: with poses, the test of corner re-observations (None without poses)
    :ivar line_tracks: with poses, the test of line re-observations (None without poses)
    :ivar corner_track_lengths: with poses, scans per corner track
    :ivar line_track_lengths: with poses, scans per line track
    """

    scans: int
    corners_per_scan: float
    lines_per_scan: float
    corner_distance: GateShare
    line_angle: GateShare
    corner_line_distance: GateShare
    corner_tracks: Optional[GateShare] = None
    line_tracks: Optional[GateShare] = None
    corner_track_lengths: Tuple[int, ...] = ()
    line_track_lengths: Tuple[int, ...] = ()

    @property
    def landmarks_per_scan(self) -> float:
        """
        Return the landmarks per scan: corners and line landmarks.

        :return: their sum
        """
        return self.corners_per_scan + self.lines_per_scan

    def summary(self) -> Dict[str, float]:
        """
        Return the figures for score's tables.

        :return: REOBSERVATION_KEYS -> value (NaN where not measured)
        """
        def share(gate: Optional[GateShare]) -> float:
            return gate.share if gate is not None else math.nan

        return dict(zip(REOBSERVATION_KEYS, (
            self.landmarks_per_scan, self.lines_per_scan, share(self.corner_distance),
            share(self.line_angle), share(self.corner_line_distance), share(self.corner_tracks),
            share(self.line_tracks), _percentile(self.corner_track_lengths, 50),
            _percentile(self.corner_track_lengths, 90), _percentile(self.line_track_lengths, 50),
            _percentile(self.line_track_lengths, 90))))

    def lines(self) -> List[str]:
        """
        Return the figures as text lines, as ``score`` prints them.

        :return: one line per figure
        """
        text = [f'landmarks per scan {self.landmarks_per_scan:.2f} (corners '
                f'{self.corners_per_scan:.2f} + line landmarks {self.lines_per_scan:.2f}) over '
                f'{self.scans} scans',
                'pose-free re-observation (consecutive scans) inside the 95 % gate: corner '
                f'distances {self.corner_distance.describe()}, line angles '
                f'{self.line_angle.describe()}, corner-line distances '
                f'{self.corner_line_distance.describe()}']
        if self.corner_tracks is not None:
            text.append('with poses, re-observations inside the 95 % gate: corners '
                        f'{self.corner_tracks.describe()}, lines '
                        f'{self.line_tracks.describe()}')
            text.append('track lengths, scans (median, p90): corners '
                        f'{_percentile(self.corner_track_lengths, 50):g}, '
                        f'{_percentile(self.corner_track_lengths, 90):g}, lines '
                        f'{_percentile(self.line_track_lengths, 50):g}, '
                        f'{_percentile(self.line_track_lengths, 90):g}')
        return text


def _percentile(lengths: Sequence[int], percent: float) -> float:
    """Return a percentile of track lengths (NaN without tracks)."""
    return float(np.percentile(lengths, percent)) if len(lengths) else math.nan


def match_lines(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """
    Match the lines of two consecutive scans, nearest first, one to one.

    :param before: (angle rad, distance m) of the first scan's lines, shape (L, 2)
    :param after: those of the second, shape (M, 2)
    :return: for each line of the first scan, the index of its match in the second, or -1
    """
    out = np.full(len(before), -1, dtype=np.intp)
    if not len(before) or not len(after):
        return out
    d_angle = np.abs(wrap_angle(before[:, None, 0] - after[None, :, 0]))
    d_radius = np.abs(before[:, None, 1] - after[None, :, 1])
    cost = (d_angle / LINE_GATE_RAD) ** 2 + (d_radius / LINE_GATE_M) ** 2
    pairs = np.argwhere((d_angle <= LINE_GATE_RAD) & (d_radius <= LINE_GATE_M))
    taken = np.zeros(len(after), dtype=bool)
    for i, j in pairs[np.argsort(cost[pairs[:, 0], pairs[:, 1]], kind='stable')]:
        if out[i] < 0 and not taken[j]:
            out[i] = j
            taken[j] = True
    return out


def _match_corners(before: Landmarks, after: Landmarks) -> np.ndarray:
    """Return for each corner of ``before`` its match in ``after`` (-1: none)."""
    if not len(before.corner_xy):
        return np.zeros(0, dtype=np.intp)
    corners = ScanCorners(after.corner_xy, after.corner_cov, after.corner_cov, after.corner_lines)
    # The sensor moved between the scans by more than the corners' noise: the widest gate.
    gates = np.full(len(before.corner_xy), ASSOCIATION_GATE_MAX_M)
    return assign([corners], before.corner_xy, gates)[0]


def _distance_and_variance(xy: np.ndarray, cov: np.ndarray, i: np.ndarray, j: np.ndarray):
    """Return the distances of corner pairs and their variances."""
    delta = xy[j] - xy[i]
    distance = np.hypot(delta[:, 0], delta[:, 1])
    unit = delta / np.maximum(distance, 1e-12)[:, None]
    variance = np.einsum('ni,nij,nj->n', unit, cov[i] + cov[j], unit)
    return distance, variance


def _corner_line_distance(xy: np.ndarray, cov: np.ndarray, line: np.ndarray,
                          line_cov: np.ndarray, c: np.ndarray, k: np.ndarray):
    """Return |distance| of corners c from lines k and its variance."""
    normal = np.column_stack([np.cos(line[k, 0]), np.sin(line[k, 0])])
    signed = np.einsum('ni,ni->n', xy[c], normal) - line[k, 1]
    d_angle = -xy[c, 0] * np.sin(line[k, 0]) + xy[c, 1] * np.cos(line[k, 0])
    jacobian = np.column_stack([d_angle, -np.ones(len(k))])
    variance = (np.einsum('ni,nij,nj->n', normal, cov[c], normal)
                + np.einsum('ni,nij,nj->n', jacobian, line_cov[k], jacobian))
    return np.abs(signed), variance


def pose_free(per_scan: Sequence[Landmarks]) -> Tuple[GateShare, GateShare, GateShare]:
    """
    Test pose-invariant quantities of landmarks seen in consecutive scans.

    :param per_scan: the landmarks of consecutive scans
    :return: the shares inside the 95 % gate of corner-corner distances, line-line angles and
        corner-line distances
    """
    counts = np.zeros((3, 2), dtype=np.int64)
    for before, after in zip(per_scan[:-1], per_scan[1:]):
        corners = _match_corners(before, after)
        lines = match_lines(before.line, after.line)
        ci = np.flatnonzero(corners >= 0)
        li = np.flatnonzero(lines >= 0)
        if len(ci) >= 2:
            i, j = np.triu_indices(len(ci), 1)
            a, b = _distance_and_variance(before.corner_xy, before.corner_cov, ci[i], ci[j])
            c, d = _distance_and_variance(after.corner_xy, after.corner_cov,
                                          corners[ci[i]], corners[ci[j]])
            counts[0] += _gated((c - a) ** 2 / (b + d), GATE_1DOF)
        if len(li) >= 2:
            i, j = np.triu_indices(len(li), 1)
            angle_before = wrap_angle(before.line[li[i], 0] - before.line[li[j], 0])
            angle_after = wrap_angle(after.line[lines[li[i]], 0] - after.line[lines[li[j]], 0])
            variance = (before.line_cov[li[i], 0, 0] + before.line_cov[li[j], 0, 0]
                        + after.line_cov[lines[li[i]], 0, 0]
                        + after.line_cov[lines[li[j]], 0, 0])
            counts[1] += _gated(wrap_angle(angle_after - angle_before) ** 2 / variance, GATE_1DOF)
        if len(ci) and len(li):
            c, k = (grid.ravel() for grid in np.meshgrid(ci, li, indexing='ij'))
            own = (before.corner_lines[c] == k[:, None]).any(axis=1)
            c, k = c[~own], k[~own]
            a, b = _corner_line_distance(before.corner_xy, before.corner_cov, before.line,
                                         before.line_cov, c, k)
            e, f = _corner_line_distance(after.corner_xy, after.corner_cov, after.line,
                                         after.line_cov, corners[c], lines[k])
            counts[2] += _gated((e - a) ** 2 / (b + f), GATE_1DOF)
    return tuple(GateShare(int(n), int(k)) for n, k in counts)


def _gated(squared: np.ndarray, gate: float) -> np.ndarray:
    """Return (tested, inside) of normalised squares (non-finite ones are left out)."""
    finite = squared[np.isfinite(squared)]
    return np.array([len(finite), int(np.count_nonzero(finite <= gate))])


class _Tracks:
    """
    Tracks of one kind of landmark: the last observation of each, and its length.

    A line track also keeps the stretch of wall its segments have covered (their union along
    its line), since a wall partly hidden in one scan is still the wall seen whole before.
    """

    def __init__(self, lines: bool):
        self.lines = lines              # the first coordinate is an angle; segments must overlap
        self.last = np.zeros((0, 2))
        self.last_cov = np.zeros((0, 2, 2))
        self.last_ends = np.zeros((0, 2, 2))
        self.last_scan = np.zeros(0, dtype=np.intp)
        self.lengths: List[int] = []
        self.tested = 0
        self.inside = 0

    def update(self, scan: int, value: np.ndarray, cov: np.ndarray, ends: np.ndarray) -> None:
        """
        Associate one scan's observations, test the re-observations and extend the tracks.

        :param scan: the scan's number
        :param value: the observations in the world frame, shape (N, 2)
        :param cov: their covariances, shape (N, 2, 2)
        :param ends: lines: their segments' ends in the world frame, shape (N, 2, 2), m (corners:
            not used)
        """
        # Only tracks seen lately take observations: the others have left the view (and a long
        # recording would otherwise compare every observation with every track it ever had).
        active = np.flatnonzero(scan - self.last_scan <= TRACK_MEMORY_SCANS)
        matched = np.full(len(value), -1, dtype=np.intp)
        if len(active) and len(value):
            error = value[:, None, :] - self.last[None, active]
            if self.lines:
                error[..., 0] = wrap_angle(error[..., 0])
            innovation = cov[:, None] + self.last_cov[None, active]
            squared = np.einsum('nki,nkij,nkj->nk', error, np.linalg.inv(innovation), error)
            gated = squared <= TRACK_GATE_2DOF
            if self.lines:
                gated &= overlapping(ends, self.last_ends[active])
            pairs = np.argwhere(gated)
            taken = np.zeros(len(active), dtype=bool)
            for n, k in pairs[np.argsort(squared[pairs[:, 0], pairs[:, 1]], kind='stable')]:
                if matched[n] < 0 and not taken[k]:
                    matched[n] = active[k]
                    taken[k] = True
                    self.tested += 1
                    self.inside += int(squared[n, k] <= GATE_2DOF)
        for n, k in enumerate(matched):
            if k >= 0:
                self.last[k], self.last_cov[k], self.last_scan[k] = value[n], cov[n], scan
                if self.lines:
                    self.last_ends[k] = spanned(ends[n], self.last_ends[k])
                self.lengths[k] += 1
        new = matched < 0
        self.last = np.concatenate([self.last, value[new]])
        self.last_cov = np.concatenate([self.last_cov, cov[new]])
        self.last_ends = np.concatenate([self.last_ends, ends[new]])
        self.last_scan = np.concatenate([self.last_scan, np.full(int(new.sum()), scan)])
        self.lengths += [1] * int(new.sum())


def with_poses(per_scan: Sequence[Landmarks], poses: np.ndarray, pose_cov: np.ndarray):
    """
    Track the landmarks in the world frame and test their re-observations.

    :param per_scan: the landmarks of consecutive scans
    :param poses: the sensor pose of each scan (x m, y m, yaw rad), shape (T, 3)
    :param pose_cov: the covariance of each pose, shape (3, 3)
    :return: (corner GateShare, line GateShare, corner track lengths, line track lengths)
    """
    corners, lines = _Tracks(False), _Tracks(True)
    for scan, (landmarks, pose) in enumerate(zip(per_scan, poses)):
        xy, xy_cov, line, line_cov = to_world(landmarks, pose, pose_cov)
        corners.update(scan, xy, xy_cov, np.stack([xy, xy], axis=1))
        lines.update(scan, line, line_cov, to_world_points(landmarks.line_ends, pose))
    return (GateShare(corners.tested, corners.inside), GateShare(lines.tested, lines.inside),
            tuple(corners.lengths), tuple(lines.lengths))


def reobservation(scans: StaticScans, config: FeatureConfig, poses: Optional[np.ndarray] = None,
                  pose_sigma_m: float = 0.0, pose_sigma_rad: float = 0.0,
                  covariance_scale: float = 1.0) -> Reobservation:
    """
    Extract the corners and lines of a recording and measure their re-observation consistency.

    :param scans: consecutive scans (a moving or a still sensor)
    :param config: the pipeline configuration
    :param poses: the sensor pose of each scan (x m, y m, yaw rad), shape (T, 3), or None
    :param pose_sigma_m: the poses' position sigma (each axis), m
    :param pose_sigma_rad: the poses' heading sigma, rad
    :param covariance_scale: multiply the landmark covariances by this (1: as extracted)
    :return: the figures
    """
    per_scan = [landmarks_from_features(features, config.max_landmark_angle_sigma_rad,
                                        covariance_scale)
                for features, _ in features_per_scan(scans, config)]
    return measure(per_scan, poses, pose_sigma_m, pose_sigma_rad)


def measure(per_scan: Sequence[Landmarks], poses: Optional[np.ndarray] = None,
            pose_sigma_m: float = 0.0, pose_sigma_rad: float = 0.0) -> Reobservation:
    """
    Measure the re-observation consistency of the landmarks of consecutive scans.

    :param per_scan: the landmarks of each scan
    :param poses: the sensor pose of each scan (x m, y m, yaw rad), shape (T, 3), NaN rows where
        unknown (left out of the tracks), or None
    :param pose_sigma_m: the poses' position sigma (each axis), m
    :param pose_sigma_rad: the poses' heading sigma, rad
    :return: the figures
    """
    distance, angle, corner_line = pose_free(per_scan)
    figures = {
        'scans': len(per_scan),
        'corners_per_scan': float(np.mean([len(s.corner_xy) for s in per_scan]))
        if len(per_scan) else math.nan,
        'lines_per_scan': float(np.mean([len(s.line) for s in per_scan]))
        if len(per_scan) else math.nan,
        'corner_distance': distance, 'line_angle': angle, 'corner_line_distance': corner_line}
    if poses is not None:
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        known = np.isfinite(poses).all(axis=1)
        pose_cov = np.diag([pose_sigma_m ** 2, pose_sigma_m ** 2, pose_sigma_rad ** 2])
        (figures['corner_tracks'], figures['line_tracks'], figures['corner_track_lengths'],
         figures['line_track_lengths']) = with_poses(
            [landmarks for landmarks, keep in zip(per_scan, known) if keep], poses[known],
            pose_cov)
    return Reobservation(**figures)
