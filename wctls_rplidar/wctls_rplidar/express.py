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

:class:`ExpressCapsuleDecoder` is a :class:`~wctls_rplidar.checked.CheckedCapsuleDecoder`:
framed as every capsule format, so a capsule cut short loses only itself, and its samples
published only when the checksum vouches for them.
"""

import numpy as np

from .checked import CapsuleLayout, CheckedCapsuleDecoder, checksum_passes, with_checksum

EXPRESS_CAPSULE_SIZE = 84
EXPRESS_SAMPLES_PER_CAPSULE = 32
EXPRESS_MAX_DISTANCE_MM = 0x3FFF
EXPRESS_MAX_CORRECTION_Q3 = 0x3F

_CABINS = EXPRESS_SAMPLES_PER_CAPSULE // 2
# Angle corrections of neighbouring samples in a damaged capsule agree this well, 1/8 degree
# (farther than any correction from one beyond the capsule's ends).
_CORRECTION_AGREEMENT_Q3 = 1
_FAR_Q3 = 1 << 8
_CABIN_DTYPE = np.dtype([('fields', '<u2', (2,)), ('corrections', 'u1')])
_CAPSULE_DTYPE = np.dtype([('sync1', 'u1'), ('sync2', 'u1'), ('start_angle', '<u2'),
                           ('cabins', _CABIN_DTYPE, (_CABINS,))])


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
    return with_checksum(capsules.view(np.uint8).reshape(count, EXPRESS_CAPSULE_SIZE))


def decode_express_capsules(raw: np.ndarray) -> tuple:
    """
    Read whole express capsules' fields.

    :param raw: capsules, shape (n, 84), uint8
    :return: ``(clean, start_field, distance_mm, correction_q3)``: checksum and sync passed
        (n,), start angle fields with the S flag (n,), distances and angle corrections (n, 32)
    """
    capsules = np.ascontiguousarray(raw, np.uint8).view(_CAPSULE_DTYPE)[:, 0]
    clean = checksum_passes(raw)
    fields = capsules['cabins']['fields'].astype(np.int64)
    nibbles = capsules['cabins']['corrections'].astype(np.int64)
    low = np.stack([nibbles & 0xF, nibbles >> 4], axis=-1)
    count = len(capsules)
    return (clean, capsules['start_angle'].astype(np.int64),
            (fields >> 2).reshape(count, EXPRESS_SAMPLES_PER_CAPSULE),
            (low | ((fields & 0x3) << 4)).reshape(count, EXPRESS_SAMPLES_PER_CAPSULE))


class ExpressLayout(CapsuleLayout):
    """The express capsule's cabins."""

    size = EXPRESS_CAPSULE_SIZE
    samples = EXPRESS_SAMPLES_PER_CAPSULE

    def read(self, capsules: np.ndarray, successors) -> tuple:
        """Return the distances (mm) and angle corrections (degrees) of intact capsules."""
        _, _, distance_mm, correction_q3 = decode_express_capsules(capsules)
        return distance_mm, correction_q3 / 8.0

    def flip_deltas(self, capsules: np.ndarray, distance_mm: np.ndarray) -> tuple:
        """Return each distance's change by a flip of one of its field's bits 2-15, and which."""
        d = np.rint(distance_mm).astype(np.int64)[..., None]
        j = np.arange(2, 16)
        field_at = 4 + 5 * (np.arange(EXPRESS_SAMPLES_PER_CAPSULE) // 2) + 2 * (
            np.arange(EXPRESS_SAMPLES_PER_CAPSULE) % 2)
        bits = (field_at[:, None] + j // 8) * 8 + j % 8
        return (d ^ (1 << (j - 2))) - d, np.broadcast_to(bits, d.shape[:2] + (j.size,))

    def plausible(self, distance_mm: np.ndarray, correction_deg: np.ndarray,
                  usable: np.ndarray, sigma_mm: float, step_rad: float) -> np.ndarray:
        """
        Tell which samples of capsules that failed their checksum to believe.

        A distance as in every layout (a neighbour pair predicts it); its angle correction
        only when it agrees with a neighbour's from another cabin, directly or through the
        cabin's other sample: the two samples of a cabin share the byte of their low bits, so
        they can be wrong together, and a wrong correction is a wrong angle that no distance
        check sees. A triangulation device's correction changes with the distance, slowly
        along a surface.
        """
        supported = super().plausible(distance_mm, correction_deg, usable, sigma_mm, step_rad)
        correction_q3 = np.rint(correction_deg * 8.0).astype(np.int64)
        pad = np.full((len(correction_q3), 1), -_FAR_Q3)
        padded = np.concatenate([pad, correction_q3, pad], axis=1)
        # Sample 2c's neighbour in another cabin is 2c - 1, sample 2c + 1's is 2c + 2.
        outward = np.where(np.arange(EXPRESS_SAMPLES_PER_CAPSULE) % 2 == 0, -1, 1)
        index = np.arange(EXPRESS_SAMPLES_PER_CAPSULE) + 1
        other = padded[:, index + outward]
        partner = padded[:, index - outward]
        partner_other = padded[:, index - 2 * outward]
        agrees = np.abs(correction_q3 - other) <= _CORRECTION_AGREEMENT_Q3
        through_partner = ((np.abs(correction_q3 - partner) <= _CORRECTION_AGREEMENT_Q3)
                           & (np.abs(partner - partner_other) <= _CORRECTION_AGREEMENT_Q3))
        return supported & (agrees | through_partner)


class ExpressCapsuleDecoder(CheckedCapsuleDecoder):
    """
    Incremental decoder of express capsules that resynchronises capsule by capsule.

    :param us_per_sample: the scan mode's microseconds per sample (sets the sweep limit)
    :param max_distance_m: the mode's farthest range; distances beyond are rejected
    """

    FRAME_SIZE = EXPRESS_CAPSULE_SIZE
    SAMPLES_PER_FRAME = EXPRESS_SAMPLES_PER_CAPSULE

    def __init__(self, us_per_sample: float, max_distance_m: float = 16.0):
        super().__init__(ExpressLayout(), us_per_sample, max_distance_m)
