# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Ultra-dense capsules (answer type 0x86): 64 samples with a device timestamp (pure, no I/O).

The layout, as SLAMTEC's SDK reads it (sl_lidar_cmd.h, handler_capsules.cpp):

- bytes 0-1: sync nibbles and checksum (XOR of bytes 2 to 169), as in every capsule;
- bytes 2-5: u32 timestamp on the device's clock; bytes 6-7: u16 device status;
- bytes 8-9: u16 start angle, 1/64 degree, bit 15 the S flag;
- 32 cabins of 5 bytes: two u16 and a byte whose low and high nibbles extend them to 20 bits,
  sample 2c and 2c + 1. Bits 0-1 of a sample are its scale s: bits 2 to 11 + s are a value v
  and the bits above a quality of 8 - s bits, shifted up by s. The distance is ``2 v`` mm
  (s = 0, to 2046 mm), ``2046 + 3 v`` (s = 1), ``8187 + 4 v`` (s = 2) or ``24567 + 5 v``
  (s = 3). The SDK averages a scale-0 distance within 2 mm of the distance before it (in
  quarter millimetres, halves rounded down) with that one: the device's 2 mm step, smoothed;
  this decoder does the same, so that it agrees with the SDK sample for sample.
- Sample k (0-63) lies at ``start + k * sweep / 64`` (no angle correction: a dTOF device),
  the sweep being the angle to the next capsule's start.

