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

1. Framing (:mod:`~wctls_rplidar.framing`, shared by every capsule format). Capsules are
   84 bytes apart. A capsule cut short (a run of lost bytes up to its end: a lost USB packet,
   an overrun buffer) is followed at once by the next: from a capsule header (sync nibbles A,
   5) the next capsule starts at the first header within 84 bytes whose start angle lies one
   sweep on (a false header in the distances has a random angle), else 84 bytes on, else the
   next one is looked for within 12 bytes per capsule of 84, 168 or 252 bytes on (or exactly up
   to 672 bytes on): the region between two headers holds ``n`` capsules (headers in between
   may be damaged) that lost ``d`` bytes. Bytes are lost, never gained: a region longer than
   its capsules was framed on a false header, and its samples are unreadable. Only without any
   header is sync lost and searched byte by byte, as by the SDK.
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
3. Angles (:class:`~wctls_rplidar.framing.AngleTrack`). Start angles advance by one
   capsule's sweep: a start angle is believed when it lies within 1/8 degree of the one
   predicted from the last believed capsule (1/8 of a sweep, for the motor's speed, for a
   capsule whose checksum passed on a line not otherwise damaged), or, without a recent
   prediction, when it and its successor's advance like the capsules before. Otherwise the
   predicted angle is used (counted as replaced), unless the prediction may be the wrong one:
   an intact capsule out of sequence says it lost count of capsules, and in a region that lost
   a run of bytes a capsule may be framed where none began; such a capsule is lost, as one with
   nothing to predict from. Sample k lies at ``start + k * sweep / 40`` as in the SDK, the sweep
   from the next start angle when it is in step, else the tracked one.
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

import math
import statistics
from typing import Optional

import numpy as np

from .framing import AngleTrack, CapsuleFramer, CapsulePlacer, LinkDamage, placeable
from .protocol import (CAPSULE_SIZE, DENSE_RETURN_QUALITY, Samples, SAMPLES_PER_CAPSULE,
                       StreamCounts)

# The S1's DenseBoost sweep of one capsule at 10 Hz, 1/256 degree, until one is measured.
_NOMINAL_SWEEP_Q8 = 3980

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
# A double bit flip: a repaired spike lies this many sigmas from its prediction, after a change
# of at least this many tolerances (the check's at its usual sigmas). On a line that shows no
# damage otherwise, the repair's tolerance is at most this share of the mode's range for one
# capsule's sign to be believed (see believed_flips).
_REPAIR_SIGMAS = 2.0
_CLEAN_LINE_TOLERANCE_SHARE = 1e-3
_REPAIR_MIN_TOLERANCES = 2.0
# The spikes a capsule (of the samples given) may have for one to tell of a flipped bit: a double
# flip's two, and no spike of the scene's (see flip_repairs).
_MAX_SPIKES = 2
# A second difference of three samples with independent noise sigma has std sqrt(6) sigma; the
# midpoint prediction's residual sqrt(1.5) sigma and an extrapolation's sqrt(6) sigma.
_MAD_TO_SIGMA = 1.4826 / math.sqrt(6.0)
# Steepest surface a neighbour pair may describe: tan(80 degrees) of range per radian.
_STEEPEST = math.tan(math.radians(80.0))

_DISTANCE_OFFSETS = 4 + 2 * np.arange(SAMPLES_PER_CAPSULE)
_NO_ANGLE_FIELD = 0x7FFF        # a start angle field beyond 360 degrees: no angle


