# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The dense capsule stream (answer 0x85, the S1's DenseBoost), recovered capsule by capsule (pure).

SLAMTEC's SDK drops a capsule whose checksum fails and, with it, the capsule before (its sweep
needs the next start angle); after a lost byte it searches byte by byte. On a line that damages
1 % of the bytes that loses more than half of the samples, at 5 % nearly all (a capsule is 84
bytes: 0.95^84 = 1.3 % arrive intact), and the 1 in 256 damaged capsules that pass the 8-bit
checksum are published as measured. This decoder uses what the stream guarantees besides the
checksum, in four steps:

1. Framing. Capsules are 84 bytes apart. A capsule cut short (a run of lost bytes up to its
   end: a lost USB packet, an overrun buffer) is followed at once by the next: from a capsule
   header (sync nibbles A, 5) the next capsule starts at the first header within 84 bytes whose
   start angle lies one sweep on (a false header in the distances has a random angle), else 84
   bytes on, else the next one is looked for within 12 bytes per capsule of 84, 168 or 252
   bytes on (or exactly up to 672 bytes on): the region between two headers holds ``n``
   capsules (headers in between may be damaged) that lost ``d`` bytes. Bytes are lost, never
   gained: a region longer than its capsules was framed on a false header, and its samples are
   unreadable. Only without any header is sync lost and searched byte by byte, as by the SDK.
2. Realignment. In a region that lost ``d`` bytes each distance lies 0..d bytes before its
   place; the shift grows at each lost byte, whose sample is lost with it. A distance read one
   byte off is a byte of one sample and a byte of the next, off by multiples of 256 mm, while
   neighbouring samples of a surface agree: each sample's shift is found by dynamic programming
   as the monotone path, ending at ``d`` at the region's end, whose neighbours agree best. Only
   bytes between the two headers are read. A run of lost bytes is one move over the samples it
   took; one that reached the next header ends the path early, and where its place is in doubt
   the samples in doubt are left out rather than read a sample or more late. (Where a sample
   lost both its bytes among scattered losses, its place among smooth neighbours cannot be
   told: the samples up to the previous lost byte may land one sample step, 0.39 degrees, off.)