:class:`UltraDenseCapsuleDecoder` is a :class:`~wctls_rplidar.checked.CheckedCapsuleDecoder`
(framing, start angle tracking and checksum vouching as for express and ultra capsules); its
samples carry the capsule's device timestamp (:attr:`~wctls_rplidar.protocol.Samples.
device_time_us`), which a driver may use to stamp scans on the device's clock.
"""

from typing import Optional

import numpy as np

from .checked import CapsuleLayout, CheckedCapsuleDecoder, with_checksum

ULTRA_DENSE_CAPSULE_SIZE = 170
ULTRA_DENSE_SAMPLES_PER_CAPSULE = 64
# Per scale: the distance at value 0 (mm), mm per value step and the value's bits.
SCALE_BASE_MM = (0, 2046, 8187, 24567)
SCALE_STEP_MM = (2, 3, 4, 5)
_VALUE_BITS = (10, 11, 12, 13)
ULTRA_DENSE_MAX_DISTANCE_MM = SCALE_BASE_MM[3] + SCALE_STEP_MM[3] * ((1 << _VALUE_BITS[3]) - 1)
# The SDK smooths a scale-0 distance with the one before it when they lie this close, 1/4 mm.
_SMOOTHING_Q2 = 8

_CABINS = ULTRA_DENSE_SAMPLES_PER_CAPSULE // 2
_CABIN_DTYPE = np.dtype([('low', '<u2', (2,)), ('high', 'u1')])
_CAPSULE_DTYPE = np.dtype([('sync1', 'u1'), ('sync2', 'u1'), ('time_us', '<u4'),
                           ('status', '<u2'), ('start_angle', '<u2'),
                           ('cabins', _CABIN_DTYPE, (_CABINS,))])


def encode_ultra_dense_capsules(start_q6: np.ndarray, distance_mm: np.ndarray,
                                quality: np.ndarray, start_flag: np.ndarray,
                                time_us: np.ndarray) -> bytes:
    """
    Encode ultra-dense capsules (answer type 0x86) with their checksums, as a device would.

    Each distance takes the finest scale that reaches it, rounded to that scale's step.

    :param start_q6: start angle of each capsule, 1/64 degree, 0-23039
    :param distance_mm: distances, shape (n, 64), mm, 0 = no return, at most
        :data:`ULTRA_DENSE_MAX_DISTANCE_MM`
    :param quality: qualities, shape (n, 64), 0-255 (coarser scales keep their high bits)
    :param start_flag: S flag of each capsule (set on the first capsule after the start command)
    :param time_us: each capsule's timestamp on the device's clock, microseconds (modulo 2^32)
    :return: the capsule bytes
    """
    flags = np.asarray(start_flag, dtype=np.uint16) << 15
    count = len(flags)
    distance = np.asarray(distance_mm, np.float64).reshape(count, ULTRA_DENSE_SAMPLES_PER_CAPSULE)
    fields = np.zeros(distance.shape, np.int64)
    done = np.zeros(distance.shape, bool)
    for scale, (base, step, bits) in enumerate(zip(SCALE_BASE_MM, SCALE_STEP_MM, _VALUE_BITS)):
        value = np.rint((distance - base) / step).astype(np.int64)
        fits = ~done & (value <= (1 << bits) - 1)
        level = np.asarray(quality, np.int64).reshape(distance.shape) >> scale
        fields[fits] = ((level << (bits + 2)) | (value << 2) | scale)[fits]
        done |= fits
    capsules = np.zeros(count, _CAPSULE_DTYPE)
    capsules['time_us'] = np.asarray(time_us, np.int64) % (1 << 32)
    capsules['start_angle'] = np.asarray(start_q6, np.uint16) | flags
    pairs = fields.reshape(count, _CABINS, 2)
    capsules['cabins']['low'] = pairs & 0xFFFF
    capsules['cabins']['high'] = (pairs[..., 0] >> 16) | ((pairs[..., 1] >> 16) << 4)
    return with_checksum(capsules.view(np.uint8).reshape(count, ULTRA_DENSE_CAPSULE_SIZE))


def decode_ultra_dense_fields(raw: np.ndarray) -> tuple:
    """
    Read whole ultra-dense capsules' 20-bit sample fields, before the SDK's smoothing.

    :param raw: capsules, shape (n, 170), uint8
    :return: ``(time_us, start_field, distance_q2, scale)``: timestamps and start angle
        fields (n,), distances in 1/4 mm and scales (n, 64)
    """
    capsules = np.ascontiguousarray(raw, np.uint8).view(_CAPSULE_DTYPE)[:, 0]
    low = capsules['cabins']['low'].astype(np.int64)
    high = capsules['cabins']['high'].astype(np.int64)
    fields = np.stack([low[..., 0] | ((high & 0xF) << 16), low[..., 1] | ((high >> 4) << 16)],
                      axis=-1).reshape(len(capsules), ULTRA_DENSE_SAMPLES_PER_CAPSULE)
    return (capsules['time_us'].astype(np.int64), capsules['start_angle'].astype(np.int64),
            _field_distance_q2(fields), fields & 0x3)


def _field_distance_q2(fields: np.ndarray) -> np.ndarray:
    """Return the distances of 20-bit sample fields, 1/4 mm (before the SDK's smoothing)."""
    scale = fields & 0x3
    bits = np.array(_VALUE_BITS)[scale]
    value = (fields >> 2) & ((1 << bits) - 1)
    return 4 * (np.array(SCALE_BASE_MM)[scale] + np.array(SCALE_STEP_MM)[scale] * value)


class UltraDenseLayout(CapsuleLayout):
    """The ultra-dense capsule's cabins, with the SDK's smoothing of scale-0 distances."""

    size = ULTRA_DENSE_CAPSULE_SIZE
    samples = ULTRA_DENSE_SAMPLES_PER_CAPSULE
    angle_at = 8
    clock_bits = 32

    def __init__(self):
        self._last_q2 = 0       # the last distance decoded, 1/4 mm (the SDK's _last_dist_q2)

    def read(self, capsules: np.ndarray, successors) -> tuple:
        """Return intact capsules' distances (mm, smoothed as the SDK does); no correction."""
        _, _, distance_q2, scale = decode_ultra_dense_fields(capsules)
        # Rows of zeros stand in for capsules not received: they leave the smoothing alone.
        received = capsules[:, 0] != 0
        flat = distance_q2[received].reshape(-1)
        smoothable = (scale[received].reshape(-1) == 0).tolist()
        values = flat.tolist()
        last = self._last_q2
        for i, value in enumerate(values):
            if smoothable[i] and last and abs(value - last) <= _SMOOTHING_Q2:
                value = (value + last) >> 1
                values[i] = value
            last = value
        self._last_q2 = last
        distance_q2[received] = np.array(values, np.int64).reshape(-1, self.samples)
        return distance_q2 / 4.0, np.zeros(distance_q2.shape)

    def flip_deltas(self, capsules: np.ndarray, distance_mm: np.ndarray) -> tuple:
        """
        Return each distance's change by a flip of one bit of its 20-bit field, and which bit.

        Bits 0-15 of sample 2c's and 2c + 1's fields are their u16, bits 16-19 the low and high
        nibble of the cabin's fifth byte; a flipped scale bit rescales the whole value.
        """
        raw = np.ascontiguousarray(capsules, np.uint8).view(_CAPSULE_DTYPE)[:, 0]
        low = raw['cabins']['low'].astype(np.int64)
        high = raw['cabins']['high'].astype(np.int64)
        fields = np.stack([low[..., 0] | ((high & 0xF) << 16),
                           low[..., 1] | ((high >> 4) << 16)],
                          axis=-1).reshape(len(raw), self.samples)[..., None]
        j = np.arange(20)
        before, after = (_field_distance_q2(f) for f in (fields, fields ^ (1 << j)))
        k = np.arange(self.samples)[:, None]
        cabin_at = 10 + 5 * (k // 2)
        bits = np.where(j < 16, (cabin_at + 2 * (k % 2) + j // 8) * 8 + j % 8,
                        (cabin_at + 4) * 8 + (j - 16) + 4 * (k % 2))
        return (after - before) / 4.0, np.broadcast_to(bits, fields.shape[:2] + (j.size,))

    def device_times_us(self, capsules: np.ndarray) -> Optional[np.ndarray]:
        """Return the capsules' timestamps, microseconds on the device's clock."""
        return decode_ultra_dense_fields(capsules)[0]


class UltraDenseCapsuleDecoder(CheckedCapsuleDecoder):
    """
    Incremental decoder of ultra-dense capsules that resynchronises capsule by capsule.

    :param us_per_sample: the scan mode's microseconds per sample (sets the sweep limit)
    :param max_distance_m: the mode's farthest range; distances beyond are rejected
    """

    FRAME_SIZE = ULTRA_DENSE_CAPSULE_SIZE
    SAMPLES_PER_FRAME = ULTRA_DENSE_SAMPLES_PER_CAPSULE

    def __init__(self, us_per_sample: float, max_distance_m: float = 40.0):
        super().__init__(UltraDenseLayout(), us_per_sample, max_distance_m)