class _Frame:
    """One capsule's raw content once framed (mutable working record of the decoder)."""

    __slots__ = ('slot', 'angle_field', 'distances', 'readable', 'clean', 'realigned', 'cut',
                 'end', 'placement', 'suspect', 'key')

    def __init__(self, slot, angle_field, distances, readable, clean, realigned, end,
                 cut=False, key=None):
        self.slot = slot
        self.angle_field = angle_field
        self.distances = distances
        self.readable = readable
        self.clean = clean
        self.realigned = realigned
        self.cut = cut
        self.end = end
        self.placement = None
        self.suspect = not clean
        self.key = key                  # its bytes when framed whole, else None


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
        self._counts = dict.fromkeys(StreamCounts.__dataclass_fields__, 0)
        self._angles = AngleTrack(self._max_sweep_q8, _NOMINAL_SWEEP_Q8)
        self._framer = CapsuleFramer(CAPSULE_SIZE, self._angles, self._counts)
        self._placer = CapsulePlacer(self._angles, self._framer, self._counts)
        self._stream = CapsuleSamples(SAMPLES_PER_CAPSULE, self._counts)
        self._noise = RangeNoise()
        self._withheld = False

    @property
    def counts(self) -> StreamCounts:
        """Return what the decoder has met so far (capsules, damage, repairs, losses)."""
        return StreamCounts(**self._counts)

    @property
    def damage(self) -> LinkDamage:
        """Return the share of bytes damaged and whether the last samples were withheld."""
        return LinkDamage(self._framer.damage.share, self._withheld)

    def feed(self, data: bytes) -> Samples:
        """
        Decode what the next received chunk completes.

        A capsule is decoded once the header and start angle of the capsule after it have
        arrived.

        :param data: the next received bytes, any length
        :return: the samples decoded, in stream order
        """
        raw, regions, offset = self._framer.split(data)
        frames = self._frame(raw, regions, offset)
        if not frames:
            return Samples.concat([])
        after = regions[-1].end
        self._placer.place(frames, int(raw[after + 2]) | int(raw[after + 3]) << 8)
        placed = np.array([placeable(f.placement, f.clean, f.cut) for f in frames])
        self._counts['lost_frames'] += int(np.count_nonzero(~placed))
        distances = self._check_distances(frames, placed)
        return self._stream.of([f for f, ok in zip(frames, placed) if ok],
                               distances[placed].reshape(-1))

    def _frame(self, raw: np.ndarray, regions: list, offset: int) -> list:
        """
        Cut regions into capsules, realigning those that lost bytes.

        An overlong region (framed on a false header) or a tangled one has unreadable samples.

        :param raw: the bytes held by the framer
        :param regions: the complete regions in them
        :param offset: the stream offset of ``raw[0]``
        :return: the capsules, a list of ``_Frame``
        """
        aligned = self._aligned(raw, [region for region in regions
                                      if not region.lost and not region.tangled], offset)
        noise_mm = min(_SIGMAS * math.sqrt(2.0) * self._noise.sigma_mm, _JUMP_MM / 2.0)
        short = [region for region in regions if region.lost > 0 and not region.tangled]
        realigned = _realign(raw, short, [region.lost for region in short], self._max_mm,
                             noise_mm)
        frames = []
        for pos, count, end, slot, shift, cut, tangled in regions:
            if shift == 0 and not tangled:
                frames += [next(aligned) for _ in range(count)]
                continue
            if shift < 0 or tangled:
                # Only the first start angle is known (behind the header framing found; in a
                # tangled region the others' places are not).
                at = pos + CAPSULE_SIZE * np.arange(count) + 2
                fields = [int(raw[a]) | int(raw[a + 1]) << 8 if j == 0 or not tangled
                          else _NO_ANGLE_FIELD for j, a in enumerate(at.tolist())]
                frames += [_Frame(slot + j, fields[j],
                                  np.zeros(SAMPLES_PER_CAPSULE, np.int64),
                                  np.zeros(SAMPLES_PER_CAPSULE, bool), False, False,
                                  offset + min(end, pos + CAPSULE_SIZE * (j + 1)), True)
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
                                     offset + frame_end, cut))
        self._counts['frames'] += len(frames)
        self._counts['damaged_frames'] += sum(not f.clean for f in frames)
        self._counts['realigned_frames'] += sum(f.realigned for f in frames)
        return frames

    @staticmethod
    def _aligned(raw: np.ndarray, regions: list, offset: int):
        """Return an iterator over the capsules of regions exactly 84 bytes per capsule long."""
        starts = [r.pos + CAPSULE_SIZE * j for r in regions for j in range(r.count)]
        slots = [r.slot + j for r in regions for j in range(r.count)]
        capsules = raw[np.array(starts, np.int64)[:, None] + np.arange(CAPSULE_SIZE)]
        received = (capsules[:, 0] & 0x0F) | (capsules[:, 1] << 4)
        clean = (((capsules[:, 0] >> 4) == 0xA) & ((capsules[:, 1] >> 4) == 0x5)
                 & (received == np.bitwise_xor.reduce(capsules[:, 2:], axis=1))).tolist()
        fields = capsules[:, 2:].astype(np.int64)
        values = fields[:, 0::2] | (fields[:, 1::2] << 8)
        readable = np.ones(SAMPLES_PER_CAPSULE, bool)
        return iter([_Frame(slot, int(row[0]), row[1:], readable, ok, False,
                            offset + start + CAPSULE_SIZE, key=capsule.tobytes())
                     for slot, row, ok, start, capsule in zip(slots, values, clean, starts,
                                                              capsules)])

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
        step_rad = math.radians(self._angles.sweep_deg() / SAMPLES_PER_CAPSULE)
        trusted = placed & ~suspect
        if trusted.any():
            shown = unseen_flips(
                np.count_nonzero(trusted), flip_repairs(
                    distances[trusted], keep[trusted], *_flip_deltas(distances[trusted]),
                    self._noise.sigma_mm, step_rad, np.array([f.slot for f in frames])[trusted]))
            if believed_flips(self._placer, shown, self._noise.sigma_mm, self._max_mm):
                # The checksum let damage by: no capsule of the batch vouches for its samples.
                suspect[:] = True
        if suspect.any():
            keep[suspect] &= (distances[suspect] == 0) | supported_by_neighbours(
                distances[suspect], keep[suspect], self._noise.sigma_mm, step_rad)
        clean = np.array([f.clean for f in frames])
        self._withheld = bool(suspect.any()) and self._framer.damage.withheld(
            4 * clean.sum() < clean.size)
        if self._withheld:
            # Nor one that passed its checksum: on such a line 1 in 256 damaged capsules does.
            keep &= distances == 0
        self._counts['rejected_samples'] += int(np.count_nonzero(~keep[placed]))
        return np.where(keep, distances, 0.0)


