# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The landmark tracker's figures on a recording: how long ids last, how often they are wrong.

The tracker (:mod:`wctls_ros.frontend.tracking`) runs over the scans with the motion between
consecutive poses (a still recording: no motion), each step given ``step_sigma_m`` and
``step_sigma_rad``, or with given motions (the odometry's own steps and covariances, as a
robot without a reference runs it); the poses then only judge the tracks. Per kind (corners,
line landmarks), over the tracks ever confirmed:

- **confirmed tracks**, and their **length**: scans from the first observation to the last
  (median, p90), and the metres the sensor travelled meanwhile (with poses);
- **id switches** (one track on two world landmarks): with hand labels, each change of the true
  corner a track's observations match (:func:`.score.match_detections`); without, each
  observation of a track that is not within the 99.99 % gate (chi2 2 dof 18.42) of the track's
  previous observation, both in the world frame with the pose's covariance
  (``pose_sigma_m``, ``pose_sigma_rad``), a line written with its normal within 90 deg of the
  other's (the line (alpha, r) is also (alpha + pi, -r));
- **duplicates** (two confirmed tracks on one world landmark): with labels, two tracks whose
  observations mostly match the same true corner; without, two tracks never seen in one scan
  whose mean world positions (lines: world lines, and overlapping stretches) are within the
  99.99 % gate of their observations' mean covariance;
