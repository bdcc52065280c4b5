# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The stable corners of a static recording, and their NEES under a noise model.

A corner is tracked across the scans (associated by position, :func:`.rules.associate`),
and the beams of its two walls are remembered. A scan in which something crossed one of those
beams (:attr:`.calibration.NoiseFit.crossed`) does not count for the corner: its position there
shows the scene's change, not the sensor's noise. Over the scans left (its *clear* scans):

- *jumps* are positions more than ``JUMP_SIGMAS`` robust standard deviations from the corner's
  centre (Mahalanobis, with a covariance estimated from the positions themselves: no noise
  model is assumed), e.g. a mixed return joining a wall in a few scans;
- the corner is *stable* when clear in at least half of the scans, found in at least
  ``STABLE_PRESENCE`` of its clear scans, with at most ``MAX_JUMP_SHARE`` of those jumps;
- its NEES is the mean over its clear scans but the jumps of e' P^-1 e, with e the position
  less the mean of those positions and P its propagated covariance (2 when calibrated), as
  :func:`.analysis.corner_stats` computes it.

Which corners are stable, and which scans are clear, is decided once (with the fitted model);
the NEES of any other model is then measured on the same corners and scans.
"""

from dataclasses import dataclass
import math
from typing import Callable, List, Sequence, Tuple

import numpy as np
from wctls_ros.core import FeatureConfig

from .analysis import corner_stats, corners_per_scan, features_per_scan
from .rules import assign, associate
from .samples import ScanCorners
from .scans import StaticScans

# Corners found in at least this share of the scans are tracked (and then judged stable or not).
TRACK_PRESENCE = 0.5
# A stable corner is found in at least this share of its clear scans...
STABLE_PRESENCE = 0.9
# ... with at most this share of its positions jumps...
MAX_JUMP_SHARE = 0.05
# ... and is clear (nothing crossed its walls) in at least this share of the scans.
MIN_CLEAR_SHARE = 0.5
# A position this many robust sigmas (Mahalanobis) from the corner's centre is a jump (a
# Gaussian position goes that far once in 66 million scans).
JUMP_SIGMAS = 6.0
# Inliers of the robust covariance: within this Mahalanobis distance squared (chi2, 2 dof, 99.9 %).
_INLIER_CHI2 = 13.8
# The beams this close to a corner's walls belong to it (a crossing object's shadow edge).
_WALL_MARGIN_BEAMS = 2


@dataclass(frozen=True)
class TrackedCorner:
    """
    A corner associated across the scans of a recording.

    :ivar center_xy_m: its mean position, shape (2,), m
    :ivar gate_m: association radius around the centre, m
    :ivar walls: which beams its two walls (and two beams either side) cover, shape (N,)
    :ivar clear: the scans in which nothing crossed those beams, shape (T,)
    """

    center_xy_m: np.ndarray
    gate_m: float
    walls: np.ndarray
    clear: np.ndarray


@dataclass(frozen=True)
class CornerNees:
    """
    One tracked corner under one model.

    :ivar found: clear scans in which the corner was found
    :ivar jumps: of those, positions that jumped (left out of the NEES)
    :ivar nees: mean NEES over the others (NaN with fewer than 3)
    """

    found: int
    jumps: int
    nees: float

    @property
    def used(self) -> int:
        """
        Return how many positions the NEES is the mean of.

        :return: found less jumps
        """
        return self.found - self.jumps


def track_corners(scans: StaticScans, config: FeatureConfig,
                  crossed: np.ndarray) -> List[TrackedCorner]:
    """
    Associate the corners across the scans, with the beams of their walls and clear scans.

    :param scans: the scans
    :param config: the pipeline configuration (the fitted model)
    :param crossed: returns something crossed, shape (T, N)
    :return: the corners found in at least TRACK_PRESENCE of the scans, clockwise from +x
    """
    extracted = features_per_scan(scans, config)
    per_scan = [corners for _, corners in extracted]
    centers, gates = associate(per_scan, TRACK_PRESENCE)
    assignment = assign(per_scan, centers, gates)
    beams = scans.ranges.shape[1]
    tracked = []
    for k in range(len(centers)):
        walls = np.zeros(beams, dtype=bool)
        for t in np.flatnonzero(assignment[:, k] >= 0):
            features, corners = extracted[t]
            for segment in corners.segments[assignment[t, k]]:
                first = int(features.segments.first_index[segment])
                last = int(features.segments.last_index[segment])
                walls[np.arange(first, last + 1 if last >= first else last + beams + 1)
                      % beams] = True
        walls = _widen(walls, _WALL_MARGIN_BEAMS)
        clear = ~(crossed & walls[None, :]).any(axis=1)
        tracked.append(TrackedCorner(centers[k], float(gates[k]), walls, clear))
    return tracked


def _widen(mask: np.ndarray, margin: int) -> np.ndarray:
    """Return a beam mask grown by ``margin`` beams on either side of each run."""
    grown = mask.copy()
    for shift in range(1, margin + 1):
        grown[shift:] |= mask[:-shift]
        grown[:-shift] |= mask[shift:]
    return grown


def corner_nees(scans: StaticScans, config: FeatureConfig,
                corners: Sequence[TrackedCorner]) -> List[CornerNees]:
    """
    Measure the NEES of the tracked corners under one model, on their clear scans.

    :param scans: the scans the corners were tracked on
    :param config: the pipeline configuration (the model under test)
    :param corners: the tracked corners
    :return: one result per corner
    """
    if not corners:
        return []
    per_scan = corners_per_scan(scans, config)
    return nees_of(per_scan, corners)


def nees_of(per_scan: List[ScanCorners], corners: Sequence[TrackedCorner]) -> List[CornerNees]:
    """
    Measure the NEES of the tracked corners from extracted corners, on their clear scans.

    :param per_scan: one model's corners per scan
    :param corners: the tracked corners
    :return: one result per corner
    """
    centers = np.array([c.center_xy_m for c in corners]).reshape(-1, 2)
    assignment = assign(per_scan, centers, np.array([c.gate_m for c in corners]))
    results = []
    for k, corner in enumerate(corners):
        found_in = np.flatnonzero((assignment[:, k] >= 0) & corner.clear)
        xy = np.array([per_scan[t].xy[assignment[t, k]] for t in found_in]).reshape(-1, 2)
        covariance = np.array([per_scan[t].covariance[assignment[t, k]]
                               for t in found_in]).reshape(-1, 2, 2)
        jumps = jumps_of(xy)
        # A corner never found in a clear scan has no NEES (and no mean to take one against).
        nees = corner_stats(xy[~jumps], covariance[~jumps]).nees if len(xy) else math.nan
        results.append(CornerNees(len(found_in), int(jumps.sum()), nees))
    return results


def jumps_of(xy: np.ndarray) -> np.ndarray:
    """
    Flag the positions far from the bulk of a corner's positions, without a noise model.

    The bulk's mean and covariance are estimated from the positions within twice the median
    distance of the coordinate-wise median, then refined from the positions within the 99.9 %
    ellipse of that estimate (three times); a position beyond JUMP_SIGMAS of the final estimate
    is a jump.

    :param xy: the corner's positions, shape (n, 2), m
    :return: shape (n,), True for a jump
    """
    if len(xy) < 5:
        return np.zeros(len(xy), dtype=bool)
    distance = np.hypot(*(xy - np.median(xy, axis=0)).T)
    inliers = distance <= 2.0 * np.median(distance)
    for _ in range(3):
        if inliers.sum() < 3:
            return np.zeros(len(xy), dtype=bool)
        error = xy - xy[inliers].mean(axis=0)
        # A floor of (0.1 mm)^2 keeps positions quantised to one value from dividing by 0.
        covariance = np.cov(xy[inliers].T) + np.eye(2) * 1e-8
        squared = np.einsum('ni,ij,nj->n', error, np.linalg.inv(covariance), error)
        inliers = squared <= _INLIER_CHI2
    return squared > JUMP_SIGMAS ** 2


def is_stable(corner: TrackedCorner, result: CornerNees) -> bool:
    """
    Return whether a corner is stable enough to check a model on.

    :param corner: the tracked corner
    :param result: its NEES under the model it was tracked with
    :return: clear in enough scans, found in nearly all of them, hardly ever jumping
    """
    clear = int(corner.clear.sum())
    return (clear >= MIN_CLEAR_SHARE * len(corner.clear) and clear > 0
            and result.found >= STABLE_PRESENCE * clear
            and result.jumps <= MAX_JUMP_SHARE * result.found and math.isfinite(result.nees))


def pooled_nees(results: Sequence[CornerNees]) -> float:
    """
    Return the mean NEES over every used position of the corners given.

    :param results: the corners' results
    :return: the mean (2 when calibrated), NaN without positions
    """
    usable = [r for r in results if math.isfinite(r.nees)]
    count = sum(r.used for r in usable)
    return sum(r.nees * r.used for r in usable) / count if count else math.nan


def fit_flatness(nees_at: Callable[[float], float], lower_m: float, nees_at_lower: float,
                 upper_m: float = 0.05, tolerance: float = 0.01,
                 evaluations: int = 12) -> Tuple[float, float, bool]:
    """
    Find the wall-flatness sigma (D18) that brings a pooled NEES down to 2.

    The NEES falls as the flatness sigma s grows, and the variance it adds grows as s^2: the
    root is sought in s^2 by regula falsi with the Illinois step (the end that stays put has
    its NEES halved towards 2), within [lower_m^2, upper_m^2].

    :param nees_at: the pooled NEES with a flatness sigma s, m
    :param lower_m: the smallest s (the one already configured), m
    :param nees_at_lower: the pooled NEES there (already measured)
    :param upper_m: the largest s tried, m
    :param tolerance: stop when the NEES is within this share of 2
    :param evaluations: the most evaluations of nees_at
    :return: (s, m: lower_m when the NEES is at most 2 there; the NEES at s; whether it is
        within the tolerance of 2, or at most 2 at lower_m)
    """
    if not math.isfinite(nees_at_lower) or nees_at_lower <= 2.0 * (1.0 + tolerance):
        return lower_m, nees_at_lower, math.isfinite(nees_at_lower)
    low, high = (lower_m ** 2, nees_at_lower - 2.0), (upper_m ** 2, nees_at(upper_m) - 2.0)
    if not math.isfinite(high[1]) or high[1] > 0.0:        # even the largest s is too little
        return upper_m, high[1] + 2.0, False
    best = high
    side = 0
    for _ in range(evaluations - 1):
        variance = (low[0] * high[1] - high[0] * low[1]) / (high[1] - low[1])
        excess = nees_at(math.sqrt(variance)) - 2.0
        best = (variance, excess)
        if not math.isfinite(excess) or abs(excess) <= 2.0 * tolerance:
            break
        if excess > 0.0:
            low = best
            if side == 1:
                high = (high[0], high[1] / 2.0)
            side = 1
        else:
            high = best
            if side == -1:
                low = (low[0], low[1] / 2.0)
            side = -1
    return (math.sqrt(best[0]), best[1] + 2.0,
            math.isfinite(best[1]) and abs(best[1]) <= 2.0 * tolerance)