class CapsuleSamples:
    """
    The samples of placed capsules in stream order, as every capsule format lays them out.

    A capsule's samples spread evenly over its sweep (less each one's angle correction, in a
    format that has one); a turn starts at the first sample whose evenly spread angle is below
    its predecessor's.

    :param samples_per_capsule: samples per capsule of the format
    :param counts: the decoder's counts (``samples`` counts what is laid out)
    """

    def __init__(self, samples_per_capsule: int, counts: dict):
        self._per = samples_per_capsule
        self._k = np.arange(samples_per_capsule)
        self._fractions = self._k / samples_per_capsule
        self._counts = counts
        self._last_uniform_deg = None

    def of(self, frames: list, distance_mm: np.ndarray, correction_deg=None,
           device_time_us: Optional[np.ndarray] = None) -> Samples:
        """
        Lay out the samples of placed capsules.

        :param frames: the placed capsules, in stream order
        :param distance_mm: their distances, shape (capsules x samples,), mm (0: none)
        :param correction_deg: each sample's angle correction, degrees (None: none)
        :param device_time_us: each sample's device timestamp, microseconds (None: none)
        :return: the samples
        """
        count, per = len(frames), self._per
        if not count:
            return Samples.concat([])
        starts = np.array([f.placement.start_q8 for f in frames], np.float64)
        sweeps = np.array([f.placement.sweep_q8 for f in frames], np.float64)
        uniform = np.mod((starts[:, None] + sweeps[:, None] * self._fractions).reshape(-1)
                         / 256.0, 360.0)
        previous = np.concatenate([[-np.inf if self._last_uniform_deg is None
                                    else self._last_uniform_deg], uniform[:-1]])
        self._last_uniform_deg = uniform[-1]
        self._counts['samples'] += uniform.size
        k = np.tile(self._k, count)
        return Samples(angle_deg=(uniform if correction_deg is None
                                  else np.mod(uniform - correction_deg, 360.0)),
                       distance_mm=distance_mm,
                       quality=np.where(distance_mm > 0, DENSE_RETURN_QUALITY, 0).astype(np.uint8),
                       start=uniform < previous,
                       frame_end=np.repeat([f.end for f in frames], per),
                       samples_after=per - 1 - k,
                       slot=np.repeat([f.slot for f in frames], per) * per + k,
                       device_time_us=device_time_us)


