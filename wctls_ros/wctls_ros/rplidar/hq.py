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
the same samples from an intact stream; after a failed CRC it searches from the byte after
the sync, so a capsule that lost bytes costs only itself and not the one after it too.
"""

import zlib

import numpy as np

from .protocol import Samples, StreamCounts

HQ_SYNC = 0xA5
HQ_SAMPLES_PER_CAPSULE = 96
_NODE_DTYPE = np.dtype([('angle_z_q14', '<u2'), ('distance_q2', '<u4'), ('quality', 'u1'),
                        ('flag', 'u1')])
_CAPSULE_DTYPE = np.dtype([('sync', 'u1'), ('time_us', '<u8'),
                           ('nodes', _NODE_DTYPE, (HQ_SAMPLES_PER_CAPSULE,)), ('crc', '<u4')])
HQ_CAPSULE_SIZE = _CAPSULE_DTYPE.itemsize
_CRC_PADDING = b'\0' * (4 - (HQ_CAPSULE_SIZE - 4) % 4)


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
    Incremental decoder of HQ capsules, checked by their CRC.

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
        self._counts = dict.fromkeys(StreamCounts.__dataclass_fields__, 0)

    @property
    def counts(self) -> StreamCounts:
        """Return what the decoder has met so far."""
        return StreamCounts(**self._counts)

    def feed(self, data: bytes) -> Samples:
        """
        Decode what the next received chunk completes.

        :param data: the next received bytes, any length
        :return: the samples decoded, in stream order
        """
        buffer = self._pending + bytes(data)
        good, pos, synced = [], 0, True
        while True:
            at = buffer.find(HQ_SYNC, pos)
            if at < 0:
                self._counts['discarded_bytes'] += len(buffer) - pos
                pos = len(buffer)
                break
            if at + HQ_CAPSULE_SIZE > len(buffer):
                self._counts['discarded_bytes'] += at - pos
                pos = at
                break
            capsule = buffer[at:at + HQ_CAPSULE_SIZE]
            if hq_crc(capsule[:-4]) != int.from_bytes(capsule[-4:], 'little'):
                if synced:
                    self._counts['damaged_frames'] += 1
                    self._counts['resyncs'] += 1
                synced = False
                self._counts['discarded_bytes'] += at + 1 - pos
                pos = at + 1
                continue
            self._counts['discarded_bytes'] += at - pos
            synced = True
            good.append(at)
            pos = at + HQ_CAPSULE_SIZE
        samples = self._samples(buffer, good)
        self._pending = buffer[pos:]
        self._offset += pos
        return samples

    def _samples(self, buffer: bytes, starts: list) -> Samples:
        """Lay out the samples of the intact capsules starting at ``starts``."""
        if not starts:
            return Samples.concat([])
        raw = np.frombuffer(buffer, np.uint8)
        capsules = raw[np.array(starts)[:, None] + np.arange(HQ_CAPSULE_SIZE)]
        capsules = np.ascontiguousarray(capsules).view(_CAPSULE_DTYPE)[:, 0]
        nodes = capsules['nodes'].reshape(-1)
        count = len(starts)
        ends = self._offset + np.array(starts, np.int64) + HQ_CAPSULE_SIZE
        distance_q2 = nodes['distance_q2'].astype(np.int64)
        rejected = distance_q2 > self._max_q2
        self._counts['frames'] += count
        self._counts['samples'] += nodes.size
        self._counts['rejected_samples'] += int(np.count_nonzero(rejected))
        k = np.tile(np.arange(HQ_SAMPLES_PER_CAPSULE), count)
        return Samples(angle_deg=nodes['angle_z_q14'] * 90.0 / 16384.0,
                       distance_mm=np.where(rejected, 0, distance_q2) / 4.0,
                       quality=(nodes['quality'] >> 2).astype(np.uint8),
                       start=(nodes['flag'] & 1).astype(bool),
                       frame_end=np.repeat(ends, HQ_SAMPLES_PER_CAPSULE),
                       samples_after=HQ_SAMPLES_PER_CAPSULE - 1 - k,
                       slot=np.repeat(ends // HQ_CAPSULE_SIZE - 1, HQ_SAMPLES_PER_CAPSULE)
                       * HQ_SAMPLES_PER_CAPSULE + k,
                       device_time_us=np.repeat(capsules['time_us'].astype(np.int64),
                                                HQ_SAMPLES_PER_CAPSULE))
