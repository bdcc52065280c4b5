# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A capsule decoder that publishes the samples a checksum or their neighbours vouch for (pure).

Every capsule format shares the framing (:mod:`~wctls_rplidar.framing`): the sync nibbles,
the checksum (XOR of the bytes after the first two, its nibbles beside the sync nibbles) and the
start angle. :class:`CheckedCapsuleDecoder` frames a stream of any of them, so that a capsule
cut short is followed at once by the next one, and judges start angles by their sequence. It
reads a capsule's samples with its format's :class:`CapsuleLayout` and publishes their
distances when the checksum passed on a line not otherwise damaged and the start angle is in
sequence. In a capsule that is suspect (it failed its checksum, its start angle was replaced, or
most recent capsules fail: at 5 % corrupted bytes almost none of 84-170 bytes passes) a sample
is published only where the layout finds it plausible (:meth:`CapsuleLayout.plausible`: by
default a neighbour pair of the same capsule predicts its distance, as in dense capsules, with
the range noise measured the same way); the others are published as no return (counted as
rejected samples). Unlike the dense decoder it does not realign the samples of a capsule that
lost bytes: they are all unreadable.

Sample k of N in a capsule lies at ``start + k * sweep / N - correction_k``: the sweep is the
angle to the next capsule's start, and the correction, which formats without one leave at 0,
is the layout's. A turn starts where the uncorrected angles fall back (the corrections may be
larger than the step between samples).
"""

import math
from typing import Optional

import numpy as np

from .capsules import (believed_flips, CapsuleSamples, flip_repairs, RangeNoise,
                       repaired_samples, sharp_repairs, supported_by_neighbours, unseen_flips)
from .framing import AngleTrack, CapsuleFramer, CapsulePlacer, LinkDamage, placeable
from .protocol import Samples, StreamCounts

# The sweep assumed until one is measured: the turn at 10 Hz, degrees per second.
_NOMINAL_DEG_PER_S = 3600.0
_NO_ANGLE_FIELD = 0x7FFF       # a start angle field beyond 360 degrees: no angle
# How far a damaged capsule's timestamp may lie from continuing the step of the two before it,
# microseconds (the device rounds each to a microsecond).
STEADY_TIME_US = 2
# What a sample of an intact capsule is, as its layout's flip check finds it (unseen_flips).
SPIKE = 1
SPIKE_RUN = 2


class CapsuleLayout:
    """
    What a capsule format's bytes after the start angle mean (a subclass per format).

    :cvar size: bytes per capsule
    :cvar samples: samples per capsule
    :cvar reads_successor: a capsule's last samples are read with its successor's first bytes
    :cvar angle_at: the start angle's offset, bytes
    :cvar clock_bits: the bits of the device timestamp it carries, if any
    """

    size = 0
    samples = 0
    reads_successor = False
    angle_at = 2
    clock_bits = 64

    def read(self, capsules: np.ndarray, successors: Optional[np.ndarray]) -> tuple:
        """
        Read the samples of intact capsules.

        :param capsules: shape (n, size), uint8
        :param successors: the capsule after each, shape (n, size), uint8, for a layout that
            reads its successor; a row of zeros where the successor is unknown
        :return: ``(distance_mm, correction_deg)``, each of shape (n, samples): distances
            (0: no return; negative: unreadable) and angle corrections
        """
        raise NotImplementedError

    def plausible(self, distance_mm: np.ndarray, correction_deg: np.ndarray,
                  usable: np.ndarray, sigma_mm: float, step_rad: float) -> np.ndarray:
        """
        Tell which samples of capsules that failed their checksum to believe.

        By default a distance a neighbour pair of the same capsule predicts, as in dense
        capsules: right for a layout whose samples share no bytes that carry a distance.

        :param distance_mm: distances of damaged capsules, shape (n, samples), mm
        :param correction_deg: their angle corrections, shape (n, samples), degrees
        :param usable: which distances are readable and in range
        :param sigma_mm: the range noise scale, mm
        :param step_rad: angle between samples, rad
        :return: shape (n, samples), bool
        """
        return supported_by_neighbours(distance_mm, usable, sigma_mm, step_rad)

    def unseen_flips(self, capsules: np.ndarray, distance_mm: np.ndarray, usable: np.ndarray,
                     sigma_mm: float, step_rad: float, slots: np.ndarray) -> tuple:
        """
        Tell which intact capsules show bits flipped that their checksum cannot see, and where.

        By default :func:`~wctls_rplidar.capsules.unseen_flips` of the repairs
        :meth:`flip_deltas` allows.

        :param capsules: the capsules, shape (n, size), uint8
        :param distance_mm: their distances, shape (n, samples), mm
        :param usable: which distances are readable and in range
        :param sigma_mm: the range noise scale, mm
        :param step_rad: angle between samples, rad
        :param slots: the capsules' stream indices
        :return: ``(shown, spikes)``: the capsules that show a double flip, shape (n,), and
            per sample, shape (n, samples), int: :data:`SPIKE` where it is a lone spike one
            flipped bit repairs, :data:`SPIKE_RUN` where it is one of a run of samples one
            flipped bit moved together (read from one field), else 0
        """
        flips = self.flip_deltas(capsules, distance_mm)
        if flips is None:
            return np.zeros(len(capsules), bool), np.zeros(distance_mm.shape, np.int8)
        return (unseen_flips(len(capsules), flip_repairs(distance_mm, usable, *flips, sigma_mm,
                                                         step_rad, slots)),
                SPIKE * repaired_samples(slots, distance_mm.shape[1], flip_repairs(
                    distance_mm, usable, *flips, sigma_mm, step_rad, slots, between=False)))

    def flip_deltas(self, capsules: np.ndarray, distance_mm: np.ndarray) -> Optional[tuple]:
        """
        Tell how each distance changes when one bit of its bytes flips, and which bit that is.

        :param capsules: intact capsules, shape (n, size), uint8
        :param distance_mm: their distances as read, shape (n, samples), mm
        :return: ``(deltas, bits)`` as :func:`~wctls_rplidar.capsules.flip_repairs` takes them;
            None for a layout that does not say (its capsules then show no double flips)
        """
        return None

    def device_times_us(self, capsules: np.ndarray) -> Optional[np.ndarray]:
        """
        Read the device's timestamps of intact capsules, for a format that carries one.

        :param capsules: shape (n, size), uint8
        :return: shape (n,), microseconds on the device's clock; None without
        """
        return None


def checksum_passes(capsules: np.ndarray) -> np.ndarray:
    """
    Tell which capsules carry their sync nibbles and checksum.

    :param capsules: shape (n, size), uint8
    :return: shape (n,), bool
    """
    received = (capsules[:, 0] & 0x0F) | (capsules[:, 1] << 4)
    return (((capsules[:, 0] >> 4) == 0xA) & ((capsules[:, 1] >> 4) == 0x5)
            & (received == np.bitwise_xor.reduce(capsules[:, 2:], axis=1)))


class SteadyDeviceTimes:
    """
    Tells which capsules' device timestamps to believe, capsule by capsule in stream order.

    A timestamp a checksum vouches for is believed. Another is believed when the two capsules
    just before it were read and it continues their step (within :data:`STEADY_TIME_US`): a
    device's capsules last the same time, and a damaged byte moves one timestamp alone, by a
    whole unit of that byte (at least a microsecond, and twice that in the step test).

    :param clock_bits: the timestamp's bits (32: it wraps, and a step across the wrap counts)
    """

    def __init__(self, clock_bits: int):
        self._wrap = 1 << clock_bits if clock_bits < 64 else None
        self._recent = []           # (slot, timestamp) of the last two capsules read

    def believe(self, slots: np.ndarray, times_us: np.ndarray, read: np.ndarray,
                vouched: np.ndarray) -> np.ndarray:
        """
        Judge the timestamps of the next capsules.

        :param slots: the capsules' stream indices (consecutive capsules: consecutive slots)
        :param times_us: their timestamps as read, microseconds
        :param read: which capsules' bytes were read (the others' timestamps are no evidence)
        :param vouched: which capsules' checksums vouch for them
        :return: the timestamps believed, -1 elsewhere
        """
        believed = np.where(read & vouched, np.asarray(times_us, np.int64), -1)
        for i, (slot, time_us) in enumerate(zip(np.asarray(slots).tolist(),
                                                np.asarray(times_us, np.int64).tolist())):
            if not read[i]:
                self._recent = []
                continue
            if believed[i] < 0 and len(self._recent) == 2:
                (slot_2, time_2), (slot_1, time_1) = self._recent
                second = time_us - 2 * time_1 + time_2
                if self._wrap is not None:
                    second = (second + self._wrap // 2) % self._wrap - self._wrap // 2
                if slot - slot_1 == slot_1 - slot_2 == 1 and abs(second) <= STEADY_TIME_US:
                    believed[i] = time_us
            self._recent = self._recent[-1:] + [(slot, time_us)]
        return believed


def with_checksum(capsules: np.ndarray) -> bytes:
    """
    Set the sync nibbles and checksum of capsules whose other bytes are laid out.

    :param capsules: shape (n, size), uint8, changed in place
    :return: their bytes
    """
    sums = np.bitwise_xor.reduce(capsules[:, 2:], axis=1)
    capsules[:, 0] = 0xA0 | (sums & 0x0F)
    capsules[:, 1] = 0x50 | (sums >> 4)
    return capsules.tobytes()


class _Frame:
    """One capsule once framed (mutable working record of the decoder)."""

    __slots__ = ('slot', 'angle_field', 'raw', 'clean', 'cut', 'end', 'placement', 'suspect',
                 'key')

    def __init__(self, slot, angle_field, raw, clean, cut, end):
        self.slot = slot
        self.angle_field = angle_field
        self.raw = raw                  # its bytes when it is whole, else None
        self.clean = clean
        self.cut = cut
        self.end = end
        self.placement = None
        self.suspect = not clean
        self.key = None if raw is None else raw.tobytes()


class CheckedCapsuleDecoder:
    """
    Incremental decoder of one capsule format that resynchronises capsule by capsule.

    A subclass per format names its ``FRAME_SIZE`` (bytes) and ``SAMPLES_PER_FRAME``.

    :param layout: the format's layout
    :param us_per_sample: the scan mode's microseconds per sample (sets the sweep limit)
    :param max_distance_m: the mode's farthest range; distances beyond are rejected
    """

    def __init__(self, layout: CapsuleLayout, us_per_sample: float, max_distance_m: float):
        self._layout = layout
        # As the dense decoder's (the SDK's for dense capsules): a capsule's sweep at 100 Hz.
        max_sweep_q8 = (360 * 100 * layout.samples
                        // max(1000000 // max(int(us_per_sample), 1), 1)) << 8
        nominal_q8 = round(_NOMINAL_DEG_PER_S * layout.samples * us_per_sample * 1e-6 * 256.0)
        self._max_mm = int(max_distance_m * 1000.0)
        self._counts = dict.fromkeys(StreamCounts.__dataclass_fields__, 0)
        self._angles = AngleTrack(max_sweep_q8, min(max(nominal_q8, 1), max_sweep_q8))
        self._framer = CapsuleFramer(layout.size, self._angles, self._counts, layout.angle_at)
        self._placer = CapsulePlacer(self._angles, self._framer, self._counts)
        self._pending = []              # a placed capsule waiting for its successor's bytes
        self._stream = CapsuleSamples(layout.samples, self._counts)
        self._noise = RangeNoise(layout.samples)
        self._device_times = SteadyDeviceTimes(layout.clock_bits)
        self._withheld = False
        # (slot, bytes, distances, usable) of the last intact capsule judged for flips.
        self._last_intact = None

    @property
    def counts(self) -> StreamCounts:
        """Return what the decoder has met so far (capsules, damage, losses)."""
        return StreamCounts(**self._counts)

    @property
    def damage(self) -> LinkDamage:
        """Return the share of bytes damaged and whether the last samples were withheld."""
        return LinkDamage(self._framer.damage.share, self._withheld)

    def feed(self, data: bytes) -> Samples:
        """
        Decode what the next received chunk completes.

        A capsule is decoded once the header and start angle of the capsule after it have
        arrived (with a layout that reads its successor, once the capsule after it is framed).

        :param data: the next received bytes, any length
        :return: the samples decoded, in stream order
        """
        raw, regions, offset = self._framer.split(data)
        frames = self._frame(raw, regions, offset)
        if frames:
            after = regions[-1].end
            self._placer.place(frames, self._framer.angle_field(raw, after))
        placed = [f for f in frames if placeable(f.placement, f.clean, f.cut)]
        self._counts['lost_frames'] += len(frames) - len(placed)
        if not self._layout.reads_successor:
            return self._samples(placed, [None] * len(placed))
        placed = self._pending + placed
        if not placed:
            return Samples.concat([])
        published, self._pending = placed[:-1], placed[-1:]
        following = {f.slot: f for f in placed}
        return self._samples(published, [following.get(f.slot + 1) for f in published])

    def _frame(self, raw: np.ndarray, regions: list, offset: int) -> list:
        """
        Cut regions into capsules.

        A capsule of a region that lost or gained bytes is unreadable; only the first one's
        start angle, behind the header framing verified, is known.

        :param raw: the bytes held by the framer
        :param regions: the complete regions in them
        :param offset: the stream offset of ``raw[0]``
        :return: the capsules, a list of ``_Frame``
        """
        size = self._layout.size
        frames = []
        for pos, count, end, slot, lost, cut, tangled in regions:
            for j in range(count):
                at = pos + size * j
                frame_end = offset + min(end, at + size)
                if not lost and not tangled:
                    capsule = raw[at:at + size].copy()
                    frames.append(_Frame(slot + j, self._framer.angle_field(capsule, 0),
                                         capsule, bool(checksum_passes(capsule[None])[0]),
                                         False, frame_end))
                    continue
                field = self._framer.angle_field(raw, pos) if j == 0 else _NO_ANGLE_FIELD
                frames.append(_Frame(slot + j, field, None, False, cut or lost < 0 or tangled,
                                     frame_end))
        self._counts['frames'] += len(frames)
        self._counts['damaged_frames'] += sum(not f.clean for f in frames)
        return frames

    def _flip_signs(self, capsules: np.ndarray, distances: np.ndarray, usable: np.ndarray,
                    slots: np.ndarray, step_rad: float, after: Optional[tuple]) -> tuple:
        """
        Return the layout's signs of unseen flips of intact capsules (``unseen_flips``).

        The capsules are judged between the last intact one before them (when it was the
        capsule just before the first: a spike among the first samples is lone only against
        their predecessors) and the intact capsule after the last (whose first cabin the last
        one's last sample is read with, in a layout that reads its successor).

        :param after: ``(slot, bytes, distances, usable)`` of the capsule after the last, None
            when it is not intact or not the next one
        """
        before = self._last_intact
        self._last_intact = (int(slots[-1]), capsules[-1], distances[-1], usable[-1])
        rows = [before] if before is not None and before[0] == slots[0] - 1 else []
        rows += [(int(slot), *columns) for slot, *columns in zip(slots, capsules, distances,
                                                                 usable)]
        rows += [after] if after is not None else []
        first = 1 if before is not None and before[0] == slots[0] - 1 else 0
        slot, raw, distance, use = (np.array(column) for column in zip(*rows))
        shown, spikes = self._layout.unseen_flips(raw, distance, use, self._noise.sigma_mm,
                                                  step_rad, slot)
        return shown[first:first + len(slots)], spikes[first:first + len(slots)]

    def _intact_after(self, frame, successor) -> Optional[tuple]:
        """Return the successor of a capsule as :meth:`_flip_signs` takes it, if intact."""
        if successor is None or successor.raw is None or not successor.clean or (
                successor.slot != frame.slot + 1):
            return None
        size = self._layout.size
        distances, _ = self._layout.read(
            successor.raw[None], np.zeros((1, size), np.uint8) if self._layout.reads_successor
            else None)
        return (successor.slot, successor.raw, distances[0],
                (distances[0] >= 0) & (distances[0] <= self._max_mm))

    def _samples(self, frames: list, successors: list) -> Samples:
        """Lay out the placed capsules' samples; reject those not vouched for."""
        count, per = len(frames), self._layout.samples
        if not count:
            return Samples.concat([])
        # A successor's first bytes count only when its checksum vouches for them.
        blank = np.zeros(self._layout.size, np.uint8)
        whole = [f.raw if f.raw is not None else blank for f in frames]
        after = [s.raw if s is not None and s.raw is not None and s.clean else blank
                 for s in successors]
        distances, corrections = self._layout.read(
            np.array(whole), np.array(after) if self._layout.reads_successor else None)
        readable = np.array([f.raw is not None for f in frames])[:, None] & (distances >= 0)
        suspect = np.array([f.suspect for f in frames])
        self._noise.update(np.where(readable, distances, 0.0))
        usable = readable & (distances <= self._max_mm)
        step_rad = math.radians(self._angles.sweep_deg() / per)
        trusted = ~suspect & readable.any(axis=1)
        spiked = np.zeros(distances.shape, bool)
        if trusted.any():
            shown, spikes = self._flip_signs(
                np.array(whole)[trusted], distances[trusted], usable[trusted],
                np.array([f.slot for f in frames])[trusted], step_rad,
                self._intact_after(frames[-1], successors[-1]) if trusted[-1] else None)
            if believed_flips(self._placer, shown, self._noise.sigma_mm, self._max_mm):
                # The checksum let damage by: no capsule of the batch vouches for its samples.
                suspect[:] = True
            elif sharp_repairs(self._noise.sigma_mm, self._max_mm):
                # A double flip whose second bit moved a sample too little to show leaves one
                # spike. On a smooth scene a run of samples that one flip moved together is no
                # clutter's; a lone sample may be, and is left out only on a line that shows
                # damage (an intact line's clutter is published as it is).
                spiked[trusted] = spikes >= (SPIKE if self._placer.shows_damage() else SPIKE_RUN)
        vouched = usable & ~suspect[:, None] & ~spiked
        clean = np.array([f.clean for f in frames])
        if suspect.any():
            plausible = self._layout.plausible(distances[suspect], corrections[suspect],
                                               usable[suspect], self._noise.sigma_mm, step_rad)
            # Until the line's damage is measured, neighbours vouch for no capsule that failed
            # its checksum: packets swapped in the first capsules move a capsule's samples
            # into another whole, and they agree with each other.
            vouched[suspect] = (usable[suspect] & (distances[suspect] > 0) & plausible
                                & (self._framer.damage.measured | clean[suspect])[:, None])
        self._withheld = bool(suspect.any()) and self._framer.damage.withheld(
            4 * clean.sum() < clean.size)
        if self._withheld:
            # Nor one that passed its checksum: on such a line 1 in 256 damaged capsules does.
            vouched[:] = False
        keep = vouched | (readable & (distances == 0))
        self._counts['rejected_samples'] += int(np.count_nonzero(~keep))
        distance = np.where(keep, distances, 0).reshape(-1).astype(np.float64)
        times = self._layout.device_times_us(np.array(whole))
        if times is not None:
            times = np.repeat(self._device_times.believe(
                np.array([f.slot for f in frames]), times,
                np.array([f.raw is not None for f in frames]), ~suspect), per)
        return self._stream.of(frames, distance,
                               np.where(readable, corrections, 0.0).reshape(-1), times)