3. Angles. Start angles advance by one capsule's sweep: a start angle is believed when it lies
   within 1/8 degree of the one predicted from the last believed capsule (1/8 of a sweep, for
   the motor's speed, for a capsule whose checksum passed on a line not otherwise damaged), or,
   without a recent prediction, when it and its successor's
   advance like the capsules before. Otherwise the predicted angle is used (counted as
   replaced), unless the prediction may be the wrong one: an intact capsule out of sequence
   says it lost count of capsules, and in a region that lost a run of bytes a capsule may be
   framed where none began; such a capsule is lost, as one with nothing to predict from.
   Sample k lies at
   ``start + k * sweep / 40`` as in the SDK, the sweep from the next start angle when it is in
   step, else the tracked one.
4. Plausibility. A capsule that failed its checksum, was realigned or had its angle replaced is
   suspect, and so are all capsules while most recent ones fail (1 in 256 damaged capsules
   passes the checksum: on such a line a pass proves little). In a suspect capsule a distance
   is kept only if a neighbour pair of the same capsule predicts it (interpolated from both
   sides, or extrapolated from either) within 4 sigmas of the range noise plus the curvature a
   straight surface has in polar coordinates: a single damaged byte is a jump no surface makes
   there. The noise is the median second difference of recent capsules. Distances beyond the
   mode's range are rejected in every capsule. Rejected and unreadable samples are published
   as no return, and counted.

On an undamaged stream the output is exactly the SDK's, and nothing is rejected.
"""

from dataclasses import dataclass
import math
from typing import Optional

import numpy as np

from .protocol import (CAPSULE_SIZE, DENSE_RETURN_QUALITY, FULL_TURN_Q6, Samples,
                       SAMPLES_PER_CAPSULE, StreamCounts)

FULL_TURN_Q8 = FULL_TURN_Q6 << 2
# Bytes per capsule that framing and realignment follow (at 5 % lost bytes, 0.04 % of the
# capsules lose more), and capsules between two headers: up to two damaged headers in a row
# when bytes were lost, up to seven when the spacing is exact.
_MAX_SHIFT = 12
_MAX_REGION = 3
_MAX_EXACT_REGION = 8
# Realignment: neighbouring samples of one surface agree this well, mm.
_JUMP_MM = 1000
# Realignment moves from the sample before: (samples back, bytes lost in between, only onto a
# capsule's first sample, cost). One lost byte: read across it (that sample is garbage and left
# to the plausibility check) or skip the sample it hit; two: skip one or two samples, or lose a
# header's bytes. (Measured on the emulator at 5 % lost bytes, these keep the most samples
# right.) Skipping a sample over two lost bytes costs: it is rare among scattered losses, and
# the true samples before a run of lost bytes (a capsule cut short) read late take one such
# skip per two bytes, where the run itself costs nothing (see _monotone_paths).
_SKIP_COST = 0.2
_MOVES = ((1, 0, False, 0.0), (1, 1, False, 0.0), (1, 2, True, 0.0), (2, 1, False, 0.0),
          (2, 2, False, _SKIP_COST), (3, 2, False, _SKIP_COST))
# Plausibility: noise sigmas allowed, the noise scale's floor (whole-mm distances) and its
# prior (the S1's datasheet accuracy) until intact capsules have measured it.
_SIGMAS = 4.0
_SIGMA_FLOOR_MM = 3.0
_SIGMA_PRIOR_MM = 50.0
_SIGMA_WINDOW = 512
# A second difference of three samples with independent noise sigma has std sqrt(6) sigma; the
# midpoint prediction's residual sqrt(1.5) sigma and an extrapolation's sqrt(6) sigma.
_MAD_TO_SIGMA = 1.4826 / math.sqrt(6.0)
# Steepest surface a neighbour pair may describe: tan(80 degrees) of range per radian.
_STEEPEST = math.tan(math.radians(80.0))
# Angles: tolerance for a suspect start angle (1/8 degree), the share of a sweep allowed for one
# whose checksum passed, and how far (capsules, about a turn) a prediction reaches.
_ANGLE_TOLERANCE_Q8 = 32
_CLEAN_ANGLE_SHARE = 8
_PREDICTION_REACH = 24
# A prediction this few capsules old outranks a run of two observed angles; after this many
# start angles in a row not believed, the sweep is measured anew; measured sweeps refine the
# tracked one with this weight; the S1's sweep at 10 Hz, 1/256 degree, until one is measured.
_FRESH_GAP = 2
_RESTART_AFTER = 8
_SWEEP_WEIGHT = 1.0 / 8.0
_NOMINAL_SWEEP_Q8 = 3980
# The line counts as damaged while this share of the recent capsules fails (weight 1/32).
_DAMAGED_SHARE = 0.5
_DAMAGE_WEIGHT = 1.0 / 32.0

_K = np.arange(SAMPLES_PER_CAPSULE)
_FRACTIONS = _K / SAMPLES_PER_CAPSULE
_DISTANCE_OFFSETS = 4 + 2 * _K


def _wrap_q8(angle_q8: int) -> int:
    """Return an angle difference in 1/256 degree wrapped into [-180, 180) degrees."""
    return (angle_q8 + FULL_TURN_Q8 // 2) % FULL_TURN_Q8 - FULL_TURN_Q8 // 2


class _Frame:
    """One capsule's raw content once framed (mutable working record of the decoder)."""

    __slots__ = ('slot', 'angle_field', 'distances', 'readable', 'clean', 'realigned', 'cut',
                 'end', 'start_q8', 'sweep_q8', 'suspect', 'replaced')

    def __init__(self, slot, angle_field, distances, readable, clean, realigned, end,
                 cut=False):
        self.slot = slot
        self.angle_field = angle_field
        self.distances = distances
        self.readable = readable
        self.clean = clean
        self.realigned = realigned
        self.cut = cut
        self.end = end
        self.start_q8 = None
        self.sweep_q8 = None
        self.suspect = not clean
        self.replaced = False


class DenseCapsuleDecoder:
    """
    Incremental decoder of dense capsules that resynchronises capsule by capsule.

    :param us_per_sample: the scan mode's microseconds per sample (sets the sweep limit)
    :param max_distance_m: the mode's farthest range; distances beyond are rejected
    """

    FRAME_SIZE = CAPSULE_SIZE
    SAMPLES_PER_FRAME = SAMPLES_PER_CAPSULE

    def __init__(self, us_per_sample: float, max_distance_m: float = 40.0):
        # The SDK's integer formula: the sweep of 40 samples at 100 Hz, in whole degrees.
        self._max_sweep_q8 = (360 * 100 * SAMPLES_PER_CAPSULE
                              // max(1000000 // max(int(us_per_sample), 1), 1)) << 8
        self._max_mm = int(max_distance_m * 1000.0)
        self._buffer = b''
        self._offset = 0            # stream offset of _buffer[0]
        self._synced = False        # _buffer[0] starts a capsule header
        self._slot = 0              # capsule index of the capsule at _buffer[0]
        self._gap_from = None       # stream offset where sync was lost
        self._angles = _AngleTrack(self._max_sweep_q8)
        self._last_angle = None
        self._damage = 0.0
        self._noise = _RangeNoise()
        self._counts = dict.fromkeys(StreamCounts.__dataclass_fields__, 0)

    @property
    def counts(self) -> StreamCounts:
        """Return what the decoder has met so far (capsules, damage, repairs, losses)."""
        return StreamCounts(**self._counts)

    def feed(self, data: bytes) -> Samples:
        """
        Decode what the next received chunk completes.

        A capsule is decoded once the header and start angle of the capsule after it have
        arrived.

        :param data: the next received bytes, any length
        :return: the samples decoded, in stream order
        """
        buffer = self._buffer + bytes(data)
        raw = np.frombuffer(buffer, np.uint8)
        headers = ((raw[:-1] >> 4) == 0xA) & ((raw[1:] >> 4) == 0x5)
        regions = []
        pos = 0
        while True:
            if not self._synced:
                found = np.flatnonzero(headers[pos:])
                if not found.size:
                    keep = max(len(buffer) - 1, pos)      # a header may begin in the last byte
                    self._counts['discarded_bytes'] += keep - pos
                    pos = keep
                    break
                pos = self._regain_sync(pos, pos + int(found[0]))
            step = self._next_header(raw, headers, pos)
            if step is None:
                break
            count, end = step
            if count == 0:
                # No header where the next capsules should begin: this one leads nowhere.
                self._synced = False
                self._gap_from = self._offset + pos
                self._counts['resyncs'] += 1
                self._counts['discarded_bytes'] += 1
                pos += 1
                continue
            regions.append((pos, count, end, self._slot))
            self._slot += count
            pos = end
        frames = self._frame(raw, regions)
        self._buffer = buffer[pos:]
        self._offset += pos
        if not frames:
            return Samples.concat([])
        after = regions[-1][2]
        self._judge_angles(frames, int(raw[after + 2]) | int(raw[after + 3]) << 8)
        # A capsule whose start angle is out of sequence is not placed at the predicted one when
        # that may be wrong too: in a region that lost a run of bytes it may be framed where
        # none began (a short one's bytes read as its successor's), and an intact one says the
        # prediction lost count of capsules.
        placed = np.array([f.start_q8 is not None and f.sweep_q8 is not None
                           and not ((f.cut or f.clean) and f.replaced) for f in frames])
        self._counts['lost_frames'] += int(np.count_nonzero(~placed))
        distances = self._check_distances(frames, placed)
        return self._samples([f for f, ok in zip(frames, placed) if ok], distances[placed])

    def _regain_sync(self, pos: int, header: int) -> int:
        """Skip to a header found byte by byte; count the capsules the gap held as lost."""
        self._counts['discarded_bytes'] += header - pos
        self._synced = True
        if self._gap_from is not None:
            lost = max(round((self._offset + header - self._gap_from) / CAPSULE_SIZE), 1)
            self._slot += lost
            self._counts['frames'] += lost
            self._counts['lost_frames'] += lost
            self._gap_from = None
        return header

    def _next_header(self, raw: np.ndarray, headers: np.ndarray, pos: int):
        """
        Find where the capsules after the one at ``pos`` end.

        :return: ``(n, end)``: n capsules end at the header at ``end``; ``(0, None)`` when no
            header lies where one should; None until enough bytes have arrived
        """
        size = raw.size
        for count in range(1, _MAX_EXACT_REGION + 1):
            expected, reach = pos + count * CAPSULE_SIZE, count * _MAX_SHIFT
            exact = expected + 4 <= size and headers[expected]
            if count == 1 and expected + 4 <= size and not (
                    exact and self._follows(raw, pos, expected)):
                # A header in sequence (a sweep on) wins over one merely 84 bytes on, which may
                # lie in the distances of a successor that arrived early.
                for early in np.flatnonzero(headers[pos + 1:expected]) + pos + 1:
                    if self._follows(raw, pos, early):
                        return 1, int(early)
            if exact:
                return count, expected
            if count > _MAX_REGION:
                # Beyond a few capsules only an exact 84-byte spacing is evidence enough.
                if expected + 4 > size:
                    return None
                continue
            if expected + reach + 4 > size:
                return None
            near = np.flatnonzero(headers[expected - reach:expected + reach + 1])
            if near.size:
                near += expected - reach
                return count, int(near[np.argmin(np.abs(near - expected))])
        return 0, None

    def _follows(self, raw: np.ndarray, pos: int, at: int) -> bool:
        """
        Tell whether the header at ``at`` starts the capsule after the one at ``pos``.

        Any run of lost bytes shortens a capsule, up to all but its first byte: a header
        anywhere within it starts the next capsule when its start angle lies one sweep on (a
        false header in the distances has a random one).

        :param raw: the received bytes
        :param pos: a capsule header
        :param at: a later header
        :return: True when its start angle follows at the tracked sweep
        """
        this = _start_q8(int(raw[pos + 2]) | int(raw[pos + 3]) << 8)
        following = _start_q8(int(raw[at + 2]) | int(raw[at + 3]) << 8)
        if this is None or following is None:
            return False
        sweep_q8 = self._angles.sweep_deg() * 256.0
        return abs(_wrap_q8(following - this - round(sweep_q8))) <= sweep_q8 / _CLEAN_ANGLE_SHARE

    def _frame(self, raw: np.ndarray, regions: list) -> list:
        """
        Cut regions into capsules, realigning those that lost bytes.

        Bytes are lost, never gained: a region longer than its capsules (its closing header
        found late, or false) was framed wrongly, and its samples are unreadable.
        """
        shifts = [count * CAPSULE_SIZE - (end - pos) for pos, count, end, _ in regions]
        aligned = self._aligned(raw, [region for region, shift in zip(regions, shifts)
                                      if not shift])
        noise_mm = min(_SIGMAS * math.sqrt(2.0) * self._noise.sigma_mm, _JUMP_MM / 2.0)
        realigned = _realign(raw, [r for r, shift in zip(regions, shifts) if shift > 0],
                             [shift for shift in shifts if shift > 0], self._max_mm, noise_mm)
        frames = []
        for (pos, count, end, slot), shift in zip(regions, shifts):
            if shift == 0:
                frames += [next(aligned) for _ in range(count)]
                continue
            if shift < 0:
                at = pos + CAPSULE_SIZE * np.arange(count) + 2
                frames += [_Frame(slot + j, int(raw[at[j]]) | int(raw[at[j] + 1]) << 8,
                                  np.zeros(SAMPLES_PER_CAPSULE, np.int64),
                                  np.zeros(SAMPLES_PER_CAPSULE, bool), False, False,
                                  self._offset + min(end, pos + CAPSULE_SIZE * (j + 1)), True)
                           for j in range(count)]
                continue
            distances, kept, path = next(realigned)
            for j in range(count):
                first = j * SAMPLES_PER_CAPSULE
                # The first capsule's angle follows its verified header; a later one's sits at
                # the shift of its first sample.
                at = pos + CAPSULE_SIZE * j + 2 - (path[first] if j else 0)
                frame_end = min(end, pos + CAPSULE_SIZE * (j + 1))
                frames.append(_Frame(slot + j, int(raw[at]) | int(raw[at + 1]) << 8,
                                     distances[first:first + SAMPLES_PER_CAPSULE],
                                     kept[first:first + SAMPLES_PER_CAPSULE], False, True,
                                     self._offset + frame_end, shift > count * _MAX_SHIFT))
        self._counts['frames'] += len(frames)
        self._counts['damaged_frames'] += sum(not f.clean for f in frames)
        self._counts['realigned_frames'] += sum(f.realigned for f in frames)
        return frames

    def _aligned(self, raw: np.ndarray, regions: list):
        """Return an iterator over the capsules of regions exactly 84 bytes per capsule long."""
        starts = [pos + CAPSULE_SIZE * j for pos, count, _, _ in regions for j in range(count)]
        slots = [slot + j for _, count, _, slot in regions for j in range(count)]
        capsules = raw[np.array(starts, np.int64)[:, None] + np.arange(CAPSULE_SIZE)]
        received = (capsules[:, 0] & 0x0F) | (capsules[:, 1] << 4)
        clean = (((capsules[:, 0] >> 4) == 0xA) & ((capsules[:, 1] >> 4) == 0x5)
                 & (received == np.bitwise_xor.reduce(capsules[:, 2:], axis=1))).tolist()
        fields = capsules[:, 2:].astype(np.int64)
        values = fields[:, 0::2] | (fields[:, 1::2] << 8)
        readable = np.ones(SAMPLES_PER_CAPSULE, bool)
        return iter([_Frame(slot, int(row[0]), row[1:], readable, ok, False,
                            self._offset + start + CAPSULE_SIZE)
                     for slot, row, ok, start in zip(slots, values, clean, starts)])

    def _judge_angles(self, frames: list, next_field: int):
        """Place each capsule's samples in angle, in stream order (step 3)."""
        slip = 0
        for i, frame in enumerate(frames):
            self._damage += _DAMAGE_WEIGHT * ((not frame.clean) - self._damage)
            damaged_line = self._damage > _DAMAGED_SHARE
            after = frames[i + 1] if i + 1 < len(frames) else None
            frame.slot += slip
            # On a damaged line a passing checksum does not vouch for a start angle either.
            placement = self._angles.place(
                frame.slot, frame.angle_field, frame.clean and not damaged_line,
                after.slot + slip if after else frame.slot + 1,
                after.angle_field if after else next_field,
                bool(after) and after.clean and not damaged_line)
            if placement.slip:
                # Whole capsules the stream lost without a trace in its bytes (or that a
                # resync counted wrongly): the start angles tell how many.
                slip += placement.slip
                frame.slot += placement.slip
                self._counts['frames'] += max(placement.slip, 0)
                self._counts['lost_frames'] += max(placement.slip, 0)
            frame.start_q8, frame.sweep_q8 = placement.start_q8, placement.sweep_q8
            frame.replaced = placement.replaced
            self._counts['replaced_angles'] += frame.replaced
            frame.suspect |= frame.replaced or damaged_line
        self._slot += slip

    def _check_distances(self, frames: list, placed: np.ndarray) -> np.ndarray:
        """
        Measure the range noise; reject implausible distances (step 4).

        :return: the capsules' distances, shape (capsules, 40), mm; 0 where rejected
        """
        distances = np.array([f.distances for f in frames], np.float64)
        readable = np.array([f.readable for f in frames])
        suspect = np.array([f.suspect for f in frames])
        self._noise.update(np.where(readable, distances, 0.0))
        keep = readable & (distances <= self._max_mm)
        if suspect.any():
            step_rad = math.radians(self._angles.sweep_deg() / SAMPLES_PER_CAPSULE)
            keep[suspect] &= (distances[suspect] == 0) | _supported(
                distances[suspect], keep[suspect], self._noise.sigma_mm, step_rad)
        self._counts['rejected_samples'] += int(np.count_nonzero(~keep[placed]))
        return np.where(keep, distances, 0.0)

    def _samples(self, frames: list, distances: np.ndarray) -> Samples:
        """Lay out the placed capsules' samples."""
        count = len(frames)
        if not count:
            return Samples.concat([])
        starts = np.array([f.start_q8 for f in frames], np.float64)
        sweeps = np.array([f.sweep_q8 for f in frames], np.float64)
        angle = np.mod((starts[:, None] + sweeps[:, None] * _FRACTIONS).reshape(-1) / 256.0,
                       360.0)
        distance = distances.reshape(-1)
        previous = np.concatenate([[-np.inf if self._last_angle is None else self._last_angle],
                                   angle[:-1]])
        self._last_angle = angle[-1]
        self._counts['samples'] += angle.size
        k = np.tile(_K, count)
        return Samples(angle_deg=angle,
                       distance_mm=distance,
                       quality=np.where(distance > 0, DENSE_RETURN_QUALITY, 0).astype(np.uint8),
                       start=angle < previous,
                       frame_end=np.repeat([f.end for f in frames], SAMPLES_PER_CAPSULE),
                       samples_after=SAMPLES_PER_CAPSULE - 1 - k,
                       slot=np.repeat([f.slot for f in frames], SAMPLES_PER_CAPSULE)
                       * SAMPLES_PER_CAPSULE + k)


class _RangeNoise:
    """
    The range noise scale, from the median second difference along capsules.

    A damaged sample spoils three second differences: while fewer than half are, their median
    is the noise's. Until a capsule's worth is measured, the S1's datasheet accuracy.
    """

    def __init__(self):
        self.sigma_mm = _SIGMA_PRIOR_MM
        self._window = []
        self._unmeasured = 0
        self._measured = False

    def update(self, distances: np.ndarray):
        """
        Take the distances of more capsules.

        :param distances: shape (capsules, 40), mm; 0 where there is no (readable) return
        """
        second = distances[:, :-2] - 2.0 * distances[:, 1:-1] + distances[:, 2:]
        returns = (distances[:, :-2] > 0) & (distances[:, 1:-1] > 0) & (distances[:, 2:] > 0)
        self._window.append(np.abs(second[returns]))
        self._unmeasured += int(np.count_nonzero(returns))
        if self._unmeasured < (_SIGMA_WINDOW // 4 if self._measured else SAMPLES_PER_CAPSULE):
            return
        # A quarter of the window is new (a capsule's worth at first): take the median.
        window = np.concatenate(self._window)[-_SIGMA_WINDOW:]
        self._window, self._unmeasured, self._measured = [window], 0, True
        self.sigma_mm = max(_SIGMA_FLOOR_MM, _MAD_TO_SIGMA * float(np.median(window)))


@dataclass(frozen=True)
class Placement:
    """
    A capsule's place in angle, as :class:`_AngleTrack` decides it.

    :ivar start_q8: start angle, 1/256 degree; None when the capsule cannot be placed
    :ivar sweep_q8: angle its 40 samples span, 1/256 degree; None when it cannot be placed
    :ivar replaced: the start angle is the predicted one, not the received one
    :ivar slip: capsules the stream lost unseen before this one (negative: counted too many)
    """

    start_q8: Optional[int]
    sweep_q8: Optional[float]
    replaced: bool
    slip: int


class _AngleTrack:
    """
    The start angles of the capsules in sequence: which to believe and what to predict.

    :param max_sweep_q8: the largest plausible sweep of one capsule, 1/256 degree (the SDK's)
    """

    def __init__(self, max_sweep_q8: int):
        self._max_sweep_q8 = max_sweep_q8
        self._reference = None      # (slot, start) of the last believed start angle
        self._sweep = None          # one capsule's sweep, smoothed, 1/256 degree
        self._previous = None       # (slot, observed start) of the capsule before
        self._misses = 0            # start angles in a row not believed

    def sweep_deg(self) -> float:
        """Return one capsule's sweep, degrees (the S1's at 10 Hz until measured)."""
        return (self._sweep or _NOMINAL_SWEEP_Q8) / 256.0

    def place(self, slot: int, field: int, clean: bool, next_slot: int, next_field: int,
              next_clean: bool) -> tuple:
        """
        Decide a capsule's start angle and sweep from its field and its successor's.

        :param slot: the capsule's index in the stream
        :param field: its start angle field (bit 15: S)
        :param clean: its checksum passed on a line not otherwise damaged
        :param next_slot: the successor's index
        :param next_field: the successor's start angle field
        :param next_clean: the same of the successor (False when not known yet)
        :return: the :class:`Placement`
        """
        if clean and field & 0x8000:
            # The device (re)started its stream here, as the SDK takes the S flag.
            self._reference = self._sweep = self._previous = None
        observed, following = _start_q8(field), _start_q8(next_field)
        tolerance = self._tolerance(clean)
        consecutive = next_slot == slot + 1
        ahead = None if observed is None or following is None or not consecutive else (
            (following - observed) % FULL_TURN_Q8)
        predicted, gap = self._predict(slot)
        matches = (observed is not None and predicted is not None
                   and abs(_wrap_q8(observed - predicted)) <= tolerance)
        slip = 0 if matches or predicted is None or observed is None else self._slip(
            observed - predicted, gap, self._starts_run(slot, observed, ahead, clean, tolerance),
            tolerance)
        if slip:
            slot, predicted, matches = slot + slip, observed, True
        # Against a recent believed angle only the prediction counts; a run of two angles could
        # be two damaged ones that happen to agree.
        run = (not matches and (predicted is None or gap > _FRESH_GAP)
               and self._starts_run(slot, observed, ahead, clean, tolerance))
        self._previous = (slot, observed)
        if matches or run:
            self._believe(slot, observed, ahead if run else None)
            start, replaced = observed, False
        elif predicted is not None:
            start, replaced = predicted, True
        else:
            return Placement(None, None, False, 0)
        if not matches and not run:
            self._misses += 1
            if self._misses >= _RESTART_AFTER:
                # Too long without a believed angle: start over from runs of start angles.
                self._reference = self._sweep = None
        step = None if following is None or not consecutive else (
            (following - start) % FULL_TURN_Q8)
        if step is not None and (abs(step - self._sweep) <= self._tolerance(next_clean)
                                 if self._sweep is not None else 0 < step <= self._max_sweep_q8):
            return Placement(start, step, replaced, slip)
        if next_clean and next_field & 0x8000:
            return Placement(start, None, replaced, slip)   # before a restart: dropped (SDK)
        # The next start angle is damaged or far: sweep as the capsules before.
        return Placement(start, self._sweep, replaced, slip)

    def _slip(self, beyond_q8: int, gap: int, runs_on: bool, tolerance: float) -> int:
        """
        Tell how many capsules the stream lost unseen, from a start angle ahead of prediction.

        :param beyond_q8: the observed start angle minus the predicted one, 1/256 degree
        :param gap: capsules since the last believed start angle
        :param runs_on: the successor's start angle follows on at the sweep
        :param tolerance: how far the angle may lie from a whole number of sweeps
        :return: capsules lost (negative: counted too many), 0 when it does not look like that
        """
        if not runs_on:
            return 0
        beyond = _wrap_q8(beyond_q8)
        lost = round(beyond / self._sweep)
        if lost == 0 or gap + lost < 1 or abs(beyond - lost * self._sweep) > tolerance:
            return 0
        return lost

    def _tolerance(self, clean: bool) -> float:
        """Return how far a start angle may lie from its prediction, 1/256 degree."""
        if not clean or self._sweep is None:
            return _ANGLE_TOLERANCE_Q8
        # A passing checksum makes a damaged angle unlikely: allow for the motor's speed.
        return max(self._sweep / _CLEAN_ANGLE_SHARE, _ANGLE_TOLERANCE_Q8)

    def _predict(self, slot: int) -> tuple:
        """Return the predicted start angle (1/256 degree) and its distance in capsules."""
        if self._reference is None or self._sweep is None:
            return None, None
        gap = slot - self._reference[0]
        if not 0 < gap <= _PREDICTION_REACH:
            return None, None
        return round(self._reference[1] + gap * self._sweep) % FULL_TURN_Q8, gap

    def _starts_run(self, slot: int, observed, ahead, clean: bool, tolerance: float) -> bool:
        """Tell whether a start angle advances to its successor's like the capsules before."""
        if ahead is None or not 0 < ahead <= self._max_sweep_q8:
            return False
        if self._sweep is not None:
            return abs(ahead - self._sweep) <= tolerance
        if self._previous is not None and self._previous[0] == slot - 1 and (
                self._previous[1] is not None):
            behind = (observed - self._previous[1]) % FULL_TURN_Q8
            return abs(ahead - behind) <= _ANGLE_TOLERANCE_Q8 or clean
        # At the start of a stream, nothing to compare with: the SDK's rule, for intact capsules.
        return clean

    def _believe(self, slot: int, start: int, run_sweep):
        """Take a start angle as true: it becomes the reference and refines the sweep."""
        self._misses = 0
        if self._reference is not None and self._reference[0] == slot - 1:
            measured = (start - self._reference[1]) % FULL_TURN_Q8
            if self._sweep is None:
                self._sweep = measured if 0 < measured <= self._max_sweep_q8 else None
            elif abs(measured - self._sweep) <= self._sweep / _CLEAN_ANGLE_SHARE:
                self._sweep += (measured - self._sweep) * _SWEEP_WEIGHT
        elif self._sweep is None:
            self._sweep = run_sweep
        self._reference = (slot, start)


def _start_q8(field: int):
    """Return a start angle field's angle in 1/256 degree, None when beyond 360 degrees."""
    angle_q6 = field & 0x7FFF
    return angle_q6 << 2 if angle_q6 < FULL_TURN_Q6 else None


def _realign(raw: np.ndarray, regions: list, shifts: list, max_mm: int, noise_mm: float):
    """
    Read the distances of regions that lost (shift > 0) or gained bytes (step 2).

    All regions are realigned together, in one dynamic programming pass over their samples
    (shorter regions padded at the end).

    :param raw: the received bytes
    :param regions: ``(pos, count, end, slot)`` of each region
    :param shifts: bytes each region lost (negative: gained)
    :param max_mm: farthest valid distance, mm
    :param noise_mm: how far true neighbours may differ by noise alone, mm
    :return: an iterator, in region order, of ``(distances, kept, shift per sample)``
    """
    if not regions:
        return iter(())
    count = max(region[1] for region in regions)
    offsets = (np.repeat(CAPSULE_SIZE * np.arange(count), SAMPLES_PER_CAPSULE)
               + np.tile(_DISTANCE_OFFSETS, count))
    pos = np.array([region[0] for region in regions])
    shift = np.array(shifts)
    reach = np.arange(shift.max() + 1)
    index = pos[:, None, None] + offsets[None, None, :] - reach[None, :, None]
    # A distance is read between the region's first header and the next one.
    end = np.array([region[2] for region in regions])
    inside = ((index >= pos[:, None, None] + _DISTANCE_OFFSETS[0])
              & (index + 2 <= end[:, None, None]))
    index = np.clip(index, 0, raw.size - 2)
    values = raw[index].astype(np.int64) | (raw[index + 1].astype(np.int64) << 8)
    lengths = [SAMPLES_PER_CAPSULE * region[1] for region in regions]
    paths, kept = _monotone_paths(values, inside, shift, lengths, max_mm, noise_mm)
    samples = np.arange(values.shape[2])
    return iter([(values[r, path, samples][:length], keep[:length], path[:length])
                 for r, (path, keep, length) in enumerate(zip(paths, kept, lengths))])


def _monotone_paths(values: np.ndarray, inside: np.ndarray, last_shift: np.ndarray,
                    lengths: list, max_mm: int, noise_mm: float) -> tuple:
    """
    Choose each sample's shift in regions that lost bytes (step 2).

    A path scores per sample how well its distance agrees with the one kept before it (see
    ``_MOVES``): the shift grows by the bytes lost over one or two skipped samples, or over the
    header between two capsules. A misread row of true distances (two bytes off: each sample
    read as its neighbour) can only be reached through misread garbage, so the path that keeps
    the most agreeing neighbours is the true one. It may start at any shift (the first start
    angle may have lost bytes) and ends at its region's end (the next header) at its largest
    shift: after its last sample, or over a run of lost bytes that reached the header (a capsule
    cut short), which scores nothing for the samples the run took. Reading the samples before
    such a run a sample or more late instead takes a costly skip per two bytes lost, so where
    the run's place is in doubt the samples in doubt are left out.

    :param values: distances read at each shift, shape (regions, shifts, samples), mm
    :param inside: which of them were read within the region (others cannot be its samples)
    :param last_shift: each region's largest shift
    :param lengths: each region's samples (the rest is padding)
    :param max_mm: farthest valid distance, mm
    :param noise_mm: how far true neighbours may differ by noise alone, mm (below 1 m)
    :return: ``(shift per sample, kept)``, each of shape (regions, samples): a sample stepped
        over, out of range or beyond a run of lost bytes is not kept
    """
    regions, shifts, size = values.shape
    valid = values <= max_mm
    ends = np.array(lengths)
    lanes = np.arange(regions)
    # Agreement is full within the noise of two neighbours and fades to none at 1 m: a distance
    # read a byte off moves by multiples of 256 mm where true neighbours move by millimetres.
    # Shifts beyond a region's own, readings outside the region, and moves that only land on a
    # capsule's first sample elsewhere, are barred (-inf). Index ``lengths[r]`` is region r's
    # end, reached from its last sample at the same shift.
    agreement = np.zeros((len(_MOVES), size + 1, regions, shifts))
    for i, (back, rise, onto_first, cost) in enumerate(_MOVES):
        before, after = values[:, :shifts - rise, :size - back], values[:, rise:, back:]
        both = valid[:, :shifts - rise, :size - back] & valid[:, rise:, back:]
        fade = (_JUMP_MM - np.abs(after - before)) / (_JUMP_MM - noise_mm)
        possible = inside[:, :shifts - rise, :size - back] & inside[:, rise:, back:]
        agreement[i, back:size, :, rise:] = np.where(
            possible, np.where(both, np.clip(fade, 0.0, 1.0), 0.0), -np.inf).transpose(2, 0, 1)
        agreement[i] -= cost
        if onto_first:
            agreement[i, np.arange(size + 1) % SAMPLES_PER_CAPSULE != 0] = -np.inf
        agreement[i, ends, lanes] = 0.0 if (back, rise) == (1, 0) else -np.inf
    barred = np.arange(shifts)[None, :] > last_shift[:, None]
    agreement[:, :, barred] = -np.inf
    backs, rises = (np.array(column) for column in list(zip(*_MOVES))[:2])
    # scores[m + 3, :, 2 + s]: the best score of a path whose last sample is m, at shift s; the
    # rows before sample 0 and the two columns below shift 0 stay -inf, so that a move reads
    # its starting score at [m + 3 - back, :, 2 + s - rise] for every s at once.
    scores = np.full((size + 4, regions, shifts + 2), -np.inf)
    scores[3, :, 2:] = np.where(barred | ~inside[:, :, 0], -np.inf, 0.0)
    rows = 3 - backs[:, None, None]
    columns = 2 - rises[:, None, None] + np.arange(shifts)[None, None, :]
    choice = np.zeros((size + 1, regions, shifts), np.int64)
    for m in range(1, size + 1):
        candidates = agreement[:, m] + scores[rows + m, lanes[None, :, None], columns]
        choice[m] = candidates.argmax(axis=0)
        scores[m + 3, :, 2:] = candidates.max(axis=0)
    paths, kept = [], []
    for region, (last, length) in enumerate(zip(last_shift.tolist(), lengths)):
        path, keep = [0] * size, [True] * size
        m, s = _path_end(scores[3:, region, 2:], length, last)
        for skipped in range(m + 1, length):
            path[skipped], keep[skipped] = last, False
        if m == length:
            m, s = m - 1, last                     # from the end, the last sample's shift
        while m >= 0:
            path[m] = s
            back, rise = _MOVES[choice[m, region, s]][:2] if m else (1, 0)
            for skipped in range(m - back + 1, m):
                path[skipped], keep[skipped] = s - rise, False
            m, s = m - back, s - rise
        paths.append(path)
        kept.append(keep)
    paths, kept = np.array(paths), np.array(kept)
    kept &= np.take_along_axis(valid & inside, paths[:, None, :], axis=1)[:, 0, :]
    # A region with no possible path (cut to its header) keeps nothing.
    kept &= np.isfinite(scores[ends + 3, lanes, last_shift + 2])[:, None]
    return paths, kept


def _path_end(scores: np.ndarray, length: int, last_shift: int) -> tuple:
    """
    Choose where a region's path ends: at its end, or before a run of lost bytes up to it.

    A run over q >= 2 samples before the end lost 2q or 2q - 1 bytes.

    :param scores: the region's path scores, shape (samples + 1, shifts)
    :param length: its samples (index ``length``: its end)
    :param last_shift: its largest shift
    :return: ``(sample, shift)`` of the path's last sample read, or ``(length, last_shift)``
    """
    best, end = scores[length, last_shift], (length, last_shift)
    for q in range(2, length + 1):
        for odd in (0, 1):
            m, s = length - 1 - q, last_shift - 2 * q + odd
            if m >= 0 and s >= 0 and scores[m, s] > best:
                best, end = scores[m, s], (m, s)
    return end


def _supported(distances: np.ndarray, usable: np.ndarray, sigma_mm: float,
               step_rad: float) -> np.ndarray:
    """
    Tell which distances a neighbour pair in the same capsule predicts (step 4).

    :param distances: distances of suspect capsules, shape (capsules, 40), mm
    :param usable: which distances may predict others (readable, in range)
    :param sigma_mm: range noise scale, mm
    :param step_rad: angle between samples, rad
    :return: per distance, True when predicted within tolerance
    """
    shape = distances.shape
    pad = np.zeros((shape[0], 2))
    d = np.concatenate([pad, distances, pad], axis=1)
    ok = np.concatenate([pad.astype(bool), usable & (distances > 0), pad.astype(bool)], axis=1)
    before2, before, after, after2 = (d[:, i:i + shape[1]] for i in (0, 1, 3, 4))
    ok_b2, ok_b, ok_a, ok_a2 = (ok[:, i:i + shape[1]] for i in (0, 1, 3, 4))

    def surface(centre, rise):
        # A straight surface at range r, climbing ``rise`` per sample, has second difference
        # r step^2 + 2 rise^2 / r (the polar form of a line). Pairs that climb faster than a
        # surface seen at 80 degrees incidence (plus the noise) predict nothing.
        steep = np.abs(rise) > _STEEPEST * step_rad * centre + noise_rise
        with np.errstate(divide='ignore', invalid='ignore'):
            bend = centre * step_rad ** 2 + 2.0 * rise ** 2 / np.maximum(centre, 1.0)
        return bend, ~steep

    noise_rise = _SIGMAS * math.sqrt(2.0) * sigma_mm
    midpoint = 0.5 * (before + after)
    forward = 2.0 * before - before2
    backward = 2.0 * after - after2
    noise_mid, noise_end = _SIGMAS * math.sqrt(1.5) * sigma_mm, _SIGMAS * math.sqrt(6.0) * sigma_mm
    bend_mid, flat_mid = surface(midpoint, 0.5 * (after - before))
    bend_forward, flat_forward = surface(before, before - before2)
    bend_backward, flat_backward = surface(after, after - after2)
    fits_mid = (ok_b & ok_a & flat_mid
                & (np.abs(distances - midpoint) <= noise_mid + 0.5 * bend_mid))
    fits_forward = (ok_b & ok_b2 & flat_forward
                    & (np.abs(distances - forward) <= noise_end + bend_forward))
    fits_backward = (ok_a & ok_a2 & flat_backward
                     & (np.abs(distances - backward) <= noise_end + bend_backward))
    return fits_mid | fits_forward | fits_backward
