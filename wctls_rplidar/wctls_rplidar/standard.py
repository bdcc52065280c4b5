# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Standard nodes (answer type 0x81) a damaged link cannot slip past: sequence and neighbours (pure).

A standard node carries no checksum: two check bits (S = not S-bar, C = 1) pass a quarter of
misaligned or corrupted nodes, whose angle and distance are then garbage (up to 512 degrees and
65 m). :class:`CheckedStandardNodeDecoder` decodes as the SDK does
(:class:`~wctls_rplidar.protocol.StandardNodeDecoder`) and then keeps a node only where

1. its angle is below 360 degrees (the field reaches 512), and
2. it continues the angle sequence: from the node before it or to the node after it, the angle
   advances by the nodes between them (counted by stream bytes) times the angle step, within
   :data:`SEQUENCE_TOLERANCE_STEPS` steps (plus a tenth of a step per node between). The step
   is the median advance of consecutive nodes, followed as the device turns. A garbage angle,
   uniform over 512 degrees, passes about 2 x 2 x 1.5 / 512 of the time at a 0.9 degree step.

A node failing either is dropped (counted as rejected): its bearing is unknown. While the link
shows damage (a resync or a dropped node within the last :data:`DAMAGE_MEMORY_NODES` nodes),
a corrupted distance byte, which no check bit covers, is also likely: then a node's distance is
published only where a neighbour pair predicts it
(:func:`~wctls_rplidar.capsules.supported_by_neighbours`, as in a dense capsule that failed
its checksum, with the range noise measured the same way), else as no return (rejected). On a
clean link every node the check bits pass is published as it is.

