# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The ultra capsule stream (answer 0x84, the Boost, Sensitivity and Stability modes), pure.

The layout, as SLAMTEC's SDK reads it (the packed structs of an ultra capsule and its cabins and
the variable bit scale constants in ``sl_lidar_cmd.h``; the conversion in
``UnpackerHandler_UltraCapsuleNode`` and ``_varbitscale_decode``, ``handler_capsules.cpp``). A
capsule is 132 bytes, little-endian:

- bytes 0-3: sync nibbles and checksum (XOR of bytes 2 to 131) and the start angle (1/64 degree,
  bit 15 the S flag), as in every capsule format (:mod:`~wctls_rplidar.framing`).
- bytes 4-131: 32 cabins, a u32 each, for samples 3c, 3c + 1 and 3c + 2: bits 0-11 the major
  distance, bits 12-21 and 22-31 two signed 10-bit predictions.
- The major is scaled by a variable bit scale: a scaled value s below 512 is s mm; from 512, 1280,
  1792 and 3328 on it is 512, 2048, 4096 and 16384 mm plus ``(s - that start) << level`` with
  level 1, 2, 3 and 4 (up to 28656 mm). Sample 3c is the major. Sample 3c + 1 is the major plus
  its prediction shifted left by the major's level; sample 3c + 2 is the next cabin's major
  (for the last cabin, that of the next capsule's first) plus its prediction shifted by that
  major's level. Where a cabin's major is 0 and the next one's is not, sample 3c + 1 is taken
  from the next major and its level too. A prediction of 511 or -512 is no return.
- Sample k (0-95) lies at ``start + k * sweep / 96 - offset(distance)``: the sweep to the next
  capsule's start as in the other formats (the SDK truncates the step to 1/65536 degree), and a
  distance-dependent offset, SLAMTEC's calibration in radians times 65536 converted back to
  degrees with their constants: ``int(r * 180 / 3.14159265) / 65536`` degrees where r is 8578
  below 50 mm (and for no return), else ``9150 - (k << 6) - k**3 // 98304`` with
  ``k = 98361 // (4 * distance_mm)``; about 7.5 degrees near, 5.6 at 0.3 m, 7.0 far.
- The SDK reports quality 47 for every return, decodes a capsule once its successor arrived
  intact, checks no sweep limit and publishes a distance that decodes negative as a huge one.

:class:`UltraCapsuleDecoder` is a :class:`~wctls_rplidar.checked.CheckedCapsuleDecoder`:
framed as every capsule format, so a capsule cut short loses only itself, and its samples
published only when the checksum vouches for them. A capsule waits for its successor to be
framed; where the successor is not intact, the samples that depend on its first cabin are
unreadable, as is a distance that decodes negative.
"""

from typing import Optional

import numpy as np

from .capsules import flip_repairs, repaired_samples, unseen_flips
from .checked import CapsuleLayout, CheckedCapsuleDecoder, SPIKE, SPIKE_RUN, with_checksum

ULTRA_CAPSULE_SIZE = 132
ULTRA_SAMPLES_PER_CAPSULE = 96
_CABINS = ULTRA_SAMPLES_PER_CAPSULE // 3
# Variable bit scale: (first scaled value, level, distance there, mm), from the top.
_SCALES = ((3328, 4, 1 << 14), (1792, 3, 1 << 12), (1280, 2, 1 << 11), (512, 1, 1 << 9),
           (0, 0, 0))
ULTRA_MAX_DISTANCE_MM = (1 << 14) + ((0xFFF - 3328) << 4)
_NO_RETURN = (0x1FF, -0x200)
# The offset's calibration (the SDK's constants).
_NEAR_OFFSET_RAD_Q16 = 8578
_FAR_OFFSET_RAD_Q16 = 9150
_OFFSET_K1 = 98361
_OFFSET_CUBE_DIVISOR = 98304
_OFFSET_NEAR_Q2 = 50 * 4
_SDK_PI = 3.14159265
# Noise sigmas a predicted sample of a damaged capsule may lie from its place between majors.
_SIGMAS = 4.0
# Steepest surface a pair may describe: tan(80 degrees) of range per radian (the dense check's).
_STEEPEST = np.tan(np.radians(80.0))


def varbitscale_decode(scaled: np.ndarray) -> tuple:
    """
    Decode variable-bit-scaled distances.

    :param scaled: 12-bit scaled values
    :return: ``(distance_mm, level)``: integer arrays
    """
    scaled = np.asarray(scaled, np.int64)
    distance = np.zeros_like(scaled)
    level = np.zeros_like(scaled)
    done = np.zeros(scaled.shape, bool)
    for first, shift, base in _SCALES:
        here = ~done & (scaled >= first)
        distance[here] = base + ((scaled[here] - first) << shift)
        level[here] = shift
        done |= here
    return distance, level


def varbitscale_encode(distance_mm: np.ndarray) -> np.ndarray:
    """
    Scale distances as the device does (to the nearest value it can send).

    :param distance_mm: whole mm, 0 to :data:`ULTRA_MAX_DISTANCE_MM`
    :return: 12-bit scaled values
    """
    distance = np.asarray(distance_mm, np.int64)
    scaled = np.zeros_like(distance)
    done = np.zeros(distance.shape, bool)
    for first, shift, base in _SCALES:
        here = ~done & (distance >= base)
        scaled[here] = first + ((distance[here] - base + ((1 << shift) >> 1)) >> shift)
        done |= here
    return np.minimum(scaled, 0xFFF)


def offset_deg(distance_mm: np.ndarray) -> np.ndarray:
    """
    Return the SDK's angle offset of ultra capsule samples at their distances.

    :param distance_mm: decoded distances, whole mm (0: no return)
    :return: degrees to subtract from a sample's place on the capsule's grid
    """
    distance_q2 = np.asarray(distance_mm, np.int64) * 4
    k = _OFFSET_K1 // np.maximum(distance_q2, _OFFSET_NEAR_Q2)
    radians_q16 = np.where(distance_q2 >= _OFFSET_NEAR_Q2,
                           _FAR_OFFSET_RAD_Q16 - (k << 6) - k ** 3 // _OFFSET_CUBE_DIVISOR,
                           _NEAR_OFFSET_RAD_Q16)
    return np.trunc(radians_q16 * 180 / _SDK_PI) / 65536.0


def _signed10(bits: np.ndarray) -> np.ndarray:
    """Return 10-bit two's complement fields as integers."""
    return ((bits & 0x3FF) ^ 0x200) - 0x200


def decode_ultra_capsules(capsules: np.ndarray, next_majors: np.ndarray) -> np.ndarray:
    """
    Read ultra capsules' distances.

    :param capsules: shape (n, 132), uint8
    :param next_majors: each capsule's successor's first scaled major, shape (n,); negative
        where unknown
    :return: distances, shape (n, 96), whole mm; 0 = no return, -1 = unreadable (depends on an
        unknown successor, or decodes negative)
    """
    count = len(capsules)
    combined = np.ascontiguousarray(capsules[:, 4:]).view('<u4').astype(np.int64)
    scaled = combined & 0xFFF
    following = np.concatenate([scaled[:, 1:], np.maximum(next_majors, 0)[:, None]], axis=1)
    known = np.ones((count, _CABINS), bool)
    known[:, -1] = np.asarray(next_majors) >= 0
    major, level = varbitscale_decode(scaled)
    major_after, level_after = varbitscale_decode(following)
    borrow = (major == 0) & (major_after != 0)
    first_base = np.where(borrow, major_after, major)
    first_level = np.where(borrow, level_after, level)
    first_known = known | (major != 0)
    predictions = (_signed10(combined >> 12), _signed10(combined >> 22))
    samples = [major]
    for prediction, base, shift, readable in ((predictions[0], first_base, first_level,
                                               first_known),
                                              (predictions[1], major_after, level_after, known)):
        silent = np.isin(prediction, _NO_RETURN)
        value = base + prediction * (1 << shift)
        samples.append(np.where(silent, 0, np.where(readable & (value >= 0), value, -1)))
    return np.stack(samples, axis=-1).reshape(count, ULTRA_SAMPLES_PER_CAPSULE)


def encode_ultra_capsules(start_q6: np.ndarray, distance_mm: np.ndarray, start_flag: np.ndarray,
                          next_distance_mm: float) -> tuple:
    """
    Encode 132-byte ultra capsules (answer type 0x84) with their checksums.

    The device sends a distance as near as its scale allows; a prediction it cannot send (too
    far from its base) is sent as no return.

    :param start_q6: start angle of each capsule, 1/64 degree, 0-23039
    :param distance_mm: distances, shape (n, 96), whole mm, 0 = no return
    :param start_flag: S flag of each capsule (set on the first capsule after the start command)
    :param next_distance_mm: the first distance of the capsule after the last
    :return: ``(data, sent_mm)``: the capsule bytes and the distances they carry, (n, 96)
    """
    flags = np.asarray(start_flag, np.int64) << 15
    count = len(flags)
    cabins = np.asarray(distance_mm, np.int64).reshape(count, _CABINS, 3)
    majors = np.concatenate([cabins[:, :, 0].reshape(-1), [int(next_distance_mm)]])
    scaled = varbitscale_encode(majors)
    major, level = varbitscale_decode(scaled)
    major_after, level_after = major[1:].reshape(count, _CABINS), level[1:].reshape(count,
                                                                                    _CABINS)
    major, level = major[:-1].reshape(count, _CABINS), level[:-1].reshape(count, _CABINS)
    borrow = (major == 0) & (major_after != 0)
    fields, sent = [], [major]
    for distance, base, shift in ((cabins[:, :, 1], np.where(borrow, major_after, major),
                                   np.where(borrow, level_after, level)),
                                  (cabins[:, :, 2], major_after, level_after)):
        step = 1 << shift
        prediction = np.floor_divide(distance - base + step // 2, step)
        silent = (distance == 0) | (prediction < -0x1FF) | (prediction > 0x1FE)
        fields.append(np.where(silent, 0x1FF, prediction) & 0x3FF)
        sent.append(np.where(silent, 0, base + prediction * step))
    combined = scaled[:-1].reshape(count, _CABINS) | (fields[0] << 12) | (fields[1] << 22)
    raw = np.zeros((count, ULTRA_CAPSULE_SIZE), np.uint8)
    raw[:, 2:4] = (np.asarray(start_q6, np.int64) | flags).astype('<u2').view(np.uint8).reshape(
        count, 2)
    raw[:, 4:] = combined.astype('<u4').view(np.uint8).reshape(count, 4 * _CABINS)
    return with_checksum(raw), np.stack(sent, axis=-1).reshape(count, ULTRA_SAMPLES_PER_CAPSULE)


class UltraLayout(CapsuleLayout):
    """The ultra capsule's cabins."""

    size = ULTRA_CAPSULE_SIZE
    samples = ULTRA_SAMPLES_PER_CAPSULE
    reads_successor = True

    def read(self, capsules: np.ndarray, successors: np.ndarray) -> tuple:
        """Return the distances (mm) and angle offsets (degrees) of intact capsules."""
        # A row of zeros is no capsule (it would carry the sync nibbles).
        next_majors = np.where(successors[:, 0] != 0,
                               successors[:, 4].astype(np.int64)
                               | (successors[:, 5].astype(np.int64) & 0xF) << 8, -1)
        distances = decode_ultra_capsules(capsules, next_majors)
        return distances, offset_deg(np.maximum(distances, 0))

    def flip_deltas(self, capsules: np.ndarray, distance_mm: np.ndarray,
                    next_scaled: Optional[np.ndarray] = None) -> tuple:
        """
        Return each predicted sample's change by a flip of one bit of its prediction, and which.

        A major's bits move three samples together, which no lone spike shows: they are left
        out, as is the last cabin's third sample (its base is the next capsule's major) where
        that major is not known.

        :param next_scaled: each capsule's successor's first scaled major, shape (n,); negative
            where unknown (None: unknown for all)
        """
        count = len(capsules)
        combined = np.ascontiguousarray(capsules[:, 4:]).view('<u4').astype(np.int64)
        scaled = combined & 0xFFF
        major, level = varbitscale_decode(scaled)
        known = np.zeros(count, bool) if next_scaled is None else np.asarray(next_scaled) >= 0
        next_major, next_level = varbitscale_decode(np.where(known, next_scaled, 0)
                                                    if next_scaled is not None
                                                    else np.zeros(count, np.int64))
        level_after = np.concatenate([level[:, 1:], next_level[:, None]], axis=1)
        major_after = np.concatenate([major[:, 1:], next_major[:, None]], axis=1)
        first_level = np.where((major == 0) & (major_after != 0), level_after, level)
        i = np.arange(10)
        deltas = np.zeros((count, _CABINS, 3, 10))
        bits = np.full((count, _CABINS, 3, 10), -1, np.int64)
        cabin_at = 4 + 4 * np.arange(_CABINS)[:, None]
        for k, (first_bit, shift) in ((1, (12, first_level)), (2, (22, level_after))):
            raw = (combined[..., None] >> first_bit) & 0x3FF
            before, after = _signed10(raw), _signed10(raw ^ (1 << i))
            sendable = ~np.isin(before, _NO_RETURN) & ~np.isin(after, _NO_RETURN)
            deltas[:, :, k] = np.where(sendable, (after - before) << shift[..., None], 0)
            bits[:, :, k] = np.where(sendable, (cabin_at + (first_bit + i) // 8) * 8
                                     + (first_bit + i) % 8, -1)
        bits[~known, -1, 2] = -1
        return (deltas.reshape(count, ULTRA_SAMPLES_PER_CAPSULE, 10),
                bits.reshape(count, ULTRA_SAMPLES_PER_CAPSULE, 10))

    def unseen_flips(self, capsules: np.ndarray, distance_mm: np.ndarray, usable: np.ndarray,
                     sigma_mm: float, step_rad: float, slots: np.ndarray) -> tuple:
        """
        Tell which intact capsules show bits flipped that their checksum cannot see, and where.

        In the predictions' bits as every layout's; in the majors' among the majors alone,
        three samples apart (a flipped major moves its three samples together: the sample
        before, predicted from it, its own and the next).
        """
        combined = np.ascontiguousarray(capsules[:, 4:]).view('<u4').astype(np.int64)
        scaled = combined & 0xFFF
        major, _ = varbitscale_decode(scaled)
        j = np.arange(12)
        flipped, _ = varbitscale_decode(scaled[..., None] ^ (1 << j))
        bits = (4 + 4 * np.arange(_CABINS)[:, None] + j // 8) * 8 + j % 8
        following = np.r_[np.asarray(slots)[1:] == np.asarray(slots)[:-1] + 1, False]
        flips = self.flip_deltas(capsules, distance_mm,
                                 np.where(following, np.r_[scaled[1:, 0], 0], -1))
        found = []
        for between in (True, False):
            found.append((
                flip_repairs(major.astype(np.float64), usable[:, 0::3],
                             (flipped - major[..., None]).astype(np.float64),
                             np.broadcast_to(bits, flipped.shape), sigma_mm, 3.0 * step_rad,
                             slots, spacing=3, between=between),
                flip_repairs(distance_mm, usable, *flips, sigma_mm, step_rad, slots,
                             between=between)))
        (majors, predictions), (major_spikes, prediction_spikes) = found
        # A run: the samples read from the major beside it moved with it (nearer it than the
        # flip's change); a far major of clutter has its predicted neighbours near the scene.
        capsule, sample, bit = major_spikes
        change = np.abs(flipped - major[..., None])[capsule, sample // 3,
                                                    bit - (4 + 4 * (sample // 3)) * 8]
        run = np.ones(capsule.size, bool)
        for offset in (-1, 1):
            at = np.clip(sample + offset, 0, ULTRA_SAMPLES_PER_CAPSULE - 1)
            run &= (np.abs(distance_mm[capsule, at] - distance_mm[capsule, sample])
                    < 0.5 * change)
        return (unseen_flips(len(capsules), majors, predictions),
                np.maximum.reduce([
                    SPIKE_RUN * repaired_samples(slots, ULTRA_SAMPLES_PER_CAPSULE,
                                                 tuple(c[run] for c in major_spikes),
                                                 (-1, 0, 1)),
                    SPIKE * repaired_samples(slots, ULTRA_SAMPLES_PER_CAPSULE,
                                             tuple(c[~run] for c in major_spikes), (-1, 0, 1)),
                    SPIKE * repaired_samples(slots, ULTRA_SAMPLES_PER_CAPSULE,
                                             prediction_spikes)]))

    def plausible(self, distance_mm: np.ndarray, correction_deg: np.ndarray,
                  usable: np.ndarray, sigma_mm: float, step_rad: float) -> np.ndarray:
        """
        Tell which samples of capsules that failed their checksum to believe.

        A cabin's major is in three samples (its own, the next one predicted from it, and the
        one before, predicted from the major after its own), so a damaged major moves them
        together and they agree with each other. So a major is checked, as a dense capsule's
        sample, against the nearest samples that do not read its bytes (interpolated from the
        ones two samples either side, or extrapolated from the two beyond on either side), and
        a predicted sample only against believed majors: interpolated from the two around it,
        at a third or two thirds of the way, or extrapolated from two on either side. The last
        cabin's third sample follows the next capsule's major: not believed. The angle offset
        is the distance's, right when the distance is.
        """
        majors = distance_mm[:, 0::3]
        # A major's nearest samples whose bytes are not its own: 3c - 2 (the cabin before's
        # major and first prediction) and 3c + 2 (the next major and this cabin's second
        # prediction), and beyond them 3c - 3 and 3c + 3.
        evidence = np.pad(np.where(usable & (distance_mm > 0), distance_mm, np.nan),
                          ((0, 0), (3, 3)), constant_values=np.nan)
        at = 3 * np.arange(majors.shape[1]) + 3

        def near(offset):
            return evidence[:, at + offset]

        # The noise of the sample and of a prediction between the pair (as the dense check's
        # midpoint) or beyond it.
        noise_mid = _SIGMAS * np.sqrt(1.5) * sigma_mm
        noise_end = _SIGMAS * np.sqrt(6.0) * sigma_mm
        with np.errstate(invalid='ignore'):
            believed = (majors > 0) & (
                _fits(majors, near(-2), near(2), 0.5, 4, noise_mid, step_rad)
                | _fits(majors, near(-3), near(-2), 3.0, 1, noise_end, step_rad)
                | _fits(majors, near(3), near(2), 3.0, 1, noise_end, step_rad))

        def shifted(values, cabins):
            # Cabin c + cabins's values at cabin c (zeros beyond the capsule).
            out = np.zeros_like(values)
            if cabins > 0:
                out[:, :-cabins] = values[:, cabins:]
            else:
                out[:, -cabins:] = values[:, :cabins]
            return out

        plausible = np.zeros(distance_mm.shape, bool)
        plausible[:, 0::3] = believed
        here, after = majors, shifted(majors, 1)
        before, later = shifted(majors, -1), shifted(majors, 2)
        ok_here, ok_after = believed, shifted(believed, 1)
        ok_before, ok_later = shifted(believed, -1), shifted(believed, 2)
        for k in (1, 2):
            sample = distance_mm[:, k::3]
            plausible[:, k::3] = (
                (ok_here & ok_after & _fits(sample, here, after, k / 3.0, 3, noise_mid,
                                            step_rad))
                | (ok_before & ok_here & _fits(sample, before, here, 1.0 + k / 3.0, 3,
                                               noise_end, step_rad))
                | (ok_after & ok_later & _fits(sample, after, later, k / 3.0 - 1.0, 3,
                                               noise_end, step_rad)))
        return plausible & usable


def _fits(sample: np.ndarray, first: np.ndarray, second: np.ndarray, fraction: float,
          spacing: int, noise: float, step_rad: float) -> np.ndarray:
    """
    Tell whether samples lie on the straight surfaces through pairs, as the dense check asks.

    A pair that climbs faster than a surface seen at 80 degrees incidence predicts nothing; the
    tolerance is the noise plus the bend of a straight surface in polar coordinates over the
    samples spanned.

    :param sample: the distances checked, mm
    :param first: the pairs' first distances, mm (NaN: no pair)
    :param second: their second distances, ``spacing`` samples on, mm (NaN: no pair)
    :param fraction: where the sample lies, in spacings from the first (beyond 1: ahead)
    :param spacing: samples between the pair's two
    :param noise: the noise allowed, mm
    :param step_rad: angle between samples, rad
    :return: bool, shape of ``sample``
    """
    predicted = first + fraction * (second - first)
    centre = np.maximum(0.5 * (first + second), 1.0)
    span = max(abs(fraction), abs(fraction - 1.0))
    rise = (second - first) / spacing
    bend = span * spacing ** 2 * (centre * step_rad ** 2 + 2.0 * rise ** 2 / centre)
    steep = np.abs(rise) > _STEEPEST * step_rad * centre + noise
    return ~steep & (np.abs(sample - predicted) <= noise + bend)


class UltraCapsuleDecoder(CheckedCapsuleDecoder):
    """
    Incremental decoder of ultra capsules that resynchronises capsule by capsule.

    :param us_per_sample: the scan mode's microseconds per sample (sets the sweep limit)
    :param max_distance_m: the mode's farthest range; distances beyond are rejected
    """

    FRAME_SIZE = ULTRA_CAPSULE_SIZE
    SAMPLES_PER_FRAME = ULTRA_SAMPLES_PER_CAPSULE

    def __init__(self, us_per_sample: float, max_distance_m: float = 25.0):
        super().__init__(UltraLayout(), us_per_sample, max_distance_m)
