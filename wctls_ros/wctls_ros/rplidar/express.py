# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The express capsule stream (answer 0x82, the legacy Express mode of the A series), pure.

The layout, as SLAMTEC's SDK reads it (the packed struct of a capsule and of its cabins in
``sl_lidar_cmd.h``; the conversion in ``UnpackerHandler_CapsuleNode``, ``handler_capsules.cpp``).
A capsule is 84 bytes, little-endian:

- byte 0: the sync nibble 0xA (high) and checksum bits 0-3 (low); byte 1: the sync nibble 0x5
  (high) and checksum bits 4-7 (low). The checksum is the XOR of bytes 2 to 83.
- bytes 2-3: the start angle, u16: bits 0-14 in 1/64 degree, bit 15 the S flag (set on the
  first capsule after the scan started).
- bytes 4-83: 16 cabins of 5 bytes; cabin c (at byte 4 + 5c) holds samples 2c and 2c + 1: two
  u16 fields, one per sample, then one byte of angle corrections. A sample's field holds its
  distance in whole millimetres in bits 2-15 (0: no return, 16383 mm at most) and bits 4-5 of
  its angle correction in bits 0-1; bits 0-3 of the correction are the byte's low nibble for
  the first sample, its high nibble for the second. The correction is unsigned, 1/8 degree
  (0 to 7.875 degrees).