class RangeNoise:
    """
    The range noise scale, from the median second difference along capsules.

    A damaged sample spoils three second differences: while fewer than half are, their median
    is the noise's (a lower quantile, scaled as for Gaussian noise, holds while fewer than that
    share are). Until a capsule's worth is measured, the S1's datasheet accuracy.

    :param samples_per_capsule: samples per capsule of the format measured
    :param quantile: the quantile of the absolute second differences measured
    """

    def __init__(self, samples_per_capsule: int = SAMPLES_PER_CAPSULE, quantile: float = 0.5):
        self.sigma_mm = _SIGMA_PRIOR_MM
        # The quantile of |N(0, 6 sigma^2)|, a second difference's, in sigmas (0.5: 1.65).
        self._quantile = quantile
        self._to_sigma = 1.0 / (statistics.NormalDist().inv_cdf(0.5 + 0.5 * quantile)
                                * math.sqrt(6.0))
        self._first = samples_per_capsule
        self._window = []
        self._unmeasured = 0
        self._measured = False

    def update(self, distances: np.ndarray):
        """
        Take the distances of more capsules.

        :param distances: shape (capsules, samples), mm; 0 where there is no (readable) return
        """
        second = distances[:, :-2] - 2.0 * distances[:, 1:-1] + distances[:, 2:]
        returns = (distances[:, :-2] > 0) & (distances[:, 1:-1] > 0) & (distances[:, 2:] > 0)
        self._window.append(np.abs(second[returns]))
        self._unmeasured += int(np.count_nonzero(returns))
        if self._unmeasured < (_SIGMA_WINDOW // 4 if self._measured else self._first):
            return
        # A quarter of the window is new (a capsule's worth at first): take the median.
        window = np.concatenate(self._window)[-_SIGMA_WINDOW:]
        self._window, self._unmeasured, self._measured = [window], 0, True
        self.sigma_mm = max(_SIGMA_FLOOR_MM, self._to_sigma * float(np.quantile(
            window, self._quantile)))


def _flip_deltas(distances: np.ndarray) -> tuple:
    """
    Return how each distance changes when one bit of its two bytes flips, and which bit.

    :param distances: dense capsules' distances, shape (capsules, 40), whole mm
    :return: ``(deltas, bits)`` as :func:`flip_repairs` takes them
    """
    d = distances.astype(np.int64)[..., None]
    j = np.arange(16)
    offsets = _DISTANCE_OFFSETS[:, None] + j // 8
    return (d ^ (1 << j)) - d, np.broadcast_to(offsets * 8 + j % 8, d.shape[:2] + (16,))


def _realign(raw: np.ndarray, regions: list, shifts: list, max_mm: int, noise_mm: float):
    """
    Read the distances of regions that lost (shift > 0) or gained bytes (step 2).

    All regions are realigned together, in one dynamic programming pass over their samples
    (shorter regions padded at the end).

    :param raw: the received bytes
    :param regions: the regions (:class:`~wctls_rplidar.framing.Region`)
    :param shifts: bytes each region lost (negative: gained)
    :param max_mm: farthest valid distance, mm
    :param noise_mm: how far true neighbours may differ by noise alone, mm
    :return: an iterator, in region order, of ``(distances, kept, shift per sample)``
    """
    if not regions:
        return iter(())
    count = max(region.count for region in regions)
    offsets = (np.repeat(CAPSULE_SIZE * np.arange(count), SAMPLES_PER_CAPSULE)
               + np.tile(_DISTANCE_OFFSETS, count))
    pos = np.array([region.pos for region in regions])
    shift = np.array(shifts)
    reach = np.arange(shift.max() + 1)
    index = pos[:, None, None] + offsets[None, None, :] - reach[None, :, None]
    # A distance is read between the region's first header and the next one.
    end = np.array([region.end for region in regions])
    inside = ((index >= pos[:, None, None] + _DISTANCE_OFFSETS[0])
              & (index + 2 <= end[:, None, None]))
    index = np.clip(index, 0, raw.size - 2)
    values = raw[index].astype(np.int64) | (raw[index + 1].astype(np.int64) << 8)
    lengths = [SAMPLES_PER_CAPSULE * region.count for region in regions]
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


def supported_by_neighbours(distances: np.ndarray, usable: np.ndarray, sigma_mm: float,
                            step_rad: float, sigmas: float = _SIGMAS,
                            between: bool = False) -> np.ndarray:
    """
    Tell which distances a neighbour pair in the same capsule predicts (step 4).

    :param distances: distances of suspect capsules, shape (capsules, samples), mm
    :param usable: which distances may predict others (readable, in range)
    :param sigma_mm: range noise scale, mm
    :param step_rad: angle between samples, rad
    :param sigmas: noise sigmas allowed (the steepness limit keeps the usual ones)
    :param between: only the pair on both sides predicts
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
    noise_mid, noise_end = sigmas * math.sqrt(1.5) * sigma_mm, sigmas * math.sqrt(6.0) * sigma_mm
    bend_mid, flat_mid = surface(midpoint, 0.5 * (after - before))
    bend_forward, flat_forward = surface(before, before - before2)
    bend_backward, flat_backward = surface(after, after - after2)
    fits_mid = (ok_b & ok_a & flat_mid
                & (np.abs(distances - midpoint) <= noise_mid + 0.5 * bend_mid))
    fits_forward = (ok_b & ok_b2 & flat_forward
                    & (np.abs(distances - forward) <= noise_end + bend_forward))
    fits_backward = (ok_a & ok_a2 & flat_backward
                     & (np.abs(distances - backward) <= noise_end + bend_backward))
    return fits_mid if between else fits_mid | fits_forward | fits_backward


def believed_flips(placer: CapsulePlacer, shown: np.ndarray, sigma_mm: float,
                   max_mm: float) -> bool:
    """
    Tell whether intact capsules' sign of a double flip is to be believed; tell the placer.

    A far point of a cluttered scene forges one repaired spike with a chance of about
    ``2 t / R`` per bit (t the repair's tolerance, R the range the clutter spreads over, at most
    the mode's), a capsule's sign (two at one bit position) with about its square times the
    pairs of far points. On a smooth scene (t of millimetres) that is negligible; on a noisy,
    cluttered one (t of decimetres) it is not: the ultra round trip of a noisy walk with 5 % far
    points forged it in 11 of 2700 streams, and every capsule's clutter was rejected. A double
    flip is likely only on a line that damages bytes, which shows it otherwise too
    (:meth:`~wctls_rplidar.framing.CapsulePlacer.shows_damage`). So on a line that shows no
    damage the sign is believed at once only where t is at most
    :data:`_CLEAN_LINE_TOLERANCE_SHARE` of the mode's range (or two capsules show it);
    elsewhere it is noted as a weak sign, and believed when it comes again within the placer's
    memory: a line that flips bits keeps showing it.

    :param placer: the decoder's placer (told of the sign)
    :param shown: the capsules that show a double flip (:func:`unseen_flips`)
    :param sigma_mm: the range noise scale, mm
    :param max_mm: the mode's farthest range, mm
    :return: whether the sign is believed (no capsule of the batch then vouches for itself)
    """
    if not shown.any():
        return False
    if (not placer.shows_damage() and np.count_nonzero(shown) < 2
            and not sharp_repairs(sigma_mm, max_mm)):
        placer.note_weak_sign()
        return False
    placer.note_unseen_damage()
    return True


def sharp_repairs(sigma_mm: float, max_mm: float) -> bool:
    """
    Tell whether a flip's repair is too tight for clutter to forge: a smooth scene's.

    :param sigma_mm: the range noise scale, mm
    :param max_mm: the mode's farthest range, mm
    :return: the repair's tolerance is at most :data:`_CLEAN_LINE_TOLERANCE_SHARE` of the range
    """
    return _REPAIR_SIGMAS * math.sqrt(1.5) * sigma_mm <= _CLEAN_LINE_TOLERANCE_SHARE * max_mm


def repaired_samples(slots: np.ndarray, per: int, repairs: tuple,
                     reach: tuple = (0,)) -> np.ndarray:
    """
    Mark the samples of lone spikes that one flipped bit repairs (:func:`flip_repairs`).

    :param slots: the capsules' stream indices (a sample reached beyond a capsule's ends is in
        the capsule before or after it, when that one is among them)
    :param per: samples per capsule
    :param repairs: ``(capsule, sample, bit)`` arrays of :func:`flip_repairs`
    :param reach: the samples (offsets from a repair's) its repaired value is read into
    :return: shape (capsules, per), bool
    """
    slots = np.asarray(slots)
    marked = np.zeros((len(slots), per), bool)
    capsule, sample, _ = repairs
    for offset in reach:
        moved, at = np.divmod(sample + offset, per)
        target = capsule + moved
        inside = (target >= 0) & (target < len(slots))
        inside[inside] &= slots[target[inside]] - slots[capsule[inside]] == moved[inside]
        marked[target[inside], at[inside]] = True
    return marked


def unseen_flips(count: int, *repairs: tuple) -> np.ndarray:
    """
    Tell which capsules that passed their checksum show bits flipped that it cannot see.

    Flipping one bit at the same position in two bytes leaves an XOR checksum as it was: two
    lone spikes that one flipped bit each repairs (:func:`flip_repairs`), at the same bit
    position of two different bytes (not neighbours), are both of one. Real
    geometry rarely shows one such spike and two at one bit position almost never: the
    evidence that a line flips bits.

    :param count: capsules
    :param repairs: ``(capsule, sample, bit)`` arrays of :func:`flip_repairs`, joined
    :return: per capsule, True when it shows a double flip
    """
    capsule, sample, bit = (np.concatenate(column) for column in zip(*repairs))
    shown = np.zeros(count, bool)
    for i in np.unique(capsule).tolist():
        here = capsule == i
        for position in np.unique(bit[here] % 8).tolist():
            at = here & (bit % 8 == position)
            apart = np.unique(sample[at])
            if (apart.size >= 2 and apart[-1] - apart[0] >= 2
                    and np.unique(bit[at] // 8).size >= 2):
                shown[i] = True
    return shown


def flip_repairs(distances: np.ndarray, usable: np.ndarray, deltas: np.ndarray,
                 bits: np.ndarray, sigma_mm: float, step_rad: float,
                 slots: Optional[np.ndarray] = None, spacing: int = 1,
                 between: bool = True) -> tuple:
    """
    Find the lone spikes of capsules that one flipped bit each repairs.

    A lone spike is a sample no neighbour pair predicts (within :data:`_SIGMAS` noise sigmas)
    that one flipped bit puts where the neighbours on both sides predict it (within
    :data:`_REPAIR_SIGMAS`), by a change of at least :data:`_REPAIR_MIN_TOLERANCES`
    tolerances, in a capsule with at most :data:`_MAX_SPIKES` spikes. A
    capsule's first and last samples have their neighbours in the capsules before and after
    it, when those are among the ones given.

    A cluttered scene (foliage, edges, glass) has far samples among near ones on an intact
    link, and a far sample lies within the repair's tolerance of some flip's repair by chance
    (uniform clutter over a range R: about ``2 t / R`` per bit, t the tolerance): two at one bit
    position in one capsule were taken for a double flip, and every capsule's clutter rejected
    (the ultra round trip of a noisy walk with 5 % far points: 11 of 2700 streams). So the
    evidence is taken only where clutter cannot forge it cheaply and a flip still gives it:
    the neighbours that predict a repaired spike must not be spikes themselves (a flip hits two
    bytes of samples apart; two far points side by side, repaired together, vouched for each
    other), and the capsule has no spikes beyond the double flip's two (a scene whose capsules
    hold clutter, one far point in twenty, forges the sign with two of its far points, and a
    third then gives it away; a flip in a capsule of a smooth scene leaves exactly two). A
    line that flips bits keeps showing the sign in its capsules of smooth surfaces.

    :param distances: the capsules' distances, shape (capsules, samples), mm (0: no return)
    :param usable: which distances are readable and in range
    :param deltas: each sample's distance change when one bit of its bytes flips, shape
        (capsules, samples, bits), mm
    :param bits: which bit that is, ``byte * 8 + bit`` (-1: none), same shape
    :param sigma_mm: the range noise scale, mm
    :param step_rad: angle between the samples given, rad
    :param slots: the capsules' stream indices (consecutive ones are neighbours)
    :param spacing: the capsule's samples between two given (their index in the repairs)
    :param between: only the neighbours on both sides vouch for a repair (False: also a pair
        on either side where the other side's neighbour has no return, as at the edge of a
        surface; evidence enough to reject the spike, not to believe a line flips bits)
    :return: ``(capsule, sample, bit)`` of each repair, arrays
    """
    count, per = distances.shape
    # Each capsule's samples between the last two of the one before and the first two after.
    d = np.zeros((count, per + 4))
    ok = np.zeros((count, per + 4), bool)
    d[:, 2:-2], ok[:, 2:-2] = distances, usable
    if slots is not None and count > 1:
        index = {slot: i for i, slot in enumerate(np.asarray(slots).tolist())}
        for i, slot in enumerate(np.asarray(slots).tolist()):
            for j, side, source in ((index.get(slot - 1), slice(0, 2), slice(per - 2, per)),
                                    (index.get(slot + 1), slice(per + 2, per + 4), slice(0, 2))):
                if j is not None:
                    d[i, side], ok[i, side] = distances[j, source], usable[j, source]
    lone = ok & (d > 0) & ~supported_by_neighbours(d, ok, sigma_mm, step_rad)
    lone[:, :2] = lone[:, -2:] = False
    # Among neighbours that agree: where the scene has spikes of its own, they tell of no flip.
    rows = np.flatnonzero(lone.any(axis=1) & (np.count_nonzero(lone, axis=1) <= _MAX_SPIKES))
    least_mm = _REPAIR_MIN_TOLERANCES * _SIGMAS * math.sqrt(1.5) * sigma_mm
    predicting = ok[rows] & ~lone[rows]
    # One side vouches only beside a sample without a return: an edge with returns on both
    # sides is a scene's, which a one-sided repair fits now and then.
    beside_none = np.zeros(predicting.shape, bool)
    beside_none[:, 1:-1] = ~predicting[:, :-2] | ~predicting[:, 2:]
    found = []
    for b in range(deltas.shape[2]):
        change = np.zeros((rows.size, per + 4))
        change[:, 2:-2] = deltas[rows, :, b]
        trial = np.where(lone[rows], d[rows] + change, d[rows])
        supported = supported_by_neighbours(trial, predicting, sigma_mm, step_rad,
                                            _REPAIR_SIGMAS, True)
        if not between:
            supported |= beside_none & supported_by_neighbours(
                trial, predicting, sigma_mm, step_rad, _REPAIR_SIGMAS, False)
        fits = (lone[rows] & (trial > 0) & (np.abs(change) >= least_mm)
                & supported)[:, 2:-2] & (bits[rows, :, b] >= 0)
        capsule, sample = np.nonzero(fits)
        found.append((rows[capsule], sample * spacing, bits[rows[capsule], sample, b]))
    return tuple(np.concatenate(column) if found else np.zeros(0, np.int64)
                 for column in zip(*found)) if found else (np.zeros(0, np.int64),) * 3