Where the damage is heavier than these checks can sort out (more than :data:`MAX_RESYNC_SHARE`
resyncs per node over the last :data:`DAMAGE_MEMORY_NODES` nodes: from about 5 % corrupted or
2-5 % dropped or inserted bytes on, where the emulator's streams showed 0.1-16 % of the nodes
kept wrong; or more than :data:`MAX_OUT_OF_SEQUENCE_SHARE` of them dropped, repeats of the
nodes just before aside: from about 20 % frames with bits flipped in two bytes, which spoil
both distance bytes of a tenth of the nodes at 30 %, 0.2-1.7 % of those kept wrong), no node is
kept at all until the link recovers: nothing is published rather than a guess.
"""

import math
from typing import Optional

import numpy as np

from .capsules import RangeNoise, supported_by_neighbours
from .framing import LinkDamage
from .protocol import NODE_SIZE, Samples, StandardNodeDecoder, StreamCounts

FULL_TURN_DEG = 360.0
SEQUENCE_TOLERANCE_STEPS = 1.5
# How much more a node's angle may stray per node between it and its neighbour, steps.
TOLERANCE_GROWTH_PER_NODE = 0.1
# Nodes after a sign of damage during which distances need their neighbours' support.
DAMAGE_MEMORY_NODES = 2000
# Consecutive nodes whose advances measure the step (at least), and the plausible steps, deg
# (32 kHz at 5 Hz to 2 kHz at 15 Hz).
_STEP_SAMPLE = 32
MAX_RESYNC_SHARE = 0.08
MAX_OUT_OF_SEQUENCE_SHARE = 0.1
# Bits flipped in both distance bytes (no check bit sees them) spoil a tenth of the nodes at 30 %
# flipped frames: the range noise is measured on the lower quartile of second differences.
_NOISE_QUANTILE = 0.25
# A node sent again (a frame a link's buffer repeats) is out of sequence but no sign of damage to
# its bytes: it repeats one of the nodes this few before it (a few frames, and repeats between).
_REPEAT_NODES = 16
_PLAUSIBLE_STEP_DEG = (0.05, 3.0)


class CheckedStandardNodeDecoder(StandardNodeDecoder):
    """
    Decode standard nodes, keeping those their sequence vouches for (see the module).

    :param us_per_sample: the mode's sample period, microseconds (unused: the step is measured)
    :param max_distance_m: the mode's range (unused)
    """

    def __init__(self, us_per_sample: Optional[float] = None,
                 max_distance_m: Optional[float] = None):
        super().__init__()
        self._step_deg: Optional[float] = None
        self._previous: Optional[tuple] = None      # the last node kept: (angle, frame end)
        self._noise = RangeNoise(_STEP_SAMPLE, _NOISE_QUANTILE)
        self._nodes_since_damage = DAMAGE_MEMORY_NODES
        self._rejected = 0
        self._seen_resyncs = 0
        # (nodes, resyncs, nodes dropped) of the recent chunks, for their shares per node.
        self._recent: list = []
        self._withheld = False

    @property
    def counts(self) -> StreamCounts:
        """Return what the decoder has met so far (rejected: nodes dropped or emptied)."""
        counts = super().counts
        return StreamCounts(frames=counts.frames, samples=counts.samples,
                            resyncs=counts.resyncs, discarded_bytes=counts.discarded_bytes,
                            rejected_samples=self._rejected)

    @property
    def damage(self) -> LinkDamage:
        """Return whether the last nodes were withheld (no share of bytes: none is measured)."""
        return LinkDamage(None, self._withheld)

    def feed(self, data: bytes) -> Samples:
        """
        Decode what the next received chunk completes, keeping the nodes the sequence vouches for.

        :param data: the next received bytes, any length
        :return: the samples kept, in stream order
        """
        samples = super().feed(data)
        if not len(samples):
            return samples
        angle, end = samples.angle_deg, samples.frame_end
        in_range = angle < FULL_TURN_DEG
        self._measure_step(angle, end, in_range)
        kept = in_range & self._in_sequence(angle, end, in_range)
        resyncs = super().counts.resyncs
        damaged = resyncs > self._seen_resyncs or not kept.all()
        self._recent.append((len(samples), resyncs - self._seen_resyncs,
                             int(np.count_nonzero(~kept & ~_repeats(samples)))))
        self._seen_resyncs = resyncs
        while sum(nodes for nodes, _, _ in self._recent[1:]) >= DAMAGE_MEMORY_NODES:
            del self._recent[0]
        recent_nodes, recent_resyncs, recent_dropped = np.sum(self._recent, axis=0)
        self._withheld = bool(recent_resyncs > MAX_RESYNC_SHARE * recent_nodes
                              or recent_dropped > MAX_OUT_OF_SEQUENCE_SHARE * recent_nodes)
        if self._withheld:
            kept[:] = False             # beyond what the checks sort out: nothing
        self._nodes_since_damage = 0 if damaged else self._nodes_since_damage + len(samples)
        self._rejected += int(np.count_nonzero(~kept))
        index = np.flatnonzero(kept)
        if index.size:
            self._previous = (float(angle[index[-1]]), int(end[index[-1]]))
        distance = samples.distance_mm[index]
        if self._nodes_since_damage < DAMAGE_MEMORY_NODES and index.size and self._step_deg:
            distance = self._supported(distance, self._step_deg)
        return Samples(angle_deg=angle[index], distance_mm=distance,
                       quality=np.where(distance > 0, samples.quality[index], 0).astype(np.uint8),
                       start=samples.start[index], frame_end=end[index],
                       samples_after=samples.samples_after[index], slot=samples.slot[index])

    def _measure_step(self, angle: np.ndarray, end: np.ndarray, in_range: np.ndarray):
        """Follow the angle step: the median advance of consecutive nodes in range."""
        advance = np.mod(np.diff(angle), FULL_TURN_DEG)
        consecutive = ((np.diff(end) == NODE_SIZE) & in_range[1:] & in_range[:-1]
                       & (advance > 0.0))
        if self._step_deg is not None:
            # Once known, only advances near it (garbage ones are uniform over the turn).
            consecutive &= np.abs(advance - self._step_deg) <= self._step_deg
        if np.count_nonzero(consecutive) < _STEP_SAMPLE:
            return
        step = float(np.median(advance[consecutive]))
        low, high = _PLAUSIBLE_STEP_DEG
        if low <= step <= high:
            self._step_deg = step

    def _in_sequence(self, angle: np.ndarray, end: np.ndarray, in_range: np.ndarray):
        """Tell which nodes continue the sequence from their predecessor or to their successor."""
        step = self._step_deg
        if step is None:
            return np.ones(len(angle), bool)
        before_angle = np.r_[np.nan if self._previous is None else self._previous[0], angle[:-1]]
        before_end = np.r_[-1 if self._previous is None else self._previous[1], end[:-1]]
        before_ok = np.r_[self._previous is not None, in_range[:-1]]
        nodes = (end - before_end) / NODE_SIZE
        advance = np.mod(angle - before_angle, FULL_TURN_DEG)
        expected = np.mod(nodes * step, FULL_TURN_DEG)
        error = np.abs(np.mod(advance - expected + 180.0, FULL_TURN_DEG) - 180.0)
        tolerance = step * (SEQUENCE_TOLERANCE_STEPS + TOLERANCE_GROWTH_PER_NODE * (nodes - 1))
        with np.errstate(invalid='ignore'):
            follows = before_ok & in_range & (error <= tolerance)
        # A node the next one follows from is in sequence too (the last waits for no successor).
        return follows | np.r_[follows[1:], False]

    def _supported(self, distance: np.ndarray, step_deg: float) -> np.ndarray:
        """Return the distances a neighbour pair predicts; the others as no return (rejected)."""
        row = distance.reshape(1, -1)
        self._noise.update(row)
        supported = supported_by_neighbours(row, row > 0, self._noise.sigma_mm,
                                            math.radians(step_deg)).reshape(-1)
        emptied = (distance > 0) & ~supported
        self._rejected += int(np.count_nonzero(emptied))
        return np.where(emptied, 0.0, distance)


def _repeats(samples: Samples) -> np.ndarray:
    """Tell which nodes repeat, angle and distance, one of the :data:`_REPEAT_NODES` before."""
    angle, distance = samples.angle_deg, samples.distance_mm
    repeated = np.zeros(len(angle), bool)
    for back in range(1, min(_REPEAT_NODES, len(angle) - 1) + 1):
        repeated[back:] |= (angle[back:] == angle[:-back]) & (distance[back:] == distance[:-back])
    return repeated
