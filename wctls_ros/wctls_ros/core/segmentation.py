"""
Split a scan into straight segments: breakpoints, Iterative End Point Fit, statistical merging.

Positions here index the scan's valid returns in *circular order*: for a full turn the order is
rotated to start at a breakpoint (or, on a closed contour without any, at the farthest return),
so a wall crossing the +-pi seam is an ordinary run of positions. SegmentRanges are half-open
position ranges [start, stop) into that order; on a full turn a segment may run past its end
(positions count modulo the number of returns).
"""

from dataclasses import dataclass
import math
from typing import Callable

import numpy as np

from ._linalg import mahalanobis_squared_2x2
from .scan import ScanPoints

# A chord shorter than this (m) has no usable direction: distances are measured from its start.
_MIN_CHORD_M = 1e-9
# A segment needs this many returns to be fitted (and so to take part in merging).
MIN_FIT_RETURNS = 3


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


def breakpoints(points: ScanPoints, range_sigma_m: float, bearing_sigma_rad: float,
                lambda_rad: float) -> np.ndarray:
    """
    Mark where the adaptive breakpoint rule of Borges and Aldon separates neighbouring returns.

    Neighbours i-1 and i are separated when their distance exceeds
    ``r sin(dphi) / sin(lambda - dphi) + 3 sqrt(range_sigma^2 + (r bearing_sigma)^2)``
    (r the smaller of the two ranges, dphi their bearing difference, so that missing beams widen
    the allowance; the last term is 3 sigma of a return's position noise, where Borges and Aldon
    have the range noise alone), or when ``dphi >= lambda``. The rule is symmetric, so reversing
    the beam order changes nothing.

    :param points: the scan's valid returns
    :param range_sigma_m: range noise std, m
    :param bearing_sigma_rad: bearing noise std, rad
    :param lambda_rad: worst incidence angle still treated as one surface, rad
    :return: boolean, shape (n,): True where return i starts a new chain (entry 0 refers to the
        seam between the last and the first return of a full turn, and is True otherwise)
    """
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=bool)
    x, y, rho, index = points.xy_m[:, 0], points.xy_m[:, 1], points.range_m, points.index
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
    reach = np.full(n, math.sin(step) / math.sin(lambda_rad - step) if step < lambda_rad
                    else -1.0)
    wider = np.flatnonzero(beams != 1.0)
    if wider.size:
        dphi = beams[wider] * step
        with np.errstate(divide='ignore', invalid='ignore'):
            reach[wider] = np.where(dphi < lambda_rad,
                                    np.sin(dphi) / np.sin(lambda_rad - dphi), -1.0)
    allowed = r * reach + 3.0 * np.sqrt(range_sigma_m ** 2 + (r * bearing_sigma_rad) ** 2)
    separated = (reach < 0.0) | (dx * dx + dy * dy > allowed * allowed)
    if not points.full_turn or n == 1:
        separated[0] = True
    return separated


def chains(points: ScanPoints, separated: np.ndarray) -> Chains:
    """
    Group the returns into chains between breakpoints, in circular order.

    A closed contour (a full turn without any breakpoint) is cut at the farthest return s and at
    the return farthest from s, both left out like IEPF split points, into two arcs of one
    chain: a choice that depends neither on where the scan's seam lies nor on the beam order.

    :param points: the scan's valid returns
    :param separated: output of :func:`breakpoints`
    :return: the chains
    """
    n = len(points)
    breaks = np.flatnonzero(separated)
    if n and not breaks.size:
        first = int(np.argmax(points.range_m))
        order = np.roll(np.arange(n), -first)
        relative = points.xy_m[order] - points.xy_m[first]
        opposite = int(np.argmax(relative[:, 0] ** 2 + relative[:, 1] ** 2))
        start, stop, chain = np.array([1, opposite + 1]), np.array([opposite, n]), np.zeros(2)
    else:
        first = int(breaks[0]) if n else 0
        order = np.roll(np.arange(n), -first)
        start = breaks - first
        stop = np.append(start[1:], n) if n else start
        chain = np.arange(start.size)
    return Chains(order, start, stop, chain.astype(np.intp))


