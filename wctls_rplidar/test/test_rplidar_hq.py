# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""HQ capsules (0x83): the SDK's samples and CRC, lost bytes, the driver end to end."""

from dataclasses import replace
import math
import struct
import zlib

import numpy as np
import pytest
from rplidar_testing import emulated_stream, LogLines, serving, true_ranges, wait_for
from test_rplidar_protocol import damaged, feed_in_chunks
from wctls_rplidar.driver import DriverConfig, RplidarDriver
from wctls_rplidar.emulator.device import EMULATED_MODELS
from wctls_rplidar.hq import encode_hq_capsules, HQ_CAPSULE_SIZE, HqCapsuleDecoder
from wctls_rplidar.protocol import AnswerType, Samples, ScanMode

# An S2 with an HQ mode beside its own (no emulated model lists one: which units stream 0x83
# no document names), at 8 kHz: 8 bytes a sample, 640 kbit/s on its 1 Mbaud line.
HQ = ScanMode(2, 'HQ', 125.0, 25.0, AnswerType.HQ_CAPSULE)
MODEL = replace(EMULATED_MODELS['s2'], modes=EMULATED_MODELS['s2'].modes + (HQ,),
                typical_mode=2)


def sdk_hq_reference(data):
    """Port of the SDK's UnpackerHandler_HQNode::onData: (angle deg, mm, quality, flag)."""
    out, buffer = [], bytearray()
    for byte in data:
        if not buffer and byte != 0xA5:
            continue
        buffer.append(byte)
        if len(buffer) < HQ_CAPSULE_SIZE:
            continue
        body, received = bytes(buffer[:-4]), struct.unpack('<I', buffer[-4:])[0]
        buffer = bytearray()
        # boost::crc_optimal<32, 0x04C11DB7, ~0, ~0, true, true> over the body padded with
        # zeros to a multiple of 4 (4 - size % 4 of them).
        if zlib.crc32(body + b'\0' * (4 - len(body) % 4)) != received:
            continue
        for k in range(96):
            angle, distance, quality, flag = struct.unpack_from('<HIBB', body, 9 + 8 * k)
            out.append((angle * 90 / 16384, distance / 4, quality, flag))
    return out


def decode(data, rng):
    """Decode a stream in random chunks; return the samples and the counts."""
    decoder = HqCapsuleDecoder(125.0, 25.0)
    return Samples.concat(feed_in_chunks(decoder, data, rng)), decoder.counts


def hq_stream(seconds=1.0, seed=0):
    """Return what the emulated device streams in its HQ mode (after the descriptor)."""
    return emulated_stream(MODEL.modes, 2, seconds=seconds, seed=seed)


def test_capsules_laid_out_by_hand_decode_to_their_samples():
    angles = np.arange(192).reshape(2, 96) * 0.5
    distances = np.arange(192).reshape(2, 96) * 10.25
    start = np.zeros((2, 96), bool)
    start[1, 10] = True
    data = encode_hq_capsules(angles, distances, np.full((2, 96), 188), start, [5, 6])
    assert len(data) == 2 * 781 and data[0] == 0xA5
    samples, counts = decode(data, np.random.default_rng(0))
    assert counts.frames == 2 and counts.damaged_frames == 0
    np.testing.assert_allclose(samples.angle_deg, angles.reshape(-1), atol=90 / 16384 / 2)
    np.testing.assert_array_equal(samples.distance_mm, distances.reshape(-1))
    assert np.flatnonzero(samples.start).tolist() == [106] and (samples.quality == 47).all()
    assert samples.device_time_us.tolist() == [5] * 96 + [6] * 96


@pytest.mark.parametrize('seed', [0, 1])
def test_an_emulated_stream_decodes_as_the_sdk_does_sample_for_sample(seed):
    data = hq_stream(seed=seed)
    samples, counts = decode(data, np.random.default_rng(seed))
    reference = np.array(sdk_hq_reference(data))
    assert counts.damaged_frames == 0 and len(samples) == len(reference) > 7000
    np.testing.assert_array_equal(samples.angle_deg, reference[:, 0])
    np.testing.assert_array_equal(samples.distance_mm, reference[:, 1])
    np.testing.assert_array_equal(samples.start, reference[:, 3].astype(int) & 1 == 1)
    truth = 1000.0 * true_ranges(math.pi - np.radians(samples.angle_deg))
    returns = samples.distance_mm > 0
    assert np.abs(samples.distance_mm[returns] - truth[returns]).max() < 1.0


def test_lost_and_corrupted_bytes_cost_only_their_capsules_and_give_no_wrong_sample():
    data = damaged(hq_stream(seed=2), np.random.default_rng(3), corrupt=2e-5, drop=2e-5)
    samples, counts = decode(data, np.random.default_rng(4))
    sdk = sdk_hq_reference(data)
    assert counts.damaged_frames > 0 and len(samples) >= len(sdk)
    truth = 1000.0 * true_ranges(math.pi - np.radians(samples.angle_deg))
    returns = samples.distance_mm > 0
    assert np.abs(samples.distance_mm[returns] - truth[returns]).max() < 1.0


def test_the_driver_scans_an_hq_mode_end_to_end_with_device_times():
    turns = []
    with serving(MODEL, baudrate=MODEL.baudrate) as path:
        driver = RplidarDriver(DriverConfig(serial_port=path), lambda t, m: turns.append(t),
                               LogLines())
        driver.start()
        try:
            wait_for(lambda: len(turns) >= 3, what='3 HQ turns')
        finally:
            driver.close()
    assert driver.status().mode.answer_type == AnswerType.HQ_CAPSULE
    for turn in turns[1:3]:
        assert len(turn.distance_mm) == pytest.approx(800, abs=2)      # 10 Hz at 8 kHz
        returns = turn.distance_mm > 0
        truth = 1000.0 * true_ranges(math.pi - np.radians(turn.angle_deg[returns]))
        assert np.median(np.abs(turn.distance_mm[returns] - truth)) < 1.0
        assert turn.device_time_us is not None