- Sample k (0-31) of a capsule lies at ``start + k * sweep / 32 - correction_k``, the sweep
  being the angle to the next capsule's start (modulo 360 degrees): a capsule is decoded once
  its successor has arrived. The SDK truncates that angle to 1/64 degree and checks no sweep
  limit (unlike the dense stream's); it drops a capsule that fails its checksum, and the one
  before it, restarts at an S flag, and reports quality 47 for every return.

:class:`ExpressCapsuleDecoder` frames the stream with :mod:`~wctls_ros.rplidar.framing` (shared
by every capsule format): a capsule cut short is followed at once by the next one, which is
read, and start angles are judged by their sequence. A capsule's distances are published only
when its checksum passes on a line not otherwise damaged and its start angle is in sequence;
other capsules placed in angle are published as no return (counted as rejected samples). Unlike
the dense decoder it does not realign the samples of a capsule that lost bytes nor keep the
plausible distances of one that failed its checksum.
"""

import numpy as np

from .framing import AngleTrack, CapsuleFramer, CapsulePlacer, placeable
from .protocol import DENSE_RETURN_QUALITY, Samples, StreamCounts

EXPRESS_CAPSULE_SIZE = 84
EXPRESS_SAMPLES_PER_CAPSULE = 32
EXPRESS_MAX_DISTANCE_MM = 0x3FFF
EXPRESS_MAX_CORRECTION_Q3 = 0x3F
# The sweep assumed until one is measured: the turn at 10 Hz, degrees per second.
_NOMINAL_DEG_PER_S = 3600.0

_CABINS = EXPRESS_SAMPLES_PER_CAPSULE // 2
_CABIN_DTYPE = np.dtype([('fields', '<u2', (2,)), ('corrections', 'u1')])
_CAPSULE_DTYPE = np.dtype([('sync1', 'u1'), ('sync2', 'u1'), ('start_angle', '<u2'),
                           ('cabins', _CABIN_DTYPE, (_CABINS,))])
_K = np.arange(EXPRESS_SAMPLES_PER_CAPSULE)
_FRACTIONS = _K / EXPRESS_SAMPLES_PER_CAPSULE
_NO_ANGLE_FIELD = 0x7FFF       # a start angle field beyond 360 degrees: no angle


def encode_express_capsules(start_q6: np.ndarray, distance_mm: np.ndarray,
                            correction_q3: np.ndarray, start_flag: np.ndarray) -> bytes:
    """
    Encode 84-byte express capsules (answer type 0x82) with their checksums.

    :param start_q6: start angle of each capsule, 1/64 degree, 0-23039
    :param distance_mm: distances, shape (n, 32), whole mm, 0 = no return, at most 16383
    :param correction_q3: angle corrections, shape (n, 32), 1/8 degree, 0-63 (sample k lies
        that far before ``start + k * sweep / 32``)
    :param start_flag: S flag of each capsule (set on the first capsule after the start command)
    :return: the capsule bytes
    """
    flags = np.asarray(start_flag, dtype=np.uint16) << 15
    count = len(flags)
    distance = np.asarray(distance_mm, np.uint16).reshape(count, _CABINS, 2)
    correction = np.asarray(correction_q3, np.uint16).reshape(count, _CABINS, 2)
    capsules = np.zeros(count, _CAPSULE_DTYPE)
    capsules['start_angle'] = np.asarray(start_q6, np.uint16) | flags
    capsules['cabins']['fields'] = (distance << 2) | (correction >> 4)
    capsules['cabins']['corrections'] = (correction[..., 0] & 0xF) | ((correction[..., 1] & 0xF)
                                                                      << 4)
    raw = capsules.view(np.uint8).reshape(count, EXPRESS_CAPSULE_SIZE)
    sums = np.bitwise_xor.reduce(raw[:, 2:], axis=1)
    capsules['sync1'] = 0xA0 | (sums & 0x0F)
    capsules['sync2'] = 0x50 | (sums >> 4)
    return capsules.tobytes()


def decode_express_capsules(raw: np.ndarray) -> tuple:
    """
    Read whole express capsules' fields.

    :param raw: capsules, shape (n, 84), uint8
    :return: ``(clean, start_field, distance_mm, correction_q3)``: checksum and sync passed
        (n,), start angle fields with the S flag (n,), distances and angle corrections (n, 32)
    """
    capsules = np.ascontiguousarray(raw, np.uint8).view(_CAPSULE_DTYPE)[:, 0]
    received = (raw[:, 0] & 0x0F) | (raw[:, 1] << 4)
    clean = (((raw[:, 0] >> 4) == 0xA) & ((raw[:, 1] >> 4) == 0x5)
             & (received == np.bitwise_xor.reduce(raw[:, 2:], axis=1)))
    fields = capsules['cabins']['fields'].astype(np.int64)
    nibbles = capsules['cabins']['corrections'].astype(np.int64)
    low = np.stack([nibbles & 0xF, nibbles >> 4], axis=-1)
    count = len(capsules)
    return (clean, capsules['start_angle'].astype(np.int64),
            (fields >> 2).reshape(count, EXPRESS_SAMPLES_PER_CAPSULE),
            (low | ((fields & 0x3) << 4)).reshape(count, EXPRESS_SAMPLES_PER_CAPSULE))


class _Frame:
    """One capsule's content once framed (mutable working record of the decoder)."""

    __slots__ = ('slot', 'angle_field', 'distances', 'corrections', 'readable', 'clean', 'cut',
                 'end', 'placement', 'suspect')

    def __init__(self, slot, angle_field, distances, corrections, readable, clean, cut, end):
        self.slot = slot
        self.angle_field = angle_field
        self.distances = distances
        self.corrections = corrections
        self.readable = readable
        self.clean = clean
        self.cut = cut
        self.end = end
        self.placement = None
        self.suspect = not clean


class ExpressCapsuleDecoder:
    """
    Incremental decoder of express capsules that resynchronises capsule by capsule.

    :param us_per_sample: the scan mode's microseconds per sample (sets the sweep limit)
    :param max_distance_m: the mode's farthest range; distances beyond are rejected
    """

    FRAME_SIZE = EXPRESS_CAPSULE_SIZE
    SAMPLES_PER_FRAME = EXPRESS_SAMPLES_PER_CAPSULE

    def __init__(self, us_per_sample: float, max_distance_m: float = 16.0):
        # As the dense decoder's (the SDK checks none here): the sweep of a capsule at 100 Hz.
        self._max_sweep_q8 = (360 * 100 * EXPRESS_SAMPLES_PER_CAPSULE
                              // max(1000000 // max(int(us_per_sample), 1), 1)) << 8
        nominal_q8 = round(_NOMINAL_DEG_PER_S * EXPRESS_SAMPLES_PER_CAPSULE * us_per_sample
                           * 1e-6 * 256.0)
        self._max_mm = int(max_distance_m * 1000.0)
        self._counts = dict.fromkeys(StreamCounts.__dataclass_fields__, 0)
        self._angles = AngleTrack(self._max_sweep_q8, min(max(nominal_q8, 1),
                                                          self._max_sweep_q8))
        self._framer = CapsuleFramer(EXPRESS_CAPSULE_SIZE, self._angles, self._counts)
        self._placer = CapsulePlacer(self._angles, self._framer, self._counts)
        self._last_uniform_deg = None

    @property
    def counts(self) -> StreamCounts:
        """Return what the decoder has met so far (capsules, damage, losses)."""
        return StreamCounts(**self._counts)

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
        placed = [f for f in frames if placeable(f.placement, f.clean, f.cut)]
        self._counts['lost_frames'] += len(frames) - len(placed)
        return self._samples(placed)

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
        exact = [r.pos + EXPRESS_CAPSULE_SIZE * j
                 for r in regions if not r.lost for j in range(r.count)]
        if exact:
            clean, fields, distances, corrections = decode_express_capsules(
                raw[np.array(exact)[:, None] + np.arange(EXPRESS_CAPSULE_SIZE)])
            decoded = iter(zip(clean.tolist(), fields.tolist(), distances, corrections))
        unreadable = np.zeros(EXPRESS_SAMPLES_PER_CAPSULE, np.int64)
        frames = []
        for pos, count, end, slot, lost, cut in regions:
            for j in range(count):
                frame_end = offset + min(end, pos + EXPRESS_CAPSULE_SIZE * (j + 1))
                if not lost:
                    ok, field, distance, correction = next(decoded)
                    frames.append(_Frame(slot + j, field, distance, correction, True, ok,
                                         False, frame_end))
                    continue
                field = int(raw[pos + 2]) | int(raw[pos + 3]) << 8 if j == 0 else _NO_ANGLE_FIELD
                frames.append(_Frame(slot + j, field, unreadable, unreadable, False, False,
                                     cut or lost < 0, frame_end))
        self._counts['frames'] += len(frames)
        self._counts['damaged_frames'] += sum(not f.clean for f in frames)
        return frames

    def _samples(self, frames: list) -> Samples:
        """Lay out the placed capsules' samples; reject those not vouched for."""
        count = len(frames)
        if not count:
            return Samples.concat([])
        starts = np.array([f.placement.start_q8 for f in frames], np.float64)
        sweeps = np.array([f.placement.sweep_q8 for f in frames], np.float64)
        uniform = np.mod((starts[:, None] + sweeps[:, None] * _FRACTIONS).reshape(-1) / 256.0,
                         360.0)
        corrections = np.array([f.corrections for f in frames], np.float64).reshape(-1)
        distances = np.array([f.distances for f in frames], np.int64)
        readable = np.array([f.readable for f in frames])[:, None]
        vouched = np.array([f.readable and not f.suspect for f in frames])[:, None]
        keep = (vouched & (distances <= self._max_mm)) | (readable & (distances == 0))
        self._counts['rejected_samples'] += int(np.count_nonzero(~keep))
        distance = np.where(keep, distances, 0).reshape(-1).astype(np.float64)
        # A turn starts where the uncorrected angles fall back: the corrections, up to 7.875
        # degrees, are larger than the step between samples.
        previous = np.concatenate([[-np.inf if self._last_uniform_deg is None
                                    else self._last_uniform_deg], uniform[:-1]])
        self._last_uniform_deg = uniform[-1]
        self._counts['samples'] += uniform.size
        k = np.tile(_K, count)
        return Samples(angle_deg=np.mod(uniform - corrections / 8.0, 360.0),
                       distance_mm=distance,
                       quality=np.where(distance > 0, DENSE_RETURN_QUALITY, 0).astype(np.uint8),
                       start=uniform < previous,
                       frame_end=np.repeat([f.end for f in frames], EXPRESS_SAMPLES_PER_CAPSULE),
                       samples_after=EXPRESS_SAMPLES_PER_CAPSULE - 1 - k,
                       slot=np.repeat([f.slot for f in frames], EXPRESS_SAMPLES_PER_CAPSULE)
                       * EXPRESS_SAMPLES_PER_CAPSULE + k)