def iterative_end_point_fit(x_m: np.ndarray, y_m: np.ndarray, start: np.ndarray,
                            stop: np.ndarray, chain: np.ndarray,
                            threshold_m: float) -> SegmentRanges:
    """
    Split runs of returns where a return lies farther than a threshold from the run's chord.

    All runs are processed together, one split level per pass. The return at a split is the
    one nearest the corner and belongs to neither side (it would otherwise be shared, or bias
    one wall); merging restores it when the two sides turn out to be one line.

    :param x_m: x of the returns in position order, shape (m,), m
    :param y_m: y of the returns in position order, shape (m,), m
    :param start: first position of each run, shape (K,)
    :param stop: one past the last position of each run, shape (K,)
    :param chain: the chain of each run, shape (K,)
    :param threshold_m: the IEPF split distance, m
    :return: the segments, sorted by start position
    """
    done = []
    start, stop, chain = (np.asarray(a, dtype=np.intp) for a in (start, stop, chain))
    while start.size:
        done.append((start, stop, chain))          # provisional: replaced below if split
        counts = stop - start
        splittable = counts >= 3
        if not splittable.all():
            done[-1] = (start[~splittable], stop[~splittable], chain[~splittable])
            start, stop, chain, counts = (a[splittable] for a in (start, stop, chain, counts))
            if not start.size:
                break
            done.append((start, stop, chain))
        # Distance of every return of each run to the line through the run's end points.
        x0, y0 = x_m[start], y_m[start]
        dx, dy = x_m[stop - 1] - x0, y_m[stop - 1] - y0
        length = np.hypot(dx, dy)
        length[length <= _MIN_CHORD_M] = np.inf    # no direction: never split at distance 0
        nx, ny = -dy / length, dx / length
        offsets = np.cumsum(counts) - counts
        position = np.arange(offsets[-1] + counts[-1]) + np.repeat(start - offsets, counts)
        distance = np.abs((x_m[position] - np.repeat(x0, counts)) * np.repeat(nx, counts)
                          + (y_m[position] - np.repeat(y0, counts)) * np.repeat(ny, counts))
        farthest = np.maximum.reduceat(distance, offsets)
        split = farthest > threshold_m
        if not split.any():
            break
        done[-1] = (start[~split], stop[~split], chain[~split])
        # The first return of each split run at its maximum distance is the split point.
        at_max = np.flatnonzero(distance == np.repeat(np.where(split, farthest, -1.0), counts))
        run = np.searchsorted(offsets, at_max, side='right') - 1
        first = np.empty(run.size, dtype=bool)
        first[0] = True
        np.not_equal(run[1:], run[:-1], out=first[1:])
        cut, parent = position[at_max[first]], run[first]
        start = np.concatenate([start[parent], cut + 1])
        stop = np.concatenate([cut, stop[parent]])
        chain = np.concatenate([chain[parent], chain[parent]])
        keep = stop > start
        start, stop, chain = start[keep], stop[keep], chain[keep]
    start, stop, chain = (np.concatenate(parts) for parts in zip(*done))
    order = np.argsort(start, kind='stable')
    return SegmentRanges(start[order], stop[order], chain[order])


def merge_collinear(segments: SegmentRanges, circular: bool, contour_length: int,
                    fit: Callable[[SegmentRanges], tuple], chi2_threshold: float
                    ) -> SegmentRanges:
    """
    Merge neighbouring segments that are statistically the same line.

    Neighbours are consecutive segments on one chain, or on two chains that touch (no return
    between them: the breakpoint between them may be noise, e.g. a bearing error at grazing
    incidence; a real occlusion never puts the same line on both sides). Each pass fits every
    segment, computes for each neighbouring pair the squared Mahalanobis distance of the
    difference of their (angle, radius) under the sum of the two covariances (independent
    returns), and merges the pairs below ``chi2_threshold``, lowest first, each segment at most
    once per pass. A merged segment spans both, including
    any return between them left out by the split. Passes repeat until nothing merges.

    :param segments: segments with >= 3 returns each, sorted by start position
    :param circular: whether the returns cover a full turn (the last and first can be neighbours)
    :param contour_length: number of returns n (positions wrap modulo n)
    :param fit: returns (angle (S,) rad, radius (S,) m, covariance (S, 2, 2)) of segments
    :param chi2_threshold: merge below this squared Mahalanobis distance (0: never merge)
    :return: the merged segments
    """
    while len(segments) >= 2 and chi2_threshold > 0.0:
        count = len(segments)
        second = np.arange(1, count + 1) % count
        touching = segments.stop % contour_length == segments.start[second]
        pair_ok = (segments.chain == segments.chain[second]) | touching
        if not circular or count < 3:
            pair_ok[-1] = False                     # the last segment has no successor
        # A merged segment must not wrap onto itself around a closed contour.
        wrapped_stop = segments.stop[second] + np.where(second == 0, contour_length, 0)
        pair_ok &= wrapped_stop - segments.start <= contour_length
        angle, radius, covariance = fit(segments)
        diff = np.empty((count, 2))
        diff[:, 0] = np.remainder(angle - angle[second] + np.pi, 2.0 * np.pi) - np.pi
        diff[:, 1] = radius - radius[second]
        distance = mahalanobis_squared_2x2(diff, covariance + covariance[second])
        with np.errstate(invalid='ignore'):
            candidates = np.flatnonzero(pair_ok & (distance < chi2_threshold))
        if not candidates.size:
            break
        used = np.zeros(count, dtype=bool)
        stop, chain = segments.stop.copy(), segments.chain.copy()
        for k in candidates[np.argsort(distance[candidates], kind='stable')]:
            j = second[k]
            if not (used[k] or used[j]):
                used[k] = used[j] = True
                stop[k] = wrapped_stop[k]
                # Two chains joined by a merged segment are one chain from now on.
                chain[chain == chain[j]] = chain[k]
        absorbed = np.zeros(count, dtype=bool)
        absorbed[second[stop != segments.stop]] = True
        segments = SegmentRanges(segments.start, stop, chain).select(~absorbed)
    return segments


