"""
Split a scan into straight segments: breakpoints, Iterative End Point Fit, statistical merging.

Positions here index the scan's valid returns in *circular order*: for a full turn the order is
rotated to start at a breakpoint (or, on a closed contour without any, at the farthest return),
so a wall crossing the +-pi seam is an ordinary run of positions. SegmentRanges are half-open
position ranges [start, stop) into the order laid out twice, so a segment may run past the end
of a closed contour.
"""

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ._linalg import solve_2x2
from .scan import ScanPoints

# A chord shorter than this (m) has no usable direction: distances are measured from its start.
_MIN_CHORD_M = 1e-9
# A segment needs this many returns to be fitted (and so to take part in merging).
MIN_FIT_RETURNS = 3


@dataclass(frozen=True)
class Chains:
    """
    Runs of returns without a breakpoint between neighbours, in circular order.

    :ivar order: indices into the ScanPoints arrays, the circular order laid out twice, (2n,)
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
    xy, rho, bearing = points.xy_m, points.range_m, points.bearing_rad
    if n == 0:
        return np.zeros(0, dtype=bool)
    previous = np.roll(np.arange(n), 1)
    gap = np.hypot(*(xy - xy[previous]).T)
    dphi = np.abs(np.angle(np.exp(1j * (bearing - bearing[previous]))))
    r = np.minimum(rho, rho[previous])
    with np.errstate(divide='ignore', invalid='ignore'):
        allowed = (r * np.sin(dphi) / np.sin(lambda_rad - dphi)
                   + 3.0 * np.hypot(range_sigma_m, r * bearing_sigma_rad))
    separated = (dphi >= lambda_rad) | (gap > allowed)
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
        opposite = int(np.argmax(np.hypot(*(points.xy_m[order] - points.xy_m[first]).T)))
        start, stop, chain = np.array([1, opposite + 1]), np.array([opposite, n]), np.zeros(2)
    else:
        first = int(breaks[0]) if n else 0
        order = np.roll(np.arange(n), -first)
        start = breaks - first
        stop = np.append(start[1:], n) if n else start
        chain = np.arange(start.size)
    return Chains(np.concatenate([order, order]), start, stop, chain.astype(np.intp))


def iterative_end_point_fit(xy_m: np.ndarray, start: np.ndarray, stop: np.ndarray,
                            chain: np.ndarray, threshold_m: float) -> SegmentRanges:
    """
    Split runs of returns where a return lies farther than a threshold from the run's chord.

    All runs are processed together, one split level per pass. The return at a split is the
    one nearest the corner and belongs to neither side (it would otherwise be shared, or bias
    one wall); merging restores it when the two sides turn out to be one line.

    :param xy_m: returns in position order, shape (m, 2), m
    :param start: first position of each run, shape (K,)
    :param stop: one past the last position of each run, shape (K,)
    :param chain: the chain of each run, shape (K,)
    :param threshold_m: the IEPF split distance, m
    :return: the segments, sorted by start position
    """
    done = []
    start, stop, chain = (np.asarray(a, dtype=np.intp) for a in (start, stop, chain))
    while start.size:
        splittable = stop - start >= 3
        done.append((start[~splittable], stop[~splittable], chain[~splittable]))
        start, stop, chain = start[splittable], stop[splittable], chain[splittable]
        if not start.size:
            break
        counts = stop - start
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        owner = np.repeat(np.arange(start.size), counts)
        position = np.arange(counts.sum()) - offsets[owner] + start[owner]
        first, last = xy_m[start], xy_m[stop - 1]
        chord = last - first
        length = np.hypot(chord[:, 0], chord[:, 1])
        has_direction = length > _MIN_CHORD_M
        normal = np.column_stack([-chord[:, 1], chord[:, 0]]) / np.where(
            has_direction, length, 1.0)[:, None]
        relative = xy_m[position] - first[owner]
        distance = np.where(has_direction[owner],
                            np.abs(np.einsum('pi,pi->p', relative, normal[owner])),
                            np.hypot(relative[:, 0], relative[:, 1]))
        farthest = np.maximum.reduceat(distance, offsets)
        split = farthest > threshold_m
        done.append((start[~split], stop[~split], chain[~split]))
        if not split.any():
            break
        # The first return of each run at its maximum distance is the split point.
        at_max = np.flatnonzero(split[owner] & (distance == farthest[owner]))
        first_at_max = at_max[np.r_[True, owner[at_max][1:] != owner[at_max][:-1]]]
        cut = position[first_at_max]
        parent = owner[first_at_max]
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
        diff = np.column_stack([np.angle(np.exp(1j * (angle - angle[second]))),
                                radius - radius[second]])
        with np.errstate(invalid='ignore'):
            distance = np.einsum('pi,pi->p', diff,
                                 solve_2x2(covariance + covariance[second], diff))
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