- switches and duplicates per 100 scans;
- the **gate share**: re-observations inside their 95 % gate against the track's prediction
  (0.95 / 0.99 = 0.96 when honest, since the tracker's gate truncates at 99 %);
- with labels, **confirmed-landmark precision** (confirmed corner tracks whose observations
  mostly match a labelled corner) and **recall** (labelled visible corners that some confirmed
  track matches).
"""

from dataclasses import dataclass
import math
import time
from typing import Dict, List, Optional, Sequence

import numpy as np
from wctls_ros.core import FeatureConfig
from wctls_ros.frontend.frames import overlapping, to_world_points, world_landmarks, wrap_angle
from wctls_ros.frontend.tracking import (chi2_quantile_even, CONFIRMED, Detections,
                                         detections_of, Motion, steps_from_poses,
                                         TEST_GATE_PROBABILITY, TrackedScan, Tracker,
                                         TrackerConfig, View)

from .analysis import features_per_scan
from .reobservation import TRACK_GATE_2DOF
from .scans import StaticScans
from .score import match_detections
from .truth import Truth

# The figures of one kind, as :meth:`TrackFigures.summary` names them.
TRACK_KEYS = ('confirmed_tracks', 'length_scans_median', 'length_scans_p90',
              'length_m_median', 'length_m_p90', 'id_switches_per_100_scans',
              'duplicates_per_100_scans', 'gate_share', 'gate_tested', 'precision', 'recall')


@dataclass(frozen=True)
class TrackRun:
    """
    The tracker's output over a recording.

    :ivar detections: each scan's detections, in the sensor frame
    :ivar tracked: each scan's ids, states, hits and squared distances
    :ivar poses: the sensor pose of each scan (x m, y m, yaw rad), shape (T, 3) (zeros when
        still)
    :ivar seconds_per_scan: the tracker's own time per scan (extraction not counted), s
    """

    detections: List[Detections]
    tracked: List[TrackedScan]
    poses: np.ndarray
    seconds_per_scan: float


def run_tracker(scans: StaticScans, config: FeatureConfig, poses: Optional[np.ndarray] = None,
                step_sigma_m: float = 0.0, step_sigma_rad: float = 0.0,
                tracker_config: Optional[TrackerConfig] = None,
                motions: Optional[Sequence[Motion]] = None) -> TrackRun:
    """
    Extract every scan's landmarks and track them.

    :param scans: consecutive scans
    :param config: the pipeline configuration
    :param poses: the sensor pose of each scan (x m, y m, yaw rad), shape (T, 3), or None for
        a still sensor
    :param step_sigma_m: the sigma of each step's dx and dy, m
    :param step_sigma_rad: the sigma of each step's dyaw, rad
    :param tracker_config: the tracker's rules (defaults: :class:`TrackerConfig`)
    :param motions: each scan's step since the previous one, T of them, instead of the steps
        between the poses (which then only judge the tracks)
    :return: the run
    """
    poses = np.zeros((len(scans), 3)) if poses is None else np.asarray(poses, dtype=float)
    if motions is None:
        motions = steps_from_poses(poses, step_sigma_m, step_sigma_rad)
    elif len(motions) != len(scans):
        raise ValueError(f'{len(motions)} motions for {len(scans)} scans')
    tracker = Tracker(tracker_config)
    detections, tracked = [], []
    spent = 0.0
    for t, (features, _) in enumerate(features_per_scan(scans, config)):
        found = detections_of(features, config.max_landmark_angle_sigma_rad)
        view = View(scans.angle_min, scans.angle_increment, scans.ranges[t], scans.range_max)
        start = time.perf_counter()
        tracked.append(tracker.update(found, motions[t], view))
        spent += time.perf_counter() - start
        detections.append(found)
    return TrackRun(detections, tracked, poses, spent / max(len(scans), 1))


@dataclass(frozen=True)
class TrackFigures:
    """
    The figures of one kind of landmark over one run (see the module's docstring).

    :ivar kind: 'corner' or 'line'
    :ivar scans: scans tracked
    :ivar lengths_scans: each confirmed track's length, scans
    :ivar lengths_m: the metres travelled over each, m
    :ivar id_switches: id switches counted
    :ivar duplicates: duplicate pairs counted
    :ivar gate_tested: re-observations tested
    :ivar gate_inside: of those, inside the 95 % gate
    :ivar precision: confirmed-landmark precision (NaN without labels)
    :ivar recall: confirmed-landmark recall (NaN without labels)
    """

    kind: str
    scans: int
    lengths_scans: np.ndarray
    lengths_m: np.ndarray
    id_switches: int
    duplicates: int
    gate_tested: int
    gate_inside: int
    precision: float = math.nan
    recall: float = math.nan

    def summary(self) -> Dict[str, float]:
        """
        Return the figures by TRACK_KEYS.

        :return: key -> value (NaN where not measured)
        """
        per_100 = 100.0 / self.scans if self.scans else math.nan
        return dict(zip(TRACK_KEYS, (
            len(self.lengths_scans), _percentile(self.lengths_scans, 50),
            _percentile(self.lengths_scans, 90), _percentile(self.lengths_m, 50),
            _percentile(self.lengths_m, 90), self.id_switches * per_100,
            self.duplicates * per_100,
            self.gate_inside / self.gate_tested if self.gate_tested else math.nan,
            self.gate_tested, self.precision, self.recall)))


def _percentile(values: np.ndarray, percent: float) -> float:
    """Return a percentile (NaN without values)."""
    return float(np.percentile(values, percent)) if len(values) else math.nan


def _observations(run: TrackRun, kind: str) -> Dict[int, List[tuple]]:
    """Return per confirmed id its observations: (scan, index among the scan's detections)."""
    out: Dict[int, List[tuple]] = {}
    confirmed = set()
    for t, scan in enumerate(run.tracked):
        identified = scan.corners if kind == 'corner' else scan.lines
        for n, (track, state) in enumerate(zip(identified.ids, identified.states)):
            out.setdefault(int(track), []).append((t, n))
            if state == CONFIRMED:
                confirmed.add(int(track))
    return {track: seen for track, seen in out.items() if track in confirmed}


def _world(run: TrackRun, kind: str, t: int, pose_cov: np.ndarray):
    """Return one scan's landmarks of a kind in the world frame: (values, covs, ends)."""
    found = run.detections[t]
    xy, xy_cov, line, line_cov = world_landmarks(
        found.corner_pose[:, :2], found.corner_cov[:, :2, :2], found.line, found.line_cov,
        run.poses[t], pose_cov)
    if kind == 'corner':
        return xy, xy_cov, np.stack([xy, xy], axis=1)
    return line, line_cov, to_world_points(found.line_ends, run.poses[t])


def _difference(kind: str, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return a - b, the angle of a line wrapped."""
    error = np.asarray(a, dtype=float) - b
    if kind == 'line':
        error[..., 0] = wrap_angle(error[..., 0])
    return error


def _facing(kind: str, value: np.ndarray, cov: np.ndarray, reference: np.ndarray):
    """
    Return a world landmark written as near a reference as it can be: (value, covariance).

    A line (alpha, r) is also the line (alpha + pi, -r). The world frame writes every line
    with r >= 0, so one that passes near the world's origin turns its normal round between two
    observations (alpha -1.54, r 0.01 and alpha 1.58, r 0.13 on ``tuw_gh25_moving``); written
    with its normal within 90 deg of the reference's, the two are compared as one line.
    """
    value = np.asarray(value, dtype=float)
    if kind != 'line' or abs(wrap_angle(value[0] - reference[0])) <= 0.5 * math.pi:
        return value, cov
    turned = np.array([1.0, -1.0])
    return (np.array([wrap_angle(value[0] + math.pi), -value[1]]),
            cov * np.outer(turned, turned))


def _squared(kind: str, a, a_cov, b, b_cov) -> float:
    """Return the squared Mahalanobis distance of two world landmarks."""
    a, a_cov = _facing(kind, a, a_cov, b)
    error = _difference(kind, a, b)
    return float(error @ np.linalg.solve(a_cov + b_cov, error))


def track_figures(run: TrackRun, kind: str, truth: Optional[Truth] = None,
                  pose_sigma_m: float = 0.05, pose_sigma_rad: float = math.radians(1.0)
                  ) -> TrackFigures:
    """
    Measure one kind's tracks of a run.

    :param run: the tracker's run
    :param kind: 'corner' or 'line'
    :param truth: hand labels or simulated truth of the corners, aligned with the scans, or None
    :param pose_sigma_m: the poses' position sigma (each axis), m, for the world-frame tests
    :param pose_sigma_rad: the poses' heading sigma, rad
    :return: the figures
    """
    tracks = _observations(run, kind)
    pose_cov = np.diag([pose_sigma_m ** 2, pose_sigma_m ** 2, pose_sigma_rad ** 2])
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(run.poses[:, :2],
                                                                   axis=0).T))])
    lengths = np.array([seen[-1][0] - seen[0][0] + 1 for seen in tracks.values()], dtype=int)
    metres = np.array([travelled[seen[-1][0]] - travelled[seen[0][0]]
                       for seen in tracks.values()])
    test_gate = chi2_quantile_even(TEST_GATE_PROBABILITY, 2)
    squared = np.concatenate([(scan.corners if kind == 'corner' else scan.lines
                               ).squared_distance for scan in run.tracked] or [np.zeros(0)])
    squared = squared[np.isfinite(squared)]
    world = [_world(run, kind, t, pose_cov) for t in range(len(run.tracked))]
    if truth is not None and kind == 'corner':
        switches, duplicates, precision, recall = _against_truth(run, tracks, truth)
    else:
        switches = _switches(kind, tracks, world)
        duplicates = _duplicates(kind, tracks, world)
        precision = recall = math.nan
    return TrackFigures(kind, len(run.tracked), lengths, metres, switches, duplicates,
                        len(squared), int(np.count_nonzero(squared <= test_gate)), precision,
                        recall)


def _switches(kind: str, tracks: Dict[int, List[tuple]], world: Sequence[tuple]) -> int:
    """Count observations outside the 99.99 % gate of their track's previous one."""
    count = 0
    for seen in tracks.values():
        for (t, n), (u, m) in zip(seen[:-1], seen[1:]):
            if _squared(kind, world[u][0][m], world[u][1][m], world[t][0][n],
                        world[t][1][n]) > TRACK_GATE_2DOF:
                count += 1
    return count


def _duplicates(kind: str, tracks: Dict[int, List[tuple]], world: Sequence[tuple]) -> int:
    """Count pairs of confirmed tracks never seen together whose world means agree."""
    ids = sorted(tracks)
    scans = {i: {t for t, _ in tracks[i]} for i in ids}
    means, covs, ends = {}, {}, {}
    for i in ids:
        reference = world[tracks[i][0][0]][0][tracks[i][0][1]]
        faced = [_facing(kind, world[t][0][n], world[t][1][n], reference) for t, n in tracks[i]]
        # Mean of the differences from the first, so that angles average across +-pi.
        means[i] = reference + _difference(kind, np.array([value for value, _ in faced]),
                                           reference).mean(axis=0)
        covs[i] = np.mean([cov for _, cov in faced], axis=0)
        ends[i] = world[tracks[i][-1][0]][2][tracks[i][-1][1]]
    count = 0
    for a, i in enumerate(ids):
        for j in ids[a + 1:]:
            if scans[i] & scans[j]:
                continue
            if kind == 'line' and not overlapping(ends[i][None], ends[j][None])[0, 0]:
                continue
            if _squared(kind, means[i], covs[i], means[j], covs[j]) <= TRACK_GATE_2DOF:
                count += 1
    return count


def _against_truth(run: TrackRun, tracks: Dict[int, List[tuple]], truth: Truth):
    """Return (id switches, duplicates, precision, recall) of the corner tracks."""
    labels = []
    for t, found in enumerate(run.detections):
        truth_xy, _ = truth.at(t)
        labels.append(match_detections(found.corner_pose[:, :2], found.corner_cov[:, :2, :2],
                                       truth_xy))
    switches, majority = 0, {}
    for track, seen in tracks.items():
        matched = [int(labels[t][n]) for t, n in seen if labels[t][n] >= 0]
        switches += sum(a != b for a, b in zip(matched[:-1], matched[1:]))
        majority[track] = (max(set(matched), key=matched.count)
                           if len(matched) * 2 > len(seen) else -1)
    true_tracks = [label for label in majority.values() if label >= 0]
    duplicates = len(true_tracks) - len(set(true_tracks))
    visible = {m for t in range(len(run.detections)) for m in np.flatnonzero(truth.at(t)[1])}
    precision = len(true_tracks) / len(majority) if majority else math.nan
    recall = len(visible & set(true_tracks)) / len(visible) if visible else math.nan
    return switches, duplicates, precision, recall


def track_lines(figures: Sequence[TrackFigures]) -> List[str]:
    """
    Return the figures as text lines.

    :param figures: one TrackFigures per kind
    :return: one line per kind
    """
    text = []
    for f in figures:
        s = f.summary()
        text.append(
            f'{f.kind}: {s["confirmed_tracks"]} confirmed tracks, length median '
            f'{s["length_scans_median"]:g} scans ({s["length_m_median"]:.2f} m), p90 '
            f'{s["length_scans_p90"]:g} scans ({s["length_m_p90"]:.2f} m); id switches '
            f'{s["id_switches_per_100_scans"]:.2f} and duplicates '
            f'{s["duplicates_per_100_scans"]:.2f} per 100 scans; inside the 95 % gate '
            f'{100 * s["gate_share"]:.1f} % of {s["gate_tested"]}; precision '
            f'{s["precision"]:.3f}, recall {s["recall"]:.3f}')
    return text