def trim_ambiguous_ends(segments: SegmentRanges, circular: bool, contour_length: int,
                        x_m: np.ndarray, y_m: np.ndarray, angle_rad: np.ndarray,
                        radius_m: np.ndarray, range_sigma_m: float, bearing_sigma_rad: float,
                        min_returns: int, window: int = 8) -> SegmentRanges:
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
    when both meet a neighbour (so that the rule does not depend on the beam order).

    :param segments: segments sorted by start position (positions modulo contour_length)
    :param circular: whether the returns cover a full turn (the last and first can meet)
    :param contour_length: number of returns n
    :param x_m: x of the returns in position order, shape (n,), m
    :param y_m: y of the returns in position order, shape (n,), m
    :param angle_rad: normal angle of each segment's line, shape (S,), rad
    :param radius_m: radius of each segment's line, shape (S,), m
    :param range_sigma_m: range noise std, m
    :param bearing_sigma_rad: bearing noise std, rad
    :param min_returns: never trim a segment below this many returns
    :param window: most returns examined (and trimmed) at each end
    :return: the trimmed segments
    """
    count = len(segments)
    if count < 2:
        return segments
    second = np.arange(1, count + 1) % count
    neighbours = np.ones(count, dtype=bool)
    neighbours[-1] = circular and count > 2
    k = np.flatnonzero(neighbours
                       & ((segments.start[second] - segments.stop) % contour_length <= 1))
    if not k.size:
        return segments
    j = second[k]
    sine = np.abs(np.sin(angle_rad[k] - angle_rad[j]))
    with np.errstate(divide='ignore', invalid='ignore'):
        det = 1.0 / np.sin(angle_rad[j] - angle_rad[k])
    corner_x = (radius_m[k] * np.sin(angle_rad[j]) - radius_m[j] * np.sin(angle_rad[k])) * det
    corner_y = (radius_m[j] * np.cos(angle_rad[k]) - radius_m[k] * np.cos(angle_rad[j])) * det
    tolerance = 3.0 * np.sqrt(range_sigma_m ** 2
                              + (corner_x ** 2 + corner_y ** 2) * bearing_sigma_rad ** 2)
    with np.errstate(divide='ignore'):
        reach2 = (tolerance / sine) ** 2
    steps = np.arange(window)

    def run_inside(positions):
        # Unbroken run (from column 0) of returns within reach of the lines' intersection.
        position = positions % contour_length
        inside = ((x_m[position] - corner_x[:, None]) ** 2
                  + (y_m[position] - corner_y[:, None]) ** 2) < reach2[:, None]
        return np.cumprod(inside, axis=1).sum(axis=1)

    room = np.maximum(segments.stop - segments.start - min_returns, 0)
    meets_next = np.zeros(count, dtype=bool)
    meets_next[k] = True
    meets_previous = np.zeros(count, dtype=bool)
    meets_previous[j] = True
    allowance = np.where(meets_next & meets_previous, room // 2, room)
    stop, start = segments.stop.copy(), segments.start.copy()
    stop[k] -= np.minimum(run_inside(segments.stop[k][:, None] - 1 - steps), allowance[k])
    start[j] += np.minimum(run_inside(segments.start[j][:, None] + steps), allowance[j])
    # A segment that crosses the end of the contour may now start past it: back to [0, n).
    wrapped = np.where(start >= contour_length, contour_length, 0)
    return SegmentRanges(start - wrapped, stop - wrapped, segments.chain)
