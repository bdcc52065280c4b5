# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The two rules every evaluation tool shares: when a sensor is still, and which corners are one.

``calibrate``, ``evaluate`` and ``score`` decide with these and nothing else, so that on the
same scans and configuration they agree:

- **stillness** (:func:`check_still`, :func:`require_still`): each steady beam's median range
  over the first third of the scans against its median over the last third, in standard errors
  of its own scan-to-scan noise. The noise is taken from the differences of consecutive scans,
  which a steady motion hardly changes, and not from the scatter within a third, which a motion
  inflates until no drift stands out (a robot carried for 20 s drifted 20 cm and passed); a
  scan-to-scan noise several times the scatter between neighbouring beams is a motion too
  (keyframes far apart);
- **association** (:func:`associate`, :func:`assign`): corners of different scans are one
  corner when within a gate of 5 predicted sigmas of the major axis, clamped to 2-25 cm;
- **corners per scan** (:func:`corners_per_scan_figure`): the mean number of corners the
  extractor reported per scan, which every tool prints the same way.

Pure numpy: no rclpy.
"""

from dataclasses import dataclass
import math
from typing import List, Sequence
import warnings

import numpy as np
from wctls_ros.core import ellipse

from .samples import ScanCorners
from .scans import StaticScans

# The sensor counts as moving when more than this fraction of the steady beams drifted...
MOVING_FRACTION = 0.1
# ... by more than this many standard errors between the first and the last third of the scans.
MOVING_Z = 6.0
# ... or when the steady beams' scan-to-scan noise is, at the median, more than this many times
# the noise between neighbouring beams of one scan (what the sensor itself scatters): keyframes
# of a moving robot (scans 0.01-2.3 m apart) change by far more from one scan to the next than
# any beam scatters, too much for a drift between thirds to stand out. Measured: 0.87-0.99 on the
# four still recordings of data/ and on simulated ones with 1 and 5 cm of noise; 6-92 on the
# moving recordings and on keyframes of the hand-carried office.
MOVING_NOISE_RATIO = 3.0
# A beam is steady when it returns in at least this fraction of the scans.
_STEADY_FRACTION = 0.95
# The smallest scan-to-scan noise assumed, m: a quantised or noiseless beam (scatter 0) does
# not count any change as a drift.
_NOISE_FLOOR_M = 1e-4
# Association gate: this many predicted sigmas (of the corner's major axis) around a cluster...
_GATE_SIGMAS = 5.0
# ... but never tighter or wider than these, m.
_GATE_MIN_M = 0.02
ASSOCIATION_GATE_MAX_M = 0.25
# Relative width of the rim of a gate where _within_gates asks np.hypot.
_RIM = 1e-12


class MovingSensorError(ValueError):
    """The scans do not come from a still sensor (the analysis needs repeated static scans)."""


@dataclass(frozen=True)
class StillnessCheck:
    """
    How much the scene drifted between the first and the last third of the scans.

    :ivar steady_beams: beams that return in (nearly) every scan
    :ivar drifted_fraction: fraction of the steady beams whose median range moved by more
        than the noise explains (MOVING_Z standard errors)
    :ivar median_drift_m: median over the steady beams of |median(last third) - median(first)|
    :ivar median_bound_m: median over the steady beams of the change the noise explains
        (MOVING_Z standard errors), m
    :ivar noise_ratio: median over the steady beams of their scan-to-scan noise, over the noise
        between neighbouring beams of one scan (second differences, median over the scans)
    :ivar still: whether the sensor counts as still: drifted_fraction at most MOVING_FRACTION
        and noise_ratio at most MOVING_NOISE_RATIO
    """

    steady_beams: int
    drifted_fraction: float
    median_drift_m: float
    median_bound_m: float
    noise_ratio: float
    still: bool

    def describe(self) -> str:
        """
        Return the figures in one line.

        :return: e.g. '3 % of 450 steady beams drifted (bound 10 %), median drift 2.0 mm
            against a bound of 9.1 mm, scan-to-scan noise 1.1 times a beam's (bound 3)'
        """
        if self.steady_beams == 0:
            return ('no beam to compare (under 6 scans, or none returns in nearly every '
                    'scan): not shown to be still')
        return (f'{100 * self.drifted_fraction:.0f} % of {self.steady_beams} steady beams '
                f'drifted (bound {100 * MOVING_FRACTION:.0f} %), median drift '
                f'{1e3 * self.median_drift_m:.1f} mm against a bound of '
                f'{1e3 * self.median_bound_m:.1f} mm, scan-to-scan noise '
                f"{self.noise_ratio:.1f} times a beam's (bound {MOVING_NOISE_RATIO:g})")


def check_still(scans: StaticScans) -> StillnessCheck:
    """
    Test whether the scans come from a still sensor in a still scene.

    Each steady beam's median range over the first third of the scans is compared with its
    median over the last third, in units of its standard error. The standard error comes from
    the beam's scan-to-scan noise, the robust spread of the differences of consecutive scans
    over sqrt(2): a steady motion adds little to one scan's change but accumulates over a
    third, so the drift stands out however large the motion. A still sensor leaves nearly every
    beam below MOVING_Z standard errors; a moving sensor or a changing scene moves most beams.
    Scans far apart (a moving robot's keyframes) change by more than the sensor's noise from
    one scan to the next: a median scan-to-scan noise above MOVING_NOISE_RATIO times the noise
    between neighbouring beams of a scan (their second differences over sqrt(6), robustly) is
    a motion as well.

    :param scans: the scans (at least 6)
    :return: the check's figures
    """
    count = len(scans)
    if count < 6:
        return StillnessCheck(0, 0.0, 0.0, 0.0, 0.0, False)
    valid = scans.valid()
    steady = valid.mean(axis=0) >= _STEADY_FRACTION
    if not steady.any():
        return StillnessCheck(0, 1.0, math.inf, 0.0, math.inf, False)
    ranges = np.where(valid, scans.ranges, np.nan)[:, steady]
    third = count // 3
    first, last = ranges[:third], ranges[-third:]
    with np.errstate(invalid='ignore'), warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)      # all-NaN beams of a third
        drift = np.abs(np.nanmedian(last, axis=0) - np.nanmedian(first, axis=0))
        noise = 1.4826 * np.nanmedian(np.abs(np.diff(ranges, axis=0)), axis=0) / math.sqrt(2.0)
        # Standard error of a difference of two medians of `third` samples.
        bound = MOVING_Z * 1.2533 * np.maximum(noise, _NOISE_FLOOR_M) * math.sqrt(2.0 / third)
        drifted = drift > bound
        second = scans.ranges[:, :-2] - 2.0 * scans.ranges[:, 1:-1] + scans.ranges[:, 2:]
        usable = valid[:, :-2] & valid[:, 1:-1] & valid[:, 2:]
        beam_noise = np.nanmedian(np.where(usable, np.abs(second), np.nan), axis=1)
        within = max(1.4826 * float(np.nanmedian(beam_noise)) / math.sqrt(6.0), _NOISE_FLOOR_M)
        ratio = noise / within
    measured = np.isfinite(drift) & np.isfinite(bound) & np.isfinite(ratio)
    if not measured.any():
        return StillnessCheck(int(steady.sum()), 1.0, math.inf, 0.0, math.inf, False)
    fraction = float(np.mean(drifted[measured]))
    noise_ratio = float(np.median(ratio[measured]))
    return StillnessCheck(int(steady.sum()), fraction, float(np.median(drift[measured])),
                          float(np.median(bound[measured])), noise_ratio,
                          fraction <= MOVING_FRACTION and noise_ratio <= MOVING_NOISE_RATIO)


def require_still(scans: StaticScans) -> StillnessCheck:
    """
    Refuse scans that do not come from a still sensor.

    :param scans: the scans
    :return: the check (when still)
    :raises MovingSensorError: with the figures that show the motion
    """
    check = check_still(scans)
    if not check.still:
        if len(scans) < 6:
            raise MovingSensorError(
                f'{scans.source or "the scans"}: {len(scans)} scans are too few to tell a '
                'still sensor (need at least 6 repeated scans)')
        raise MovingSensorError(
            f'{scans.source or "the scans"}: the sensor or the scene moved during the '
            f'recording: {check.describe()} between the first and the last third of the '
            f'{len(scans)} scans. This analysis needs repeated scans from a still sensor in a '
            'still scene; cut the bag to a still interval.')
    return check


def corners_per_scan_figure(per_scan: Sequence[ScanCorners]) -> float:
    """
    Return the mean number of corners reported per scan, as every tool prints it.

    :param per_scan: the corners of each scan
    :return: the mean (NaN without scans)
    """
    return float(np.mean([len(c) for c in per_scan])) if len(per_scan) else math.nan


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
    gates = np.clip(_GATE_SIGMAS * ellipse(cov).semi_major, _GATE_MIN_M,
                    ASSOCIATION_GATE_MAX_M)
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

    SIZE_M = 2 * ASSOCIATION_GATE_MAX_M
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
