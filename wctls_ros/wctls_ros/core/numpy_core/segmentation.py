# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Split a scan into straight segments: breakpoints, IEPF, statistical merging, trimmed ends.

Positions here index the scan's valid returns in *circular order*: for a full turn the order is
rotated to start at a breakpoint (or, on a closed contour without any, at the farthest return),
so a wall crossing the +-pi seam is an ordinary run of positions. SegmentRanges are half-open
position ranges [start, stop) into that order; on a full turn a segment may run past its end
(positions count modulo the number of returns).
"""

from dataclasses import dataclass
import math
from typing import Callable, NamedTuple, Tuple

import numpy as np

from ._linalg import mahalanobis_squared_2x2
from ..records import Lines, Noise
from ..rules import (BUDGET_EXTRA_PASSES, BUDGET_LEVELS_PER_DOUBLING, JOINABLE_SIGMAS, MIN_CHORD_M,
                     MIN_FIT_RETURNS)
from ..scan import ScanPoints


def pass_budget(count: int) -> int:
    """
    Return how many whole-contour passes IEPF (and merging) may make on a scan.

    Each pass costs O(n), so the bound makes the worst case O(n log n). Balanced splitting
    needs about log2(n / 3) levels; real and simulated scans need at most 8 (clean walls) to
    23 (5 cm noise against a 4 cm threshold, 8640 beams); twice log2(n) plus 8 leaves that
    margin. Without a bound, a wall whose every other return lies a few cm behind it makes
    IEPF peel two returns per level: n / 2 levels, a minute for 32 000 beams.

    :param count: number of returns in the scan
    :return: the number of passes, 2 ceil(log2 count) + 8
    """
    return (BUDGET_LEVELS_PER_DOUBLING * math.ceil(math.log2(max(count, 2)))
            + BUDGET_EXTRA_PASSES)


@dataclass(frozen=True)
class Chains:
    """
    Runs of returns without a breakpoint between neighbours, in circular order.

    :ivar order: indices into the ScanPoints arrays in circular order, shape (n,)
    :ivar start: first position of each run, shape (K,)
    :ivar stop: one past the last position of each run, shape (K,)
    :ivar chain: the chain each run belongs to, shape (K,) (the two arcs of a closed contour are
        one chain)
    """

    order: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    chain: np.ndarray


@dataclass(frozen=True)
class SegmentRanges:
    """
    Segment position ranges into ``Chains.order``, in circular order.

    :ivar start: first position, shape (S,)
    :ivar stop: one past the last position, shape (S,)
    :ivar chain: the chain each segment lies on, shape (S,)
    """

    start: np.ndarray
    stop: np.ndarray
    chain: np.ndarray

    def __len__(self):
        return len(self.start)

    def select(self, keep: np.ndarray) -> 'SegmentRanges':
        """
        Return the segments where ``keep`` is true (a boolean or index array).

        :param keep: selection over the segments
        :return: the selected segments
        """
        return SegmentRanges(self.start[keep], self.stop[keep], self.chain[keep])


def moment_terms(x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """
    Return the per-return quantities whose sums :func:`moment_fit` needs.

    :param x_m: shape (P,), m
    :param y_m: shape (P,), m
    :return: rows (1, x, y, x^2, y^2, x y, rho^2), shape (7, P)
    """
    rows = np.empty((7, len(x_m)))
    rows[0], rows[1], rows[2] = 1.0, x_m, y_m
    np.multiply(x_m, x_m, out=rows[3])
    np.multiply(y_m, y_m, out=rows[4])
    np.multiply(x_m, y_m, out=rows[5])
    np.add(rows[3], rows[4], out=rows[6])
    return rows


def moment_fit(sums: np.ndarray, range_sigma_m: float, bearing_sigma_rad: float):
    """
    Fit lines from per-segment sums alone: orthogonal regression with an isotropic covariance.

    Cheap enough to refit merged segments from piece sums in O(1) each; meant for
    segmentation decisions, not for the published covariance. Each return is taken to scatter
    isotropically with variance range_sigma^2 + bearing_sigma^2 rho^2 (an upper bound of its
    scatter across the line), which gives Var(angle) = s2 / (N L), Cov(angle, radius) = d Var
    (angle), Var(radius) = s2 / N + d^2 Var(angle), with L the variance of the returns along the
    line and d the offset of their centroid from the foot of the perpendicular.

    :param sums: per-segment sums of :func:`moment_terms`, shape (S, 7)
    :param range_sigma_m: range noise std, m
    :param bearing_sigma_rad: bearing noise std, rad
    :return: (angle (S,) rad in (-pi, pi], radius (S,) m >= 0, covariance of (angle, radius)
        (S, 2, 2))
    """
    n = sums[:, 0]
    mx, my, mxx, myy, mxy, mrr = (sums[:, 1:] / n[:, None]).T
    cxx, cyy, cxy = mxx - mx * mx, myy - my * my, mxy - mx * my
    normal = 0.5 * np.arctan2(-2.0 * cxy, cyy - cxx)         # the minor axis
    c, s = np.cos(normal), np.sin(normal)
    radius = mx * c + my * s
    flip = np.copysign(1.0, radius)                          # the normal points to the line
    c *= flip
    s *= flip
    along = cxx * s * s + cyy * c * c - 2.0 * cxy * s * c    # variance along the line
    offset = my * c - mx * s
    scatter = range_sigma_m ** 2 + bearing_sigma_rad ** 2 * mrr
    var_angle = scatter / (n * along)                        # inf for returns all in one spot
    covariance = np.empty((len(n), 2, 2))
    covariance[:, 0, 0] = var_angle
    covariance[:, 0, 1] = covariance[:, 1, 0] = offset * var_angle
    covariance[:, 1, 1] = scatter / n + offset * offset * var_angle
    return np.arctan2(s, c), np.abs(radius), covariance


@dataclass(frozen=True)
class PieceSums:
    """
    A contour cut into pieces at segment ends, with per-piece sums of per-return quantities.

    Segments and their merges are whole runs of pieces: written as piece ranges (a
    SegmentRanges over piece indices, wrapping modulo the number of pieces on a full turn),
    each one's sums are a difference of two rows of ``prefix``, O(1) per segment.

    :ivar edges: piece boundaries as positions, from 0 to n (the contour's length), shape (m + 1,)
    :ivar prefix: sums over the pieces before each boundary, then once more after a full turn,
        shape (2 m + 1, k)
    """

    edges: np.ndarray
    prefix: np.ndarray

    def pieces(self, segments: SegmentRanges) -> SegmentRanges:
        """
        Return segments whose ends are piece boundaries as piece ranges.

        :param segments: position ranges, start in [0, n), stop in (start, n]
        :return: the same segments over piece indices
        """
        return SegmentRanges(np.searchsorted(self.edges, segments.start),
                             np.searchsorted(self.edges, segments.stop), segments.chain)

    def positions(self, pieces: SegmentRanges) -> SegmentRanges:
        """
        Return piece ranges as position ranges (stop past n where a range wraps).

        :param pieces: piece ranges, start in [0, m), stop in (start, start + m]
        :return: the same segments over positions
        """
        count = self.edges.size - 1
        wrapped = pieces.stop > count
        stop = self.edges[pieces.stop - count * wrapped] + self.edges[-1] * wrapped
        return SegmentRanges(self.edges[pieces.start], stop, pieces.chain)

    def over(self, pieces: SegmentRanges) -> np.ndarray:
        """
        Return the sums over piece ranges.

        :param pieces: piece ranges, start in [0, m), stop in (start, start + m]
        :return: shape (S, k)
        """
        return self.prefix.take(pieces.stop, axis=0) - self.prefix.take(pieces.start, axis=0)


def piece_sums(values: np.ndarray, segments: SegmentRanges) -> PieceSums:
    """
    Sum per-return values over the pieces of a contour cut at every segment end.

    :param values: shape (k, n), one row per quantity
    :param segments: position ranges within [0, n)
    :return: the pieces and their sums
    """
    count = values.shape[1]
    boundary = np.zeros(count + 1, dtype=bool)
    boundary[segments.start] = boundary[segments.stop] = boundary[0] = boundary[count] = True
    edges = boundary.nonzero()[0]
    pieces = edges.size - 1
    prefix = np.empty((2 * pieces + 1, values.shape[0]))
    prefix[0] = 0.0
    np.add.accumulate(np.add.reduceat(values, edges[:-1], axis=1).T, axis=0,
                      out=prefix[1:pieces + 1])
    np.add(prefix[1:pieces + 1], prefix[pieces], out=prefix[pieces + 1:])
    return PieceSums(edges, prefix)


class Breaks(NamedTuple):
    """
    Where neighbouring returns are separated, and which separations merging may cross.

    :ivar separated: return i starts a new chain, shape (n,) (entry 0 refers to the seam between
        the last and the first return of a full turn, and is True otherwise)
    :ivar joinable: of those, the separations noise can explain: at most ``max_missing_beams``
        invalid beams between the two returns, and a distance within 5 sqrt(2) sigma of what
        one surface allows; shape (n,)
    """

    separated: np.ndarray
    joinable: np.ndarray


def breakpoints(points: ScanPoints, range_sigma_m: float, bearing_sigma_rad: float,
                lambda_rad: float, max_missing_beams: int, noise_sigmas: float) -> Breaks:
    """
    Mark where the adaptive breakpoint rule of Borges and Aldon separates neighbouring returns.

    Neighbours i-1 and i are separated when their distance exceeds
    ``r sin(dphi) / sin(lambda - dphi) + k sqrt(range_sigma^2 + (r bearing_sigma)^2)``
    (r the smaller of the two ranges, dphi their bearing difference, so that missing beams widen
    the allowance; the last term is k sigma of a return's position noise, where Borges and Aldon
    have the range noise alone; k = 3 up to 1080 beams per turn, more on denser scans,
    :func:`~wctls_ros.core.scan.beam_density`), when ``dphi >= lambda``, or when more than
    ``max_missing_beams`` beams between them have no valid return (nothing is known of what
    lies there: two collinear surfaces either side of a dark or open gap are not one wall). The
    rule is symmetric, so reversing the beam order changes nothing. With 3 sigma, noise alone
    separates one pair of returns in a few hundred on a wall, so a separation is joinable
    (merging may restore it) unless it is a gap or the distance exceeds the allowance by more
    than 5 sqrt(2) sigma: a discontinuity (an occlusion, a range jump).

    :param points: the scan's valid returns
    :param range_sigma_m: range noise std, m
    :param bearing_sigma_rad: bearing noise std, rad
    :param lambda_rad: worst incidence angle still treated as one surface, rad
    :param max_missing_beams: most invalid beams between two returns of one chain
    :param noise_sigmas: k, the allowance for noise in sigmas of a return's position noise
    :return: the separations
    """
    n = len(points)
    if n == 0:
        return Breaks(np.zeros(0, dtype=bool), np.zeros(0, dtype=bool))
    x, y, rho, index = points.x_m, points.y_m, points.range_m, points.index
    # Each return against its predecessor; entry 0 against the last return, across the seam.
    beams = np.empty(n)
    beams[1:] = index[1:] - index[:-1]
    # Across the seam: the rest of the turn, in increments (about 1 for a full turn).
    step = abs(points.angle_increment_rad)
    beams[0] = (index[0] + (2.0 * math.pi - (points.beam_count - 1) * step) / step
                + (points.beam_count - 1 - index[-1]))
    dx, dy, r = np.empty(n), np.empty(n), np.empty(n)
    dx[1:], dx[0] = x[1:] - x[:-1], x[0] - x[-1]
    dy[1:], dy[0] = y[1:] - y[:-1], y[0] - y[-1]
    np.minimum(rho[1:], rho[:-1], out=r[1:])
    r[0] = min(rho[0], rho[-1])
    # sin(dphi) / sin(lambda - dphi) is one number for neighbouring beams, the usual case.
    # (dphi >= lambda: no surface is seen that obliquely, always separated: reach -1.)
    reach = np.empty(n)
    reach.fill(math.sin(step) / math.sin(lambda_rad - step) if step < lambda_rad else -1.0)
    wider = (beams != 1.0).nonzero()[0]
    if wider.size:
        dphi = beams[wider] * step
        with np.errstate(divide='ignore', invalid='ignore'):
            reach[wider] = np.where(dphi < lambda_rad,
                                    np.sin(dphi) / np.sin(lambda_rad - dphi), -1.0)
    surface = r * reach
    noise = np.sqrt(range_sigma_m ** 2 + (r * bearing_sigma_rad) ** 2)
    distance = np.sqrt(dx * dx + dy * dy)
    missing = beams - 1.0                       # fractional across the seam of a full turn
    gap = missing >= max_missing_beams + 0.5
    separated = (reach < 0.0) | gap | (distance > surface + noise_sigmas * noise)
    joinable = (separated & (reach >= 0.0) & ~gap
                & (distance <= surface + JOINABLE_SIGMAS * noise))
    if not points.full_turn or n == 1:
        separated[0], joinable[0] = True, False
    return Breaks(separated, joinable)


def chains(points: ScanPoints, separated: np.ndarray) -> Chains:
    """
    Group the returns into chains between breakpoints, in circular order.

    A closed contour (a full turn without any breakpoint) is cut at the farthest return s and at
    the return farthest from s, both left out like IEPF split points, into two arcs of one
    chain: a choice that depends neither on where the scan's seam lies nor on the beam order.

    :param points: the scan's valid returns
    :param separated: where returns start a new chain (:attr:`Breaks.separated`)
    :return: the chains
    """
    n = len(points)
    breaks = separated.nonzero()[0]
    if n and not breaks.size:
        first = int(np.argmax(points.range_m))
        dx, dy = points.x_m - points.x_m[first], points.y_m - points.y_m[first]
        opposite = (int(np.argmax(dx * dx + dy * dy)) - first) % n
        start, stop = np.array([1, opposite + 1]), np.array([opposite, n])
        chain = np.zeros(2, dtype=np.intp)
    else:
        first = int(breaks[0]) if n else 0
        start = breaks - first
        stop = np.append(start[1:], n) if n else start
        chain = np.arange(start.size)
    order = np.arange(first, first + n)
    order[n - first:] -= n
    return Chains(order, start, stop, chain.astype(np.intp))


def iterative_end_point_fit(x_m: np.ndarray, y_m: np.ndarray, start: np.ndarray,
                            stop: np.ndarray, chain: np.ndarray, threshold_m,
                            max_levels: int) -> Tuple[SegmentRanges, bool]:
    """
    Split runs of returns where a return lies farther than a threshold from the run's chord.

    All runs are processed together, one split level per pass, as a partition of the positions
    into pieces (a boundary mask): each pass measures every return against its piece's chord
    and cuts the pieces whose farthest return is beyond the threshold (farthest in units of
    each return's own threshold, when they differ). The return at a split is
    the one nearest the corner and belongs to neither side (it would otherwise be shared, or
    bias one wall); merging restores it when the two sides turn out to be one line. After
    ``max_levels`` passes the pieces that would still split are not straight and are left out
    (:func:`pass_budget` keeps the work O(n log n) on any input).

    :param x_m: x of the returns in position order, shape (m,), m
    :param y_m: y of the returns in position order, shape (m,), m
    :param start: first position of each run, sorted, shape (K,)
    :param stop: one past the last position of each run, shape (K,) (runs do not overlap)
    :param chain: the chain of each run, shape (K,)
    :param threshold_m: the IEPF split distance, m: one for all returns, or per return, shape
        (m,)
    :param max_levels: the most split passes
    :return: the straight pieces with at least MIN_FIT_RETURNS returns (fewer can be neither
        fitted nor split), sorted by start position; and whether pieces were left out because
        the passes ran out
    """
    count = x_m.size
    boundary = np.zeros(count + 1, dtype=bool)
    boundary[start] = boundary[stop] = boundary[0] = boundary[count] = True
    # Distances are compared in units of each return's threshold.
    inv_threshold = 1.0 / np.broadcast_to(np.asarray(threshold_m, dtype=float), (count,))
    xy = np.array([x_m, y_m])
    for level in range(max_levels + 1):
        edges = boundary.nonzero()[0]
        first = edges[:-1]
        counts = edges[1:] - first
        # Both ends of every chord in one gather each: rows x, y.
        x0, y0 = start_xy = xy.take(first, axis=1)
        x1, y1 = end_xy = xy.take(edges[1:] - 1, axis=1)
        chord = end_xy - start_xy
        # |chord x (return - chord start)|: the return's distance times the chord length; the
        # chord's three numbers repeated to its returns in one step.
        across = np.array([chord[0], chord[1], x0 * y1 - y0 * x1]).repeat(counts, axis=1)
        cross = across[0] * y_m
        cross -= across[1] * x_m
        cross += across[2]
        np.abs(cross, out=cross)
        cross *= inv_threshold
        farthest = np.maximum.reduceat(cross, first)
        squared = chord * chord
        chord2 = squared[0] + squared[1]
        # A chord too short to have a direction never splits (it would at distance 0).
        split = (farthest * farthest > chord2) & (chord2 > MIN_CHORD_M ** 2)
        # count_nonzero, not split.any(): a reduction method costs several us a call here.
        splits = np.count_nonzero(split)
        if not splits:
            break
        if level == max_levels:                  # out of passes: drop what is not straight
            break
        cut = (cross == np.where(split, farthest, np.inf).repeat(counts)).nonzero()[0]
        if cut.size > splits:                    # ties: the first return at the maximum
            piece = np.arange(first.size).repeat(counts)
            cut = cut[np.concatenate(([True], piece[cut[1:]] != piece[cut[:-1]]))]
        boundary[cut] = boundary[cut + 1] = True
    # Keep the straight pieces inside a run (not the returns between runs) with enough returns.
    run = np.searchsorted(start, first, side='right') - 1
    keep = (edges[1:] - first >= MIN_FIT_RETURNS) & (run >= 0) & (first < stop[run]) & ~split
    return SegmentRanges(first[keep], edges[1:][keep], chain[run[keep]]), bool(splits)


def merge_collinear(segments: SegmentRanges, circular: bool, contour_length: int,
                    fit: Callable[[SegmentRanges], tuple], chi2_threshold: float,
                    max_passes: int, joinable: np.ndarray) -> Tuple[SegmentRanges, tuple, bool]:
    """
    Merge neighbouring segments that are statistically the same line.

    Neighbours are consecutive segments on one chain, or on two chains that touch (no return
    between them) across a break that noise can explain (``joinable``: e.g. a bearing error at
    grazing incidence); never across a discontinuity or a long run of missing beams, where two
    surfaces that happen to be collinear would make a phantom wall. Each pass fits every
    segment, computes for each neighbouring pair the squared Mahalanobis distance of the
    difference of their (angle, radius) under the sum of the two covariances (independent
    returns), and merges the pairs below ``chi2_threshold``, lowest first, each segment at most
    once per pass. A merged segment spans both, including any return between them left out by
    the split. Passes repeat until nothing merges, or ``max_passes`` have run (the segments are
    then valid but some neighbours stay apart). Positions may count returns or, as in the
    pipeline, the pieces of :class:`PieceSums` (whose fits are then O(1) each).

    :param segments: segments with >= 3 returns each, sorted by start position
    :param circular: whether the returns cover a full turn (the last and first can be neighbours)
    :param contour_length: number of positions n (they wrap modulo n)
    :param fit: returns (angle (S,) rad, radius (S,) m, covariance (S, 2, 2)) of segments
    :param chi2_threshold: merge below this squared Mahalanobis distance (0: never merge)
    :param max_passes: the most merging passes
    :param joinable: per position, whether a merge may cross the break before it, shape
        (contour_length,)
    :return: the merged segments, their fit (the last pass's, so not computed twice), and
        whether merging stopped because the passes ran out
    """
    for passes in range(max_passes + 1):
        line_fit = fit(segments)
        if len(segments) < 2 or chi2_threshold <= 0.0:
            break
        distance, merged_stop, candidates = _merge_distances(
            segments, line_fit, circular, contour_length, joinable, chi2_threshold)
        if not candidates.size:
            break
        if passes == max_passes:
            return segments, line_fit, True
        segments = _merge_lowest_first(segments, distance, merged_stop, candidates)
    return segments, line_fit, False


def _merge_distances(segments: SegmentRanges, line_fit: tuple, circular: bool,
                     contour_length: int, joinable: np.ndarray, chi2_threshold: float):
    """
    Return the merge test of every segment with its successor.

    :return: (the squared Mahalanobis distance of each pair, shape (S,); the stop of each pair
        merged, shape (S,); the pairs that may merge and pass, ascending)
    """
    count = len(segments)
    start, stop, chain = segments.start, segments.stop, segments.chain
    second = np.arange(1, count + 1)
    second[-1] = 0
    # A merged segment must not wrap onto itself around a closed contour.
    merged_stop = stop[second]
    merged_stop[-1] += contour_length
    touching = (stop % contour_length == start[second]) & joinable[start[second]]
    pair_ok = (((chain == chain[second]) | touching)
               & (merged_stop - start <= contour_length))
    if not circular or count < 3:
        pair_ok[-1] = False                     # the last segment has no successor
    angle, radius, covariance = line_fit
    distance = mahalanobis_squared_2x2(
        np.remainder(angle - angle[second] + np.pi, 2.0 * np.pi) - np.pi,
        radius - radius[second], covariance + covariance.take(second, axis=0))
    return distance, merged_stop, (pair_ok & (distance < chi2_threshold)).nonzero()[0]


def _root(joined: dict, label: int) -> int:
    """Return the chain a chain label was joined into (union-find's root)."""
    while label in joined:
        label = joined[label]
    return label


def _merge_lowest_first(segments: SegmentRanges, distance: np.ndarray, merged_stop: np.ndarray,
                        candidates: np.ndarray) -> SegmentRanges:
    """
    Merge the passing pairs, lowest distance first, each segment at most once.

    Chains joined by a merged segment are one chain from then on (union by root). Few
    candidates: plain Python is faster than numpy here.

    :return: the merged segments
    """
    count = len(segments)
    used = [False] * count
    absorbed = []
    new_stop, chain_of = segments.stop.copy(), segments.chain.tolist()
    joined: dict = {}                          # chain -> the chain it joined
    for k in candidates[np.argsort(distance[candidates], kind='stable')].tolist():
        j = (k + 1) % count
        if not (used[k] or used[j]):
            used[k] = used[j] = True
            absorbed.append(j)
            new_stop[k] = merged_stop[k]
            into, other = _root(joined, chain_of[k]), _root(joined, chain_of[j])
            if into != other:
                joined[other] = into
    chain = segments.chain
    if joined:
        relabel = np.arange(chain.max() + 1)
        for label in joined:
            relabel[label] = _root(joined, label)
        chain = relabel[chain]
    keep = np.ones(count, dtype=bool)
    keep[absorbed] = False
    return SegmentRanges(segments.start, new_stop, chain).select(keep)


def trim_ambiguous(segments: SegmentRanges, circular: bool, x_m: np.ndarray, y_m: np.ndarray,
                   lines: Lines, noise: Noise, min_returns: int, window: int) -> SegmentRanges:
    """
    Drop the returns at the meeting ends of two neighbouring segments that could fit both lines.

    Where two segments meet (no return, or only the IEPF split return, between them), the
    returns nearest the corner lie within the noise of both lines, and which segment they
    fall into changes from scan to scan. Left in, that switching adds corner scatter no
    covariance describes (most on short walls). The two lines are closer to each other than
    t = 3 sqrt(range_sigma^2 + (r bearing_sigma)^2) (3 sigma of a return at the corner's range
    r) within a distance t / sin(angle between them) of their intersection: the returns at a
    meeting end inside that radius, in an unbroken run from the end, are left out of both
    segments. A segment keeps at least ``min_returns`` returns, shared evenly by its two ends
    when both meet a neighbour (so that the rule does not depend on the beam order). At most
    ``window`` returns are examined at each end.

    For every meeting end at once.

    :param segments: segments sorted by start position (positions modulo n)
    :param circular: whether the returns cover a full turn (the last and first can meet)
    :param x_m: x of the returns in position order, shape (n,), m
    :param y_m: y of the returns in position order, shape (n,), m
    :param lines: each segment's line
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param min_returns: never trim a segment below this many returns
    :param window: most returns examined (and trimmed) at each end
    :return: the trimmed segments
    """
    count = len(segments)
    if count < 2:
        return segments
    start, stop = segments.start, segments.stop
    angle_rad, radius_m = lines.angle_rad, lines.radius_m
    range_sigma_m, bearing_sigma_rad = noise.deciding_sigma_m, noise.bearing_sigma_rad
    contour_length = len(x_m)
    second = np.arange(1, count + 1)
    second[-1] = 0
    meets = (start[second] - stop) % contour_length <= 1
    meets[-1] &= circular and count > 2
    k = meets.nonzero()[0]
    if not k.size:
        return segments
    j = second[k]
    # Every line's cos, sin and radius, for the two segments of every meeting in two gathers.
    line = np.array([np.cos(angle_rad), np.sin(angle_rad), radius_m])
    cos_k, sin_k, radius_k = line.take(k, axis=1)
    cos_j, sin_j, radius_j = line.take(j, axis=1)
    sine = sin_j * cos_k - cos_j * sin_k                      # sin(angle_j - angle_k)
    # Parallel neighbours give inf / NaN here, and so no return inside reach.
    corner_x = (radius_k * sin_j - radius_j * sin_k) / sine
    corner_y = (radius_j * cos_k - radius_k * cos_j) / sine
    reach2 = 9.0 * (range_sigma_m ** 2
                    + (corner_x * corner_x + corner_y * corner_y) * bearing_sigma_rad ** 2
                    ) / (sine * sine)
    # Both meeting ends at once: columns [0, K) walk back from the ends of segments k, columns
    # [K, 2 K) forward from the starts of segments j (axis 1 of the (window, 2, K) views).
    position = _end_windows(stop[k] - 1, start[j], window)
    halves = (window, 2, k.size)
    dx = x_m.take(position, mode='wrap').reshape(halves) - corner_x
    dy = y_m.take(position, mode='wrap').reshape(halves) - corner_y
    # The run from the end is the first return outside (a last row that is never inside).
    inside = np.zeros((window + 1, 2 * k.size), dtype=bool)
    np.less(dx * dx + dy * dy, reach2, out=inside[:window].reshape(halves))
    run = inside.argmin(axis=0)
    room = np.maximum(stop - start - min_returns, 0)
    meets_previous = np.concatenate((meets[-1:], meets[:-1]))
    allowance = np.where(meets & meets_previous, room // 2, room)
    stop, start = stop.copy(), start.copy()
    stop[k] -= np.minimum(run[:k.size], allowance[k])
    start[j] += np.minimum(run[k.size:], allowance[j])
    return _within_contour(start, stop, segments.chain, contour_length)


def trim_offset(segments: SegmentRanges, x_m: np.ndarray, y_m: np.ndarray, lines: Lines,
                noise: Noise, min_returns: int, threshold_sigmas: float,
                window: int) -> SegmentRanges:
    """
    Cut off the returns at segment ends that lie off the line of the segment's other returns.

    IEPF leaves a run of returns from another surface at a segment's end when the run stays
    within its threshold of the chord: a box beside a wall, met at a shallow angle, or a chair
    leg a few cm in front of it, whose returns then join the wall in some scans and not in
    others, and move its line by more than its covariance says. The last k returns at an end
    are tested against the line of the segment's other returns, not against a line they have
    pulled towards themselves (a deleted-residual test). In the frame of the segment's line
    (angle, radius), each return has a coordinate t along it and a residual e across it; the
    other returns' line is the least-squares line e = a + b t through theirs (m returns,
    t-mean t_m, sum of squares S_tt about it; to first order the orthogonal fit of those
    returns). With z_j = (e_j - a - b t_j) / sigma_j, sigma_j = sqrt(range_sigma^2 +
    (rho_j bearing_sigma)^2), the k returns sum to Z_k, normal with mean 0 on one line and
    variance at most k + s^2 (W^2 / m + (T - t_m W)^2 / S_tt), W and T the sums of 1 / sigma_j
    and t_j / sigma_j over the k returns and s^2 the mean sigma^2 of the other returns (the
    noise is an upper bound of the scatter across the line; the second term is their line's
    own error carried to the end). An end is cut after the k that maximises Z_k^2 / Var(Z_k),
    when that maximum exceeds ``threshold_sigmas`` squared. Each end cuts at most half of the
    returns a segment has beyond ``min_returns``, so that the rule does not depend on the beam
    order. At most ``window`` returns are examined at each end.

    The same sums, for every segment end and every k at once.

    :param segments: segments sorted by start position (positions modulo n)
    :param x_m: x of the returns in position order, shape (n,), m
    :param y_m: y of the returns in position order, shape (n,), m
    :param lines: each segment's line (the frame)
    :param noise: the noise (the rule decides with its deciding_sigma_m)
    :param min_returns: never cut a segment below this many returns
    :param threshold_sigmas: cut where max_k |Z_k| / sqrt(Var(Z_k)) exceeds this
    :param window: most returns examined (and cut) at each end
    :return: the trimmed segments
    """
    count = len(segments)
    if not count:
        return segments
    start, stop = segments.start, segments.stop
    angle_rad, radius_m = lines.angle_rad, lines.radius_m
    range_sigma_m, bearing_sigma_rad = noise.deciding_sigma_m, noise.bearing_sigma_rad
    # Every segment's returns laid end to end, each in its line's frame (t along, e across),
    # and each segment's sums of t, t^2, e, t e and rho^2.
    returns = stop - start
    offsets = np.add.accumulate(returns) - returns
    position = np.arange(offsets[-1] + returns[-1]) + (start - offsets).repeat(returns)
    x, y = x_m.take(position, mode='wrap'), y_m.take(position, mode='wrap')
    c, s, radius = np.array([np.cos(angle_rad), np.sin(angle_rad), radius_m]).repeat(returns,
                                                                                     axis=1)
    # Per return: t, t^2, e, t e, rho^2 and the weight 1 / sigma.
    terms = np.empty((6, position.size))
    t, _, e, _, rho2, _ = terms
    np.subtract(y * c, x * s, out=t)
    np.subtract(x * c + y * s, radius, out=e)
    np.multiply(t, t, out=terms[1])
    np.multiply(t, e, out=terms[3])
    np.add(x * x, y * y, out=rho2)
    np.divide(1.0, np.sqrt(range_sigma_m ** 2 + rho2 * bearing_sigma_rad ** 2), out=terms[5])
    whole = np.add.reduceat(terms[:5], offsets, axis=1)
    # Columns [0, S) walk back from the segments' ends, columns [S, 2 S) forward from their
    # starts; row k - 1 holds the sums over the k returns nearest the end. A window longer than
    # its segment reads on into the next segment's returns: those k exceed the segment's room,
    # and are never cut at.
    near = terms.take(_end_windows(offsets + returns - 1, offsets, window), axis=1, mode='clip')
    t, e, weight = near[0], near[2], near[5]
    rest_t, rest_tt, rest_e, rest_te, rest_rr = (
        np.concatenate((whole, whole), axis=1)[:, None, :] - np.add.accumulate(near[:5], axis=1))
    sum_z, sum_w, sum_tw = np.add.accumulate(np.array([e * weight, weight, t * weight]), axis=1)
    k = np.arange(1, window + 1)[:, None]
    both_ends = np.concatenate((returns, returns))            # columns as in ``near``
    m = both_ends - k
    with np.errstate(divide='ignore', invalid='ignore'):
        mean_t, mean_e = rest_t / m, rest_e / m
        spread = rest_tt - m * mean_t * mean_t                              # S_tt
        slope = (rest_te - m * mean_t * mean_e) / spread
        lever = sum_tw - mean_t * sum_w                                     # T - t_m W
        total = sum_z - mean_e * sum_w - slope * lever
        scatter = range_sigma_m ** 2 + bearing_sigma_rad ** 2 * rest_rr / m
        score = total * total / (k + scatter * (sum_w * sum_w / m + lever * lever / spread))
    room = (both_ends - min_returns) // 2
    # Too few returns left for a cut, or a NaN line (never kept by the pipeline): no cut; nor
    # from the first k whose other returns lie at one point along the line (no line of theirs).
    spread_left = np.logical_and.accumulate(spread > 0.0, axis=0)
    score[(k > room) | np.isnan(score) | ~spread_left] = -np.inf
    over = np.maximum.reduce(score, axis=0) > threshold_sigmas * threshold_sigmas
    if not np.count_nonzero(over):
        return segments
    cut = (score.argmax(axis=0) + 1) * over
    return _within_contour(start + cut[count:], stop - cut[:count], segments.chain, len(x_m))


def _end_windows(last: np.ndarray, first: np.ndarray, window: int) -> np.ndarray:
    """
    Return the positions of the returns within ``window`` of segment ends, from the end inwards.

    :param last: last position of some segments, shape (A,)
    :param first: first position of some segments, shape (B,)
    :param window: returns per end
    :return: shape (window, A + B): columns [0, A) walk back from ``last``, columns [A, A + B)
        forward from ``first``; positions are not wrapped (gather with ``take(mode='wrap')``)
    """
    steps = np.arange(window)[:, None]
    position = np.empty((window, last.size + first.size), dtype=np.intp)
    np.subtract(last, steps, out=position[:, :last.size])
    np.add(first, steps, out=position[:, last.size:])
    return position


def _within_contour(start: np.ndarray, stop: np.ndarray, chain: np.ndarray,
                    contour_length: int) -> SegmentRanges:
    """Return trimmed segments; one that crosses the contour's end may start past it: to [0, n)."""
    wrapped = (start >= contour_length) * contour_length
    return SegmentRanges(start - wrapped, stop - wrapped, chain)
