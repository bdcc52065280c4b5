# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The paper's repeatability analysis, and the consistency check it lacks, on repeated scans.

Every method sees the same scans; its corners are associated across scans (clusters of corner
positions present in most scans), and for each associated corner the analysis compares the
propagated covariance with the real scan-to-scan scatter: the ratio of the ellipse areas and
the normalised estimation error squared (NEES, expected 2 for a calibrated 2-D estimate; the
error is taken from the corner's mean over the scans, which has no ground truth to need).
"""

from dataclasses import dataclass, field
import math
from typing import Dict, List, Sequence

import numpy as np

from .samples import feature_config, NoiseParameters, scan_corners, ScanCorners
from .scans import StaticScans
from ..core import ellipse, FeatureConfig, nees

PROPAGATIONS = ('full', 'diagonal')
# Association gate: this many predicted sigmas (of the corner's major axis) around a cluster...
_GATE_SIGMAS = 5.0
# ... but never tighter or wider than these, m.
_GATE_MIN_M = 0.02
_GATE_MAX_M = 0.25
# Relative width of the rim of a gate where _within_gates asks np.hypot.
_RIM = 1e-12


@dataclass(frozen=True)
class CornerStats:
    """
    One associated corner under one method: propagated versus empirical covariance.

    :ivar count: scans in which the method found the corner
    :ivar mean_xy: mean position over those scans, m
    :ivar empirical_cov: covariance of the position across the scans, m^2
    :ivar propagated_cov: mean of the per-scan propagated covariances, m^2
    :ivar area_ratio: propagated over empirical 1-sigma ellipse area
    :ivar nees: mean NEES over the scans (expected 2 when calibrated)
    """

    count: int
    mean_xy: np.ndarray
    empirical_cov: np.ndarray
    propagated_cov: np.ndarray
    area_ratio: float
    nees: float


@dataclass
class Evaluation:
    """
    Everything the report shows for one set of repeated scans.

    :ivar scans: the scans
    :ivar noise: the noise model the covariances use
    :ivar methods: the methods compared
    :ivar propagation: 'full' (correct) or 'diagonal' (line covariances' off-diagonal dropped)
    :ivar per_scan: method -> one ScanCorners per scan
    :ivar centers: associated corners' positions (mean of the reference method), (K, 2), m,
        numbered clockwise from the sensor's +x axis as in the paper
    :ivar assignment: method -> (T, K) index of the corner in each scan, -1 where missing
    :ivar stats: method -> one CornerStats per associated corner
    :ivar representative: the scan the tables and the figure show
    """

    scans: StaticScans
    noise: NoiseParameters
    methods: Sequence[str]
    propagation: str
    per_scan: Dict[str, List[ScanCorners]]
    centers: np.ndarray
    assignment: Dict[str, np.ndarray]
    stats: Dict[str, List[CornerStats]] = field(default_factory=dict)
    representative: int = 0

    def scan_median_areas(self, method: str) -> np.ndarray:
        """
        Return the median 1-sigma ellipse area of the corners of each scan (the paper's Fig. 4).

        :param method: one of the methods
        :return: shape (T,), mm^2 (NaN for a scan without corners)
        """
        areas = []
        for corners in self.per_scan[method]:
            covariance = corners.covariances(self.propagation)
            areas.append(float(np.median(ellipse(covariance).area)) * 1e6
                         if len(corners) else math.nan)
        return np.array(areas)

    def pooled_nees(self, method: str) -> float:
        """
        Return the mean NEES over every associated corner in every scan.

        :param method: one of the methods
        :return: the mean (2 when calibrated)
        """
        total = sum(s.nees * s.count for s in self.stats[method])
        count = sum(s.count for s in self.stats[method])
        return total / count if count else math.nan


def run_methods(scans: StaticScans, noise: NoiseParameters, methods: Sequence[str],
                base: FeatureConfig = None) -> Dict[str, List[ScanCorners]]:
    """
    Extract every scan's corners with every method.

    :param scans: the scans
    :param noise: the noise model
    :param methods: the methods
    :param base: the pipeline's other settings (defaults: the paper's)
    :return: method -> one ScanCorners per scan
    """
    return {method: corners_per_scan(scans, feature_config(noise, method, base))
            for method in methods}


def features_per_scan(scans: StaticScans, config: FeatureConfig) -> list:
    """
    Extract every scan's features and corners with one configuration.

    :param scans: the scans
    :param config: the pipeline configuration (method and noise model)
    :return: one (the core's Features, ScanCorners) per scan
    """
    return [scan_corners(ranges, scans.angle_min, scans.angle_increment, scans.range_min,
                         scans.range_max, config) for ranges in scans.ranges]


def corners_per_scan(scans: StaticScans, config: FeatureConfig) -> List[ScanCorners]:
    """
    Extract every scan's corners with one configuration.

    :param scans: the scans
    :param config: the pipeline configuration (method and noise model)
    :return: one ScanCorners per scan
    """
    return [corners for _, corners in features_per_scan(scans, config)]


def associate(per_scan: List[ScanCorners], min_presence: float):
    """
    Find the corners present in most scans by clustering their positions across scans.

    Greedy: the corner with the most scans holding a corner within its gate (5 predicted sigmas,
    2-25 cm) seeds a cluster, which takes the nearest corner of each scan within the gate; its
    members are removed and the next seed is chosen, until no seed reaches ``min_presence``.
    Ties go to the corner found first (scan order, then the scan's order). The clusters' mean
    positions are then refined once by reassigning every scan's corners.

    Memory grows with the number of corners, not with its square: the corners are binned into
    cells (:class:`_Cells`), and only neighbouring cells are compared.

    :param per_scan: one method's corners per scan
    :param min_presence: keep corners found in at least this fraction of the scans
    :return: (centers (K, 2) m, gates (K,) m)
    """
    count = len(per_scan)
    xy = np.concatenate([c.xy for c in per_scan]) if count else np.zeros((0, 2))
    scan_of = np.concatenate([np.full(len(c), t) for t, c in enumerate(per_scan)]
                             ).astype(np.intp) if count else np.zeros(0, np.intp)
    cov = np.concatenate([c.covariance for c in per_scan]) if count else np.zeros((0, 2, 2))
    gates = np.clip(_GATE_SIGMAS * ellipse(cov).semi_major, _GATE_MIN_M, _GATE_MAX_M)
    cells = _Cells(xy)
    free = np.ones(len(xy), dtype=bool)
    support = np.zeros(len(xy), dtype=np.intp)
    for cell in cells.occupied():
        support[cell] = cells.support(cell, xy, gates, scan_of, free)
    centers, radii = [], []
    needed = max(1, int(math.ceil(min_presence * count)))
    while free.any():
        seed = int(np.argmax(support))
        if support[seed] < needed:
            break
        candidates = cells.around(xy[seed], free)
        distance = np.hypot(xy[seed, 0] - xy[candidates, 0], xy[seed, 1] - xy[candidates, 1])
        inside = distance <= gates[seed]
        members = _nearest_per_scan(candidates[inside], distance[inside], scan_of)
        taken = np.append(members, seed)
        free[taken] = False
        support[taken] = 0
        for cell in cells.next_to(xy[taken]):
            rows = cell[free[cell]]
            support[rows] = cells.support(rows, xy, gates, scan_of, free)
        centers.append(xy[members].mean(axis=0))
        radii.append(gates[seed])
    centers = np.array(centers).reshape(-1, 2)
    radii = np.array(radii)
    if len(centers):
        assignment = assign(per_scan, centers, radii)
        for k in range(len(centers)):
            hits = [per_scan[t].xy[i] for t, i in enumerate(assignment[:, k]) if i >= 0]
            centers[k] = np.mean(hits, axis=0)
    order = np.argsort(np.mod(-np.arctan2(centers[:, 1], centers[:, 0]), 2 * math.pi),
                       kind='stable')
    return centers[order], radii[order]


class _Cells:
    """
    Corner positions binned into square cells twice the widest gate across.

    Two corners within a gate of each other lie in the same cell or in neighbouring ones, so the
    distances :func:`associate` needs are those between neighbouring cells: for a static scene,
    each true corner's positions against themselves, never every corner against every other.
    Positions that are not finite are in no cell (they are within no gate).
    """

    SIZE_M = 2 * _GATE_MAX_M
    # Distances computed at once at most: bounds the memory a crowded cell takes.
    BLOCK = 1 << 21

    def __init__(self, xy: np.ndarray):
        """
        Bin the positions.

        :param xy: positions, shape (N, 2), m (rows that are not finite are left out)
        """
        finite = np.flatnonzero(np.isfinite(xy).all(axis=1))
        keys = np.floor(xy[finite] / self.SIZE_M).astype(np.int64)
        order = np.lexsort((finite, keys[:, 1], keys[:, 0]))
        keys, members = keys[order], finite[order]
        starts = np.flatnonzero(np.r_[True, (keys[1:] != keys[:-1]).any(axis=1)])[:len(keys)]
        # cell (i, j) -> its positions' indices, ascending
        self._members = {tuple(key): group for key, group in
                         zip(keys[starts].tolist(), np.split(members, starts[1:]))}

    def occupied(self):
        """
        Yield the indices of the positions of each cell that holds any.

        :return: an iterator of index arrays, ascending
        """
        return iter(self._members.values())

    def _neighbourhood(self, key) -> np.ndarray:
        """Return the indices of the positions in a cell and its eight neighbours, ascending."""
        i, j = key
        groups = [self._members[(i + di, j + dj)] for di in (-1, 0, 1) for dj in (-1, 0, 1)
                  if (i + di, j + dj) in self._members]
        return np.sort(np.concatenate(groups))

    def _key(self, xy: np.ndarray):
        return tuple(np.floor(xy / self.SIZE_M).astype(np.int64).tolist())

    def around(self, xy: np.ndarray, free: np.ndarray) -> np.ndarray:
        """
        Return the free positions that can be within a gate of a point, ascending.

        :param xy: the point, shape (2,), m (finite)
        :param free: which positions are still free, shape (N,)
        :return: indices
        """
        candidates = self._neighbourhood(self._key(xy))
        return candidates[free[candidates]]

    def next_to(self, xy: np.ndarray):
        """
        Yield the cells (their positions' indices) next to any of some points, each once.

        :param xy: the points, shape (n, 2), m (finite)
        :return: an iterator of index arrays
        """
        keys = np.unique(np.floor(xy / self.SIZE_M).astype(np.int64), axis=0).tolist()
        near = {(i + di, j + dj) for i, j in keys for di in (-1, 0, 1) for dj in (-1, 0, 1)}
        return (self._members[key] for key in sorted(near) if key in self._members)

    def support(self, rows: np.ndarray, xy: np.ndarray, gates: np.ndarray,
                scan_of: np.ndarray, free: np.ndarray) -> np.ndarray:
        """
        Count, for positions of one cell, the scans with a free position within their gate.

        :param rows: positions of one cell, indices
        :param xy: all positions, shape (N, 2), m
        :param gates: their gates, shape (N,), m
        :param scan_of: their scans, shape (N,), non-decreasing
        :param free: which are still free, shape (N,)
        :return: the count of each row (0 for a row that is not free), shape (len(rows),)
        """
        counts = np.zeros(len(rows), dtype=np.intp)
        if not len(rows):
            return counts
        candidates = self.around(xy[rows[0]], free)
        if not len(candidates):
            return counts
        # The candidates ascend, so each scan's are consecutive. Those alone in their scan
        # count one each; the scans with several (a few) need a reduction, which is slower:
        # the lone ones go first, the others after them, still by scan.
        scan_starts = np.flatnonzero(np.r_[True, np.diff(scan_of[candidates]) != 0])
        sizes = np.diff(np.r_[scan_starts, len(candidates)])
        alone = np.repeat(sizes == 1, sizes)
        lone = np.count_nonzero(alone)
        candidates = np.concatenate([candidates[alone], candidates[~alone]])
        shared_starts = np.cumsum(np.r_[0, sizes[sizes > 1][:-1]])
        step = max(1, self.BLOCK // len(candidates))
        for first in range(0, len(rows), step):
            block = rows[first:first + step]
            within = _within_gates(xy[block, 0, None] - xy[candidates, 0],
                                   xy[block, 1, None] - xy[candidates, 1], gates[block, None])
            counts[first:first + step] = np.count_nonzero(within[:, :lone], axis=1)
            if lone < len(candidates):
                counts[first:first + step] += np.count_nonzero(np.logical_or.reduceat(
                    within[:, lone:], shared_starts, axis=1), axis=1)
        counts[~free[rows]] = 0
        return counts


def _within_gates(dx: np.ndarray, dy: np.ndarray, gates: np.ndarray) -> np.ndarray:
    """
    Return whether hypot(dx, dy) <= gates, elementwise, computing hypot only where it matters.

    np.hypot takes ~60 ns an element; the squared distance against the squared gate, with a
    margin of 1e-12 (rounding errs by 1e-16), decides all but the pairs at the very rim, and
    hypot decides those: the same answer as hypot everywhere, NaN included.

    :param dx: differences in x, m
    :param dy: differences in y (the shape of dx), m
    :param gates: the gates, broadcast against dx, m
    :return: the comparison, the shape of dx
    """
    squared = dx * dx + dy * dy
    limit = gates * gates
    within = squared <= limit * (1.0 - _RIM)
    rim = ~within & ~(squared > limit * (1.0 + _RIM))
    if rim.any():
        gate = np.broadcast_to(gates, dx.shape)[rim]
        within[rim] = np.hypot(dx[rim], dy[rim]) <= gate
    return within


def _nearest_per_scan(candidates: np.ndarray, distance: np.ndarray, scan_of: np.ndarray):
    """
    Keep the candidate nearest the seed in each scan (of equals, the first).

    :param candidates: indices, ascending
    :param distance: their distances to the seed, m
    :param scan_of: every position's scan
    :return: the kept indices, ascending
    """
    order = np.lexsort((candidates, distance, scan_of[candidates]))
    scans = scan_of[candidates[order]]
    first = np.r_[True, scans[1:] != scans[:-1]]
    return np.sort(candidates[order][first])


def assign(per_scan: List[ScanCorners], centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """
    Match each scan's corners to the associated corners (nearest first, one to one).

    :param per_scan: one method's corners per scan
    :param centers: associated corners, (K, 2), m
    :param radii: their gates, (K,), m
    :return: (T, K) index of the matching corner in each scan, -1 where none
    """
    out = np.full((len(per_scan), len(centers)), -1, dtype=np.intp)
    for t, corners in enumerate(per_scan):
        if not len(corners) or not len(centers):
            continue
        distance = np.hypot(*(corners.xy[:, None, :] - centers[None]).transpose(2, 0, 1))
        pairs = np.argwhere(distance <= radii[None, :])
        used_corner, used_center = set(), set()
        for i, k in sorted(pairs.tolist(), key=lambda p: distance[p[0], p[1]]):
            if i not in used_corner and k not in used_center:
                out[t, k] = i
                used_corner.add(i)
                used_center.add(k)
    return out


def corner_stats(xy: np.ndarray, covariance: np.ndarray) -> CornerStats:
    """
    Compare the propagated covariances of one corner with its scatter over the scans.

    :param xy: the corner's position in each scan where found, (n, 2), m
    :param covariance: its propagated covariance in those scans, (n, 2, 2), m^2
    :return: the statistics (NaN ratios with fewer than 3 scans)
    """
    count = len(xy)
    mean = xy.mean(axis=0)
    if count < 3:
        nan2 = np.full((2, 2), math.nan)
        return CornerStats(count, mean, nan2, covariance.mean(axis=0), math.nan, math.nan)
    error = xy - mean
    empirical = error.T @ error / (count - 1)
    propagated = covariance.mean(axis=0)
    with np.errstate(divide='ignore'):          # a corner that never moved: ratio inf
        ratio = math.sqrt(max(np.linalg.det(propagated), 0.0) / np.linalg.det(empirical))
    return CornerStats(count, mean, empirical, propagated, ratio,
                       float(np.mean(nees(error, covariance))))


def evaluate_scans(scans: StaticScans, noise: NoiseParameters, methods: Sequence[str],
                   propagation: str = 'full', min_presence: float = 0.8,
                   base: FeatureConfig = None, reference: str = None) -> Evaluation:
    """
    Run the whole analysis on repeated scans from a still sensor.

    :param scans: the scans (check them with :func:`~.scans.require_still` first)
    :param noise: the noise model the covariances use
    :param methods: the methods to compare
    :param propagation: 'full' (correct) or 'diagonal' (the paper-gap analysis)
    :param min_presence: keep corners found in at least this fraction of the scans
    :param base: the pipeline's other settings (defaults: the paper's)
    :param reference: the method whose corners define the association (default: 'wtls' when
        compared, else the first method)
    :return: the evaluation
    :raises ValueError: on an unknown propagation
    """
    if propagation not in PROPAGATIONS:
        raise ValueError(f'propagation must be one of {PROPAGATIONS}, got {propagation!r}')
    methods = list(methods)
    per_scan = run_methods(scans, noise, methods, base)
    if reference is None:
        reference = 'wtls' if 'wtls' in methods else methods[0]
    centers, radii = associate(per_scan[reference], min_presence)
    assignment = {m: assign(per_scan[m], centers, radii) for m in methods}
    evaluation = Evaluation(scans, noise, methods, propagation, per_scan, centers, assignment)
    for method in methods:
        stats = []
        for k in range(len(centers)):
            hits = [(t, i) for t, i in enumerate(assignment[method][:, k]) if i >= 0]
            xy = np.array([per_scan[method][t].xy[i] for t, i in hits]).reshape(-1, 2)
            cov = np.array([per_scan[method][t].covariances(propagation)[i]
                            for t, i in hits]).reshape(-1, 2, 2)
            stats.append(corner_stats(xy, cov))
        evaluation.stats[method] = stats
    present = (assignment[reference] >= 0).sum(axis=1)
    evaluation.representative = int(np.argmax(present)) if len(present) else 0
    return evaluation
