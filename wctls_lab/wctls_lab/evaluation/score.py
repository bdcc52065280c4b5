# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The yardstick: real corners among the reported, reported among the real, honest covariances.

Everything is measured per method (or configuration).

With truth (a simulation's ``truth.yaml`` or hand labels, :mod:`.truth`), per scan:

- a reported corner and a true corner **match** when their distance is at most
  max(3 sigma, 5 cm), sigma the reported 1-sigma major semi-axis of the corner's position
  covariance; pairs are matched greedily, nearest first, one to one. 3 sigma of the major axis
  holds a calibrated estimate at least 98.9 % of the time (chi2, 2 dof); the 5 cm floor keeps an
  overconfident corner at the right place counted as the right corner, and its NEES then shows
  the overconfidence: "is it that corner" and "is its covariance honest" stay two questions;
- **precision** = matched detections / detections. A detection may match any true corner, also
  one that the visibility rule (8 returns and 15 cm on each wall...) calls not visible in that
  scan: a real corner found from less evidence is not a false corner;
- **recall** = matched visible true corners / visible true corners, pooled over the scans;
- **false per scan** = unmatched detections / scans, next to detections per scan;
- **NEES against truth** = e^T C^-1 e of every matched detection (e = reported minus true
  position, C its 2x2 position covariance): mean (2 when calibrated) and median (1.39);
- per true corner, its **detection rate** = scans where it is matched / scans where it is
  visible (hand-labelled corners are visible in every scan the labels cover).

On any static recording, with or without truth:

- detections are clustered across scans by :func:`~.rules.associate` (greedy seeds,
  gate 5 predicted sigmas clamped to 2-25 cm, one detection per scan and cluster);
  **recurrence** = share of all detections that belong to a cluster present in at least 90 %
  of the scans (``min_presence``);
- per such recurring corner, its **NEES against its mean** position over the scans (2 when
  calibrated), as ``evaluate`` computes it.

Pure functions (numpy, matplotlib Agg for the figure); :func:`score_scans` is what the ``score``
command, the tests and tuning scripts call.
"""

import csv
from dataclasses import dataclass
import math
import pathlib
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from wctls_ros.core import ellipse, FeatureConfig, nees
from wctls_ros.frontend.frames import landmarks_from_features

from .analysis import corner_stats, features_per_scan
from .reobservation import measure, Reobservation, REOBSERVATION_KEYS
from .rules import assign, associate, check_still
from .samples import ScanCorners
from .scans import StaticScans
from .truth import Truth

# A reported corner matches a true one within max(MATCH_SIGMAS sigma_major, MATCH_FLOOR_M).
MATCH_SIGMAS = 3.0
MATCH_FLOOR_M = 0.05
# A corner recurs when found in at least this share of the scans.
RECURRING_PRESENCE = 0.9
# A labelled corner counts as reliably found at this detection rate (the real data's bar).
RELIABLE_RATE = 0.95
# Scans the figure shows at most.
FIGURE_SCANS = 3


@dataclass(frozen=True)
class TrueCornerRate:
    """
    How often one method found one true corner.

    :ivar corner_id: the corner's id in the truth
    :ivar kind: 'inside' or 'outside'
    :ivar xy_m: its position in the first scan that has it, m
    :ivar visible_scans: scans in which it is visible
    :ivar found_scans: of those, scans in which a detection matched it
    """

    corner_id: int
    kind: str
    xy_m: np.ndarray
    visible_scans: int
    found_scans: int

    @property
    def rate(self) -> float:
        """
        Return the detection rate.

        :return: found / visible scans (NaN when never visible)
        """
        return self.found_scans / self.visible_scans if self.visible_scans else math.nan


@dataclass(frozen=True)
class RecurringCorner:
    """
    A corner one method reports in most scans of a static recording.

    :ivar xy_m: mean position over the scans that have it, m
    :ivar scans: scans in which it was found
    :ivar presence: share of the scans in which it was found
    :ivar nees: mean NEES of its detections against its mean position (2 when calibrated)
    """

    xy_m: np.ndarray
    scans: int
    presence: float
    nees: float


@dataclass(frozen=True)
class MethodScore:
    """
    Everything the score measured for one method (or configuration).

    :ivar method: its label
    :ivar detections: detections in each scan, shape (T,)
    :ivar false: unmatched detections in each scan, shape (T,); None without truth
    :ivar visible: visible true corners over all scans (0 without truth)
    :ivar found: of those, matched ones
    :ivar nees_truth: NEES against truth of every matched detection, shape (D,)
    :ivar corner_rates: per true corner, its detection rate (empty without truth)
    :ivar recurring: the recurring corners; None when the recording is not static
    :ivar recurrent_detections: detections that belong to a recurring corner
    :ivar per_scan: the detections of every scan
    :ivar labels: per scan, for each detection, the index of the true corner it matched (with
        truth) or of the recurring corner it belongs to (without), -1 for none
    :ivar reobservation: the re-observation consistency of its corners and lines, and the
        landmarks per scan (:mod:`.reobservation`), or None when not measured
    """

    method: str
    detections: np.ndarray
    false: Optional[np.ndarray]
    visible: int
    found: int
    nees_truth: np.ndarray
    corner_rates: Tuple[TrueCornerRate, ...]
    recurring: Optional[Tuple[RecurringCorner, ...]]
    recurrent_detections: int
    per_scan: List[ScanCorners]
    labels: List[np.ndarray]
    reobservation: Optional[Reobservation] = None

    @property
    def precision(self) -> float:
        """
        Return matched detections / detections.

        :return: the precision (NaN without truth or without detections)
        """
        total = int(self.detections.sum())
        if self.false is None or not total:
            return math.nan
        return 1.0 - float(self.false.sum()) / total

    @property
    def recall(self) -> float:
        """
        Return matched visible true corners / visible true corners.

        :return: the recall (NaN without truth)
        """
        return self.found / self.visible if self.visible else math.nan

    @property
    def recurrence(self) -> float:
        """
        Return the share of detections that belong to a recurring corner.

        :return: the recurrence (NaN when not static or without detections)
        """
        total = int(self.detections.sum())
        if self.recurring is None or not total:
            return math.nan
        return self.recurrent_detections / total

    def summary(self) -> Dict[str, float]:
        """
        Return the table's figures for this method.

        :return: name -> value (NaN where not measured)
        """
        rates = np.array([c.rate for c in self.corner_rates if c.visible_scans])
        recurring = self.recurring or ()
        weights = np.array([c.scans for c in recurring])
        values = np.array([c.nees for c in recurring])
        with np.errstate(invalid='ignore'):
            pooled = float(np.sum(weights * values) / weights.sum()) if recurring else math.nan
        return {
            'scans': len(self.detections),
            'detections_per_scan': float(np.mean(self.detections)),
            'false_per_scan': float(np.mean(self.false)) if self.false is not None else math.nan,
            'precision': self.precision,
            'recall': self.recall,
            'matched': len(self.nees_truth),
            'nees_truth_mean': float(np.mean(self.nees_truth)) if len(self.nees_truth)
            else math.nan,
            'nees_truth_median': float(np.median(self.nees_truth)) if len(self.nees_truth)
            else math.nan,
            'true_corners': len(rates),
            'reliable_corners': int(np.sum(rates >= RELIABLE_RATE)),
            'min_corner_rate': float(np.min(rates)) if len(rates) else math.nan,
            'recurrence': self.recurrence,
            'recurring_corners': len(recurring) if self.recurring is not None else math.nan,
            'nees_vs_mean_pooled': pooled,
            'nees_vs_mean_median': float(np.median(values)) if recurring else math.nan,
            **(self.reobservation.summary() if self.reobservation is not None
               else dict.fromkeys(REOBSERVATION_KEYS, math.nan)),
        }


@dataclass(frozen=True)
class ScoreTable:
    """
    The score of every method on one recording.

    :ivar methods: one MethodScore per method, in the order given
    :ivar scans: the scans scored
    :ivar truth: their truth (aligned with the scans), or None
    :ivar static: whether the recording counted as static (recurrence measured)
    """

    methods: Tuple[MethodScore, ...]
    scans: StaticScans
    truth: Optional[Truth]
    static: bool


def match_detections(xy_m: np.ndarray, covariance: np.ndarray,
                     truth_xy_m: np.ndarray) -> np.ndarray:
    """
    Match one scan's detections to its true corners, nearest pair first, one to one.

    :param xy_m: detections, shape (C, 2), m
    :param covariance: their position covariances, shape (C, 2, 2), m^2
    :param truth_xy_m: true corners, shape (M, 2), m (NaN rows never match)
    :return: for each detection the index of its true corner, -1 when none, shape (C,)
    """
    xy = np.asarray(xy_m, dtype=float).reshape(-1, 2)
    truth = np.asarray(truth_xy_m, dtype=float).reshape(-1, 2)
    out = np.full(len(xy), -1, dtype=np.intp)
    if not len(xy) or not len(truth):
        return out
    gate = np.maximum(MATCH_SIGMAS * ellipse(np.asarray(covariance).reshape(-1, 2, 2)
                                             ).semi_major, MATCH_FLOOR_M)
    distance = np.hypot(*(xy[:, None, :] - truth[None]).transpose(2, 0, 1))
    with np.errstate(invalid='ignore'):
        pairs = np.argwhere(distance <= gate[:, None])
    taken = np.zeros(len(truth), dtype=bool)
    for i, m in pairs[np.argsort(distance[pairs[:, 0], pairs[:, 1]], kind='stable')]:
        if out[i] < 0 and not taken[m]:
            out[i] = m
            taken[m] = True
    return out


def _truth_scores(per_scan: List[ScanCorners], truth: Truth):
    """Return (labels, false (T,), visible, found, nees, corner rates) against the truth."""
    labels, false, nees_values = [], [], []
    visible_count = np.zeros(len(truth.ids), dtype=int)
    found_count = np.zeros(len(truth.ids), dtype=int)
    for t, corners in enumerate(per_scan):
        truth_xy, visible = truth.at(t)
        match = match_detections(corners.xy, corners.covariance, truth_xy)
        matched = match >= 0
        labels.append(match)
        false.append(int(np.sum(~matched)))
        if matched.any():
            nees_values.append(nees(corners.xy[matched] - truth_xy[match[matched]],
                                    corners.covariance[matched]))
        visible_count += visible
        found = np.zeros(len(truth.ids), dtype=bool)
        found[match[matched]] = True
        found_count += visible & found
    first = [np.flatnonzero(np.isfinite(truth.xy_m[:, m, 0]))[0] for m in range(len(truth.ids))]
    rates = tuple(TrueCornerRate(int(i), kind, truth.xy_m[row, m], int(v), int(f))
                  for m, (i, kind, row, v, f) in enumerate(zip(
                      truth.ids, truth.kinds, first, visible_count, found_count)))
    return (labels, np.array(false), int(visible_count.sum()), int(found_count.sum()),
            np.concatenate(nees_values) if nees_values else np.zeros(0), rates)


def _recurrence(per_scan: List[ScanCorners], min_presence: float):
    """Return (labels, recurring corners, recurrent detections) of one method's detections."""
    count = len(per_scan)
    centers, radii = associate(per_scan, min_presence)
    assignment = assign(per_scan, centers, radii)                  # (T, K)
    present = (assignment >= 0).sum(axis=0)
    keep = np.flatnonzero(present >= max(1, math.ceil(min_presence * count)))
    labels = [np.full(len(c), -1, dtype=np.intp) for c in per_scan]
    recurring = []
    for n, k in enumerate(keep):
        hits = [(t, i) for t, i in enumerate(assignment[:, k]) if i >= 0]
        for t, i in hits:
            labels[t][i] = n
        xy = np.array([per_scan[t].xy[i] for t, i in hits])
        covariance = np.array([per_scan[t].covariance[i] for t, i in hits])
        stats = corner_stats(xy, covariance)
        recurring.append(RecurringCorner(stats.mean_xy, stats.count, stats.count / count,
                                         stats.nees))
    return labels, tuple(recurring), int(present[keep].sum())


def score_detections(method: str, per_scan: List[ScanCorners], truth: Optional[Truth] = None,
                     static: bool = True, min_presence: float = RECURRING_PRESENCE,
                     reobservation: Optional[Reobservation] = None) -> MethodScore:
    """
    Score one method's detections.

    :param method: its label
    :param per_scan: its detections in every scan
    :param truth: the true corners of those scans (aligned: scan t of the truth is per_scan[t]),
        or None
    :param static: measure recurrence (the scans come from a still sensor in a still scene)
    :param min_presence: share of the scans a recurring corner is found in, at least
    :param reobservation: the re-observation figures of its corners and lines, or None
    :return: the score
    """
    detections = np.array([len(c) for c in per_scan], dtype=int)
    labels, recurring, recurrent = (_recurrence(per_scan, min_presence) if static
                                    else (None, None, 0))
    if truth is None:
        return MethodScore(method, detections, None, 0, 0, np.zeros(0), (), recurring,
                           recurrent, per_scan, labels or [np.full(n, -1) for n in detections],
                           reobservation)
    labels, false, visible, found, nees_values, rates = _truth_scores(per_scan, truth)
    return MethodScore(method, detections, false, visible, found, nees_values, rates, recurring,
                       recurrent, per_scan, labels, reobservation)


def score_scans(scans: StaticScans, configs: Mapping[str, FeatureConfig],
                truth: Optional[Truth] = None, static: Optional[bool] = None,
                min_presence: float = RECURRING_PRESENCE, poses: Optional[np.ndarray] = None,
                pose_sigma_m: float = 0.0, pose_sigma_rad: float = 0.0) -> ScoreTable:
    """
    Run every configuration over the scans and score its corners and lines.

    :param scans: the scans
    :param configs: label (usually the method's name) -> pipeline configuration
    :param truth: the true corners, aligned with the scans (see :meth:`Truth.select`), or None
    :param static: measure recurrence; None: when :func:`~.rules.check_still` says still
    :param min_presence: share of the scans a recurring corner is found in, at least
    :param poses: the sensor pose of each scan (x m, y m, yaw rad), shape (T, 3), NaN rows
        where unknown, or None: the re-observations are then tested without poses only
    :param pose_sigma_m: the poses' position sigma (each axis), m
    :param pose_sigma_rad: the poses' heading sigma, rad
    :return: the table
    :raises ValueError: when the truth does not have one row per scan where it needs one
    """
    if truth is not None and truth.covered(len(scans)) != (0, len(scans) - 1):
        raise ValueError(f'the truth covers scans {truth.first_scan}-{truth.last_scan} of '
                         f'{len(scans)}: score those (Truth.select) or give truth for all')
    static = check_still(scans).still if static is None else static
    methods = []
    for label, config in configs.items():
        extracted = features_per_scan(scans, config)
        per_scan = [corners for _, corners in extracted]
        landmarks = [landmarks_from_features(features, config.max_landmark_angle_sigma_rad)
                     for features, _ in extracted]
        reobserved = measure(landmarks, poses, pose_sigma_m, pose_sigma_rad)
        methods.append(score_detections(label, per_scan, truth, static, min_presence,
                                        reobserved))
    return ScoreTable(tuple(methods), scans, truth, static)


# Columns of the table: key, heading, format.
COLUMNS = (
    ('method', 'method', '{}'),
    ('scans', 'scans', '{:d}'),
    ('detections_per_scan', 'detections / scan', '{:.2f}'),
    ('landmarks_per_scan', 'landmarks (corners + line landmarks) / scan', '{:.2f}'),
    ('false_per_scan', 'false / scan', '{:.2f}'),
    ('precision', 'precision', '{:.3f}'),
    ('recall', 'recall', '{:.3f}'),
    ('nees_truth_mean', 'NEES vs truth mean', '{:.2f}'),
    ('nees_truth_median', 'NEES vs truth median', '{:.2f}'),
    ('reliable_corners', f'seen true corners found in >= {RELIABLE_RATE:.0%} of scans', '{}'),
    ('min_corner_rate', 'lowest detection rate', '{:.2f}'),
    ('recurrence', 'recurrence', '{:.3f}'),
    ('recurring_corners', 'recurring corners', '{:d}'),
    ('nees_vs_mean_pooled', 'NEES vs mean pooled', '{:.2f}'),
    ('nees_vs_mean_median', 'NEES vs mean, median corner', '{:.2f}'),
)


# Columns of the re-observation table (:mod:`.reobservation`): key, heading, format.
REOBSERVATION_COLUMNS = (
    ('method', 'method', '{}'),
    ('landmarks_per_scan', 'landmarks / scan', '{:.2f}'),
    ('lines_per_scan', 'line landmarks / scan', '{:.2f}'),
    ('corner_distance_in_gate', 'corner distances in 95 % gate', '{:.3f}'),
    ('line_angle_in_gate', 'line angles in 95 % gate', '{:.3f}'),
    ('corner_line_distance_in_gate', 'corner-line distances in 95 % gate', '{:.3f}'),
    ('corner_tracks_in_gate', 'corners in 95 % gate (poses)', '{:.3f}'),
    ('line_tracks_in_gate', 'line landmarks in 95 % gate (poses)', '{:.3f}'),
    ('corner_track_median', 'corner track, median scans', '{:g}'),
    ('corner_track_p90', 'corner track, p90 scans', '{:g}'),
    ('line_track_median', 'line track, median scans', '{:g}'),
    ('line_track_p90', 'line track, p90 scans', '{:g}'),
)


def table_rows(table: ScoreTable) -> List[dict]:
    """
    Return one row of figures per method.

    :param table: the score
    :return: dicts with the COLUMNS keys (NaN where not measured)
    """
    return [dict(method=m.method, **m.summary()) for m in table.methods]


def _cell(row: dict, key: str, fmt: str) -> str:
    value = row[key]
    if key == 'reliable_corners':
        return f'{value} of {row["true_corners"]}' if row['true_corners'] else '-'
    if isinstance(value, float) and math.isnan(value):
        return '-'
    return fmt.format(int(value) if fmt == '{:d}' else value)


def markdown_table(table: ScoreTable, columns=COLUMNS) -> str:
    """
    Return the per-method table as Markdown.

    :param table: the score
    :param columns: the columns (key, heading, format): COLUMNS, or REOBSERVATION_COLUMNS for
        the re-observation table
    :return: the table's text
    """
    lines = ['| ' + ' | '.join(heading for _, heading, _ in columns) + ' |',
             '|' + '---|' * len(columns)]
    for row in table_rows(table):
        lines.append('| ' + ' | '.join(_cell(row, key, fmt) for key, _, fmt in columns) + ' |')
    return '\n'.join(lines)


def corner_rows(table: ScoreTable) -> List[list]:
    """
    Return the per-corner figures: true corners' detection rates and recurring corners' NEES.

    :param table: the score
    :return: rows [method, what ('true' or 'recurring'), id, kind, x m, y m, scans, found or
        presence, rate or NEES vs mean]
    """
    rows = []
    for m in table.methods:
        rows += [[m.method, 'true', c.corner_id, c.kind, float(c.xy_m[0]), float(c.xy_m[1]),
                  c.visible_scans, c.found_scans, c.rate] for c in m.corner_rates]
        rows += [[m.method, 'recurring', n, '', float(c.xy_m[0]), float(c.xy_m[1]), c.scans,
                  c.presence, c.nees] for n, c in enumerate(m.recurring or ())]
    return rows


def _figure_scans(table: ScoreTable) -> List[int]:
    """Return the scans the figure shows: the first, the worst (most false), the last."""
    count = len(table.scans)
    unexplained = sum(np.array([np.sum(labels < 0) for labels in m.labels])
                      for m in table.methods)
    chosen = [0, int(np.argmax(unexplained)), count - 1]
    return sorted(set(chosen))[:FIGURE_SCANS]


def draw_figure(table: ScoreTable, path, title: str = '') -> pathlib.Path:
    """
    Draw a few scans per method with true corners, matched and false detections.

    :param table: the score
    :param path: the PNG to write
    :param title: the figure's title
    :return: the path written
    """
    from ..plotting import pyplot
    plt = pyplot()
    shown = _figure_scans(table)
    rows, cols = len(shown), len(table.methods)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    bearings = table.scans.bearings
    for r, t in enumerate(shown):
        ranges = table.scans.ranges[t]
        valid = table.scans.valid()[t]
        for c, m in enumerate(table.methods):
            ax = axes[r, c]
            ax.plot(ranges[valid] * np.cos(bearings[valid]),
                    ranges[valid] * np.sin(bearings[valid]), '.', color='0.65', ms=1.0)
            if table.truth is not None:
                truth_xy, visible = table.truth.at(t)
                ax.plot(*truth_xy[visible].T, 'o', mfc='none', mec='tab:green', ms=9,
                        label='true corner, visible')
                ax.plot(*truth_xy[~visible].T, 'o', mfc='none', mec='0.75', ms=7,
                        label='true corner, not visible')
            elif m.recurring:
                ax.plot(*np.array([k.xy_m for k in m.recurring]).T, 'o', mfc='none',
                        mec='tab:green', ms=9, label='recurring corner (mean)')
            xy, good = m.per_scan[t].xy, m.labels[t] >= 0
            ax.plot(*xy[good].T, '+', color='tab:blue', ms=8, mew=1.5,
                    label='matched' if table.truth is not None else 'recurring')
            ax.plot(*xy[~good].T, 'x', color='tab:red', ms=7, mew=1.5,
                    label='false' if table.truth is not None else 'not recurring')
            ax.plot(0.0, 0.0, '*', color='black', ms=7)
            ax.set_title(f'{m.method}, scan {t}: {len(xy)} reported, {int(np.sum(~good))} '
                         f'{"false" if table.truth is not None else "not recurring"}',
                         fontsize=9)
            ax.set_aspect('equal')
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7, loc='best')
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = pathlib.Path(path)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def write_score(table: ScoreTable, out, title: str, command: str,
                notes: Sequence[str] = ()) -> pathlib.Path:
    """
    Write table.md (the score and re-observation tables), table.csv, corners.csv and score.png.

    :param table: the score
    :param out: the folder (created)
    :param title: the report's title
    :param command: the command that produced it (quoted in table.md)
    :param notes: lines to list under the command (noise model, truth source, ...)
    :return: the path of table.md
    """
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = table_rows(table)
    with open(out / 'table.csv', 'w', newline='') as stream:
        writer = csv.writer(stream)
        keys = [key for key, _, _ in COLUMNS] + ['true_corners', 'matched']
        keys += [key for key, _, _ in REOBSERVATION_COLUMNS if key not in keys]
        writer.writerow(keys)
        writer.writerows([[row[k] for k in keys] for row in rows])
    corners = corner_rows(table)
    with open(out / 'corners.csv', 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['method', 'what', 'id', 'kind', 'x_m', 'y_m', 'scans',
                         'found_scans_or_presence', 'rate_or_nees_vs_mean'])
        writer.writerows(corners)
    draw_figure(table, out / 'score.png', title)
    text = [f'# {title}', '', '    ' + command, '']
    text += [f'- {note}' for note in notes]
    text += ['', markdown_table(table), '', 'Re-observations of the corners and lines '
             '(wctls_lab.evaluation.reobservation):', '',
             markdown_table(table, REOBSERVATION_COLUMNS), '', '![scans](score.png)', '']
    (out / 'table.md').write_text('\n'.join(text))
    return out / 'table.md'
