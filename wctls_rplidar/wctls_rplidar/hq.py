# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
HQ capsules (answer type 0x83): 96 finished samples, a device timestamp and a CRC (pure, no I/O).

The layout, as SLAMTEC's SDK reads it (sl_lidar_cmd.h, handler_hqnode.cpp), little-endian:

- byte 0: sync byte 0xA5; bytes 1-8: u64 timestamp on the device's clock;
- 96 nodes of 8 bytes: u16 angle (z, 90/16384 degree), u32 distance (1/4 mm, 0 = no return),
  u8 quality, u8 flag (bit 0: first sample of a turn, bit 1 its inverse);
- u32 CRC-32 (the zlib polynomial, reflected, initial and final XOR 0xFFFFFFFF) of the 777
  bytes before it padded with zeros to 780, as the SDK computes it.

The SDK skips bytes until a sync byte, takes the next 780 bytes as a capsule and drops it
whole when the CRC fails, searching again only after it. :class:`HqCapsuleDecoder` publishes
the same samples from an intact stream. A capsule whose CRC fails is read node by node when it
lies in sequence (see the class); otherwise it searches from the byte after the sync, so a
capsule that lost bytes costs only itself and not the one after it too.
"""

import math
import zlib

import numpy as np

from .capsules import RangeNoise, supported_by_neighbours
from .checked import SteadyDeviceTimes
from .framing import LinkDamage, WITHHELD_BYTE_DAMAGE
from .protocol import Samples, StreamCounts

HQ_SYNC = 0xA5
HQ_SAMPLES_PER_CAPSULE = 96
_NODE_DTYPE = np.dtype([('angle_z_q14', '<u2'), ('distance_q2', '<u4'), ('quality', 'u1'),
                        ('flag', 'u1')])
_CAPSULE_DTYPE = np.dtype([('sync', 'u1'), ('time_us', '<u8'),
                           ('nodes', _NODE_DTYPE, (HQ_SAMPLES_PER_CAPSULE,)), ('crc', '<u4')])
HQ_CAPSULE_SIZE = _CAPSULE_DTYPE.itemsize
_CRC_PADDING = b'\0' * (4 - (HQ_CAPSULE_SIZE - 4) % 4)
# The flags a node may carry: bit 0 the start of a turn, bit 1 its inverse.
_NODE_FLAGS = (1, 2)
# A damaged capsule's node angle may differ from its neighbours' step by this share of a step.
_ANGLE_STEP_SHARE = 0.25
# Capsules the share of corrupted bytes is measured over (a running mean up to it).
_DAMAGE_MEMORY = 32


def hq_crc(body: bytes) -> int:
    """
    Return the CRC of a capsule's bytes before its CRC field, as the SDK computes it.

    :param body: the first 777 bytes
    :return: the u32 CRC
    """
    return zlib.crc32(bytes(body) + _CRC_PADDING)


def encode_hq_capsules(angle_deg: np.ndarray, distance_mm: np.ndarray, quality: np.ndarray,
                       start: np.ndarray, time_us: np.ndarray) -> bytes:
    """
    Encode HQ capsules (answer type 0x83) with their CRCs.

    :param angle_deg: raw angles, shape (n, 96), degrees in [0, 360)
    :param distance_mm: distances, shape (n, 96), mm, 0 = no return
    :param quality: qualities, shape (n, 96), 0-255
    :param start: True at the first sample of each turn, shape (n, 96)
    :param time_us: each capsule's timestamp on the device's clock, microseconds
    :return: the capsule bytes
    """
    start = np.asarray(start, np.uint8)
    capsules = np.zeros(len(start), _CAPSULE_DTYPE)
    capsules['sync'] = HQ_SYNC
    capsules['time_us'] = np.asarray(time_us, np.int64)
    nodes = capsules['nodes']
    nodes['angle_z_q14'] = np.rint(np.asarray(angle_deg) * 16384.0 / 90.0).astype(np.int64) % 65536
    nodes['distance_q2'] = np.rint(np.asarray(distance_mm) * 4.0)
    nodes['quality'] = quality
    nodes['flag'] = start | ((start ^ 1) << 1)
    raw = capsules.view(np.uint8).reshape(len(start), HQ_CAPSULE_SIZE)
    capsules['crc'] = [hq_crc(row[:-4].tobytes()) for row in raw]
    return capsules.tobytes()


class HqCapsuleDecoder:
    """
    Incremental decoder of HQ capsules, checked by their CRC or, where it fails, their structure.

    At 5 % corrupted bytes almost no capsule of 781 bytes passes its CRC. A capsule that fails
    it is still read when it lies in sequence, 781 bytes after the one before and the sync byte
    of the next (or of the one after, if the next one's was hit) 781 bytes on: a line loses
    bytes, it does not add them, so its nodes are where they belong. Each node is then judged
    by itself and its neighbours, whose bytes are their own: its angle must lie the capsule's
    median step from both neighbours' (within a quarter step: a damaged angle byte is a jump,
    and packets delivered out of order move runs of nodes) and its distance must be predicted
    by a neighbour pair as in dense capsules (its bits above the mode's range, always clear, are
    cleared first: they can only carry damage); its start flag counts only when the flag byte
    is one of the two the device sends. Other nodes are published as no return, at the angle
    their believed neighbours put them at. The top byte of every distance is clear (40 m is
    below 2^18 quarter millimetres): the share of those set measures the share of bytes
    corrupted, and from :data:`~wctls_rplidar.framing.WITHHELD_BYTE_DAMAGE` on no node of a
    damaged capsule is published (there neighbour pairs vouch for wrong distances). Its
    timestamp is believed when it continues the step of the two capsules before it
    (:class:`~wctls_rplidar.checked.SteadyDeviceTimes`).

    :param us_per_sample: the scan mode's microseconds per sample (unused: the samples carry
        their angles)
    :param max_distance_m: the mode's farthest range; distances beyond are published as no
        return
    """

    FRAME_SIZE = HQ_CAPSULE_SIZE
    SAMPLES_PER_FRAME = HQ_SAMPLES_PER_CAPSULE

    def __init__(self, us_per_sample: float, max_distance_m: float = 40.0):
        self._max_q2 = int(max_distance_m * 4000.0)
        self._pending = b''
        self._offset = 0            # stream offset of _pending[0]
        self._synced = False        # _pending[0] is where the next capsule begins
        self._noise = RangeNoise(HQ_SAMPLES_PER_CAPSULE)
        self._device_times = SteadyDeviceTimes(clock_bits=64)
        self._counts = dict.fromkeys(StreamCounts.__dataclass_fields__, 0)
        self._corrupted = 0.0       # share of the distances' top bytes set
        self._capsules = 0
        self._withheld = False

    @property
    def counts(self) -> StreamCounts:
        """Return what the decoder has met so far."""
        return StreamCounts(**self._counts)

    @property
    def damage(self) -> LinkDamage:
        """
        Return the share of bytes corrupted and whether the last damaged nodes were withheld.

        A corrupted byte is one of the 255 other values: a top byte set, the share measured, is
        255/256 of a share corrupted.
        """
        return LinkDamage(self._corrupted * 256.0 / 255.0, self._withheld)

    def feed(self, data: bytes) -> Samples:
        """
        Decode what the next received chunk completes.

        A capsule that passes its CRC is decoded at once; one that fails it once the sync
        bytes of the two after it could have arrived.

        :param data: the next received bytes, any length
        :return: the samples decoded, in stream order
        """
        buffer = self._pending + bytes(data)
        taken, pos = [], 0
        while True:
            at = pos if self._synced else buffer.find(HQ_SYNC, pos)
            if at < 0:
                self._counts['discarded_bytes'] += len(buffer) - pos
                pos = len(buffer)
                break
            if at + HQ_CAPSULE_SIZE > len(buffer):
                break
            capsule = buffer[at:at + HQ_CAPSULE_SIZE]
            clean = hq_crc(capsule[:-4]) == int.from_bytes(capsule[-4:], 'little')
            if not clean and at + 2 * HQ_CAPSULE_SIZE + 1 > len(buffer):
                break
            if clean or self._in_sequence(buffer, at):
                self._counts['discarded_bytes'] += at - pos
                self._counts['damaged_frames'] += not clean
                taken.append((at, clean, self._synced))
                self._synced = True
                pos = at + HQ_CAPSULE_SIZE
                continue
            if self._synced:
                self._counts['damaged_frames'] += 1
                self._counts['resyncs'] += 1
                self._counts['lost_frames'] += 1
            self._synced = False
            self._counts['discarded_bytes'] += at + 1 - pos
            pos = at + 1
        samples = self._samples(buffer, taken)
        self._pending = buffer[pos:]
        self._offset += pos
        return samples

    def _in_sequence(self, buffer: bytes, at: int) -> bool:
        """Tell whether a capsule that failed its CRC lies in sequence (see the class)."""
        following = (buffer[at + HQ_CAPSULE_SIZE] == HQ_SYNC,
                     buffer[at + 2 * HQ_CAPSULE_SIZE] == HQ_SYNC)
        if self._synced:
            return any(following)
        # Without a capsule before it, its own sync byte and both after it are the evidence.
        return buffer[at] == HQ_SYNC and all(following)

    def _samples(self, buffer: bytes, taken: list) -> Samples:
        """Lay out the samples of the capsules taken: ``(start, clean, after the one before)``."""
        if not taken:
            return Samples.concat([])
        raw = np.frombuffer(buffer, np.uint8)
        starts = np.array([at for at, _, _ in taken])
        clean = np.array([ok for _, ok, _ in taken])
        capsules = raw[starts[:, None] + np.arange(HQ_CAPSULE_SIZE)]
        capsules = np.ascontiguousarray(capsules).view(_CAPSULE_DTYPE)[:, 0]
        nodes = capsules['nodes']
        count = len(taken)
        distance_q2 = nodes['distance_q2'].astype(np.int64)
        angle_deg = nodes['angle_z_q14'] * 90.0 / 16384.0
        start = (nodes['flag'] & 1).astype(bool)
        self._capsules += count
        self._corrupted += (np.mean(distance_q2 >> 24 != 0) - self._corrupted) * min(
            count / min(self._capsules, _DAMAGE_MEMORY), 1.0)
        # The distance's bits above the mode's range are always clear: in a damaged capsule
        # they carry no information, only damage, and are cleared.
        distance_q2[~clean] &= (1 << self._max_q2.bit_length()) - 1
        in_range = distance_q2 <= self._max_q2
        self._noise.update(np.where(in_range, distance_q2 / 4.0, 0.0))
        keep = in_range.copy()
        published = np.ones(count, bool)
        self._withheld = False
        if not clean.all():
            damaged = ~clean
            believed_angle, step_deg = _continues_steps(angle_deg[damaged])
            # A neighbour's distance bytes are its own: they predict whatever its angle's are.
            keep[damaged] = believed_angle & in_range[damaged] & (
                (distance_q2[damaged] == 0) | supported_by_neighbours(
                    distance_q2[damaged] / 4.0, in_range[damaged], self._noise.sigma_mm,
                    math.radians(step_deg)))
            angle_deg[damaged] = _fill_angles(angle_deg[damaged], believed_angle)
            self._withheld = self._corrupted >= WITHHELD_BYTE_DAMAGE
            if self._withheld:
                keep[damaged] &= distance_q2[damaged] == 0
            # A damaged flag byte spoils only the start flag, not the node.
            start[damaged] &= believed_angle & np.isin(nodes['flag'][damaged], _NODE_FLAGS)
            # A capsule without a believed angle cannot be placed: it is lost.
            published[damaged] = believed_angle.any(axis=1)
        ends = self._offset + starts.astype(np.int64) + HQ_CAPSULE_SIZE
        # Capsules in sequence lie a capsule apart: their slots are consecutive.
        times = self._device_times.believe(ends // HQ_CAPSULE_SIZE - 1, capsules['time_us'],
                                           np.ones(count, bool), clean)
        self._counts['frames'] += count
        self._counts['lost_frames'] += int(np.count_nonzero(~published))
        count = int(np.count_nonzero(published))
        angle_deg, distance_q2, keep, start, nodes, times, ends = (
            column[published] for column in (angle_deg, distance_q2, keep, start, nodes, times,
                                             ends))
        self._counts['samples'] += keep.size
        self._counts['rejected_samples'] += int(np.count_nonzero(~keep))
        k = np.tile(np.arange(HQ_SAMPLES_PER_CAPSULE), count)
        return Samples(angle_deg=angle_deg.reshape(-1),
                       distance_mm=np.where(keep, distance_q2, 0).reshape(-1) / 4.0,
                       quality=np.where(keep, nodes['quality'] >> 2, 0).reshape(-1).astype(
                           np.uint8),
                       start=start.reshape(-1),
                       frame_end=np.repeat(ends, HQ_SAMPLES_PER_CAPSULE),
                       samples_after=HQ_SAMPLES_PER_CAPSULE - 1 - k,
                       slot=np.repeat(ends // HQ_CAPSULE_SIZE - 1, HQ_SAMPLES_PER_CAPSULE)
                       * HQ_SAMPLES_PER_CAPSULE + k,
                       device_time_us=np.repeat(times, HQ_SAMPLES_PER_CAPSULE))


def _continues_steps(angle_deg: np.ndarray) -> np.ndarray:
    """
    Tell which nodes' angles continue their neighbours' steps, capsule by capsule.

    A node's angle is believed when it lies the capsule's median step after its predecessor's
    and before its successor's, within a quarter of that step: a damaged angle byte moves a
    node's angle alone, and a node of packets delivered out of order (or twice) starts or ends a
    run of nodes that lies elsewhere, or repeats its neighbour's angle (a step of nothing). A
    capsule's first and last nodes, with one neighbour in it, are not believed.

    :param angle_deg: shape (capsules, 96), degrees
    :return: ``(believed, step_deg)``: shape (capsules, 96), bool, and the median step of all,
        degrees
    """
    steps = (np.diff(angle_deg, axis=1) + 180.0) % 360.0 - 180.0
    step = np.median(steps, axis=1, keepdims=True)
    tolerance = np.abs(step) * _ANGLE_STEP_SHARE
    regular = (np.abs(steps - step) <= tolerance) & (step > 0)
    believed = np.zeros(angle_deg.shape, bool)
    believed[:, 1:-1] = regular[:, :-1] & regular[:, 1:]
    return believed, float(np.abs(np.median(step)))


def _fill_angles(angle_deg: np.ndarray, believed: np.ndarray) -> np.ndarray:
    """
    Replace the angles not believed by their believed neighbours' interpolation, per capsule.

    :param angle_deg: shape (capsules, 96), degrees
    :param believed: which to keep
    :return: the angles, degrees in [0, 360) (a capsule with none believed unchanged; the
        nodes beyond the first or last believed one at its angle)
    """
    filled = angle_deg.copy()
    k = np.arange(angle_deg.shape[1])
    for row, ok in zip(filled, believed):
        if ok.any() and not ok.all():
            unwrapped = np.degrees(np.unwrap(np.radians(row[ok])))
            row[:] = np.interp(k, k[ok], unwrapped) % 360.0
    return filled
