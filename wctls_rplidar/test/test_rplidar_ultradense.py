# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Ultra-dense capsules (0x86): the SDK's samples, the device timestamp, the driver end to end."""

from dataclasses import replace
import math
import struct

import numpy as np
import pytest
from rplidar_testing import (emulated_stream, LogLines, sdk_framed_capsules, serving,
                             true_ranges, wait_for)
from test_rplidar_protocol import damaged, feed_in_chunks
from wctls_rplidar.driver import DriverConfig, RplidarDriver
from wctls_rplidar.emulator.device import EMULATED_MODELS, Faults
from wctls_rplidar.protocol import AnswerType, Samples, ScanMode
from wctls_rplidar.ultradense import (encode_ultra_dense_capsules,
                                      ULTRA_DENSE_CAPSULE_SIZE, UltraDenseCapsuleDecoder)

US_PER_SAMPLE = 31.25
# An S-series device with an ultra-dense mode beside its own (the emulator's models list none:
# which units stream 0x86 no document names).
ULTRA_DENSE = ScanMode(2, 'UltraDense', US_PER_SAMPLE, 40.0, AnswerType.ULTRA_DENSE_CAPSULE)
MODEL = replace(EMULATED_MODELS['s3'], modes=EMULATED_MODELS['s3'].modes + (ULTRA_DENSE,),
                typical_mode=2)


def sdk_ultra_dense_reference(data, us_per_sample=US_PER_SAMPLE):
    """Port of the SDK's UnpackerHandler_UltraDenseCapsuleNode: (angle deg, mm, quality)."""
    out, previous, last_q2 = [], None, 0
    duration_us = int(us_per_sample + 0.5)
    limit_q8 = (360 * 100 * 32 // (1000000 // duration_us)) << 8
    bases = (0, 2046 << 2, 8187 << 2, 24567 << 2)
    for capsule in sdk_framed_capsules(data, ULTRA_DENSE_CAPSULE_SIZE):
        if capsule is None:
            previous = None
            continue
        start_field = struct.unpack_from('<H', capsule, 8)[0]
        if start_field & 0x8000:
            previous = None
        if previous is not None:
            previous_q8 = (previous[0] & 0x7FFF) << 2
            diff = ((start_field & 0x7FFF) << 2) - previous_q8
            diff += (360 << 8) if diff < 0 else 0
            if diff <= limit_q8:
                increment = (diff << 8) // 64
                current = previous_q8 << 8
                for pos in range(64):
                    low, high = previous[1][pos >> 1], previous[2][pos >> 1]
                    field = low[pos & 1] | ((high & 0xF if pos & 1 == 0 else high >> 4) << 16)
                    scale = field & 0x3
                    quality = (field >> (12 + scale)) << scale
                    mask = (0xFFC, 0x1FFC, 0x3FFC, 0x7FFC)[scale]
                    q2 = (field & mask) * (2, 3, 4, 5)[scale] + bases[scale]
                    if scale == 0 and last_q2 and abs(q2 - last_q2) <= 8:
                        q2 = (q2 + last_q2) >> 1
                    last_q2 = q2
                    angle_q6 = (current >> 10) % (360 << 6)
                    current += increment
                    out.append((((angle_q6 << 8) // 90) * 90 / 16384, q2 / 4, quality))
        cabins = [struct.unpack_from('<HHB', capsule, 10 + 5 * c) for c in range(32)]
        previous = (start_field, [c[:2] for c in cabins], [c[2] for c in cabins])
    return out


def decode(data, rng=None, us_per_sample=US_PER_SAMPLE):
    """Decode a stream (in random chunks with a generator); return the samples and counts."""
    decoder = UltraDenseCapsuleDecoder(us_per_sample)
    if rng is None:
        return decoder.feed(data), decoder.counts
    return Samples.concat(feed_in_chunks(decoder, data, rng)), decoder.counts


def ultra_dense_stream(seconds=1.0, seed=0, faults=None):
    """Return what the emulated device streams in its ultra-dense mode (after the descriptor)."""
    return emulated_stream(MODEL.modes, 2, seconds=seconds, seed=seed, faults=faults)


def test_every_scale_encodes_and_decodes_with_the_sdks_smoothing():
    # Each scale's first and last steps; far apart (no smoothing) but for the pair 1000, 1002
    # mm: the SDK averages the second.
    wanted = np.array([100, 2046, 2049, 8187, 8191, 24567, 24572, 30002, 0, 1000, 1002, 5001]
                      + [3000] * 52, float)
    quality = np.full(64, 200)
    data = encode_ultra_dense_capsules(np.array([0, 500]), np.stack([wanted, wanted]),
                                       np.stack([quality, quality]), [True, False], [7, 9])
    samples, counts = decode(data)
    assert counts.damaged_frames == 0 and len(samples) == 64
    expected = wanted.copy()
    expected[10] = 1001.0
    np.testing.assert_array_equal(samples.distance_mm[:12], expected[:12])
    np.testing.assert_allclose(samples.angle_deg, np.arange(64) * 500 / 64 / 64)
    assert set(samples.device_time_us.tolist()) == {7}
    reference = sdk_ultra_dense_reference(data)
    np.testing.assert_array_equal([mm for _, mm, _ in reference], samples.distance_mm)
    # Coarser scales keep the quality's high bits: 200 at 2 mm, 200 >> 1 << 1 at 3 mm, ...
    assert [q for _, _, q in reference][:8] == [200, 200, 200, 200, 200, 200, 200, 200]


@pytest.mark.parametrize('seed', [0, 1])
def test_an_emulated_stream_decodes_as_the_sdk_does_sample_for_sample(seed):
    data = ultra_dense_stream(seconds=1.0, seed=seed)
    samples, counts = decode(data, np.random.default_rng(seed))
    reference = np.array(sdk_ultra_dense_reference(data))
    assert counts.damaged_frames == 0 and counts.rejected_samples == 0
    assert len(samples) == len(reference) > 30000
    np.testing.assert_array_equal(samples.distance_mm, reference[:, 1])
    # The SDK truncates each angle to 1/64 degree, then to 90/16384 degree.
    error = (samples.angle_deg - reference[:, 0] + 180.0) % 360.0 - 180.0
    assert ((error >= 0.0) & (error < 1 / 64 + 90 / 16384)).all()
    truth = 1000.0 * true_ranges(math.pi - np.radians(samples.angle_deg))
    returns = samples.distance_mm > 0
    # Whole steps of 2 to 5 mm, and the SDK's smoothing of 2 mm steps.
    assert np.abs(samples.distance_mm[returns] - truth[returns]).max() <= 3.5


def test_the_device_timestamp_of_every_capsule_is_exposed():
    data = ultra_dense_stream(seconds=0.5)
    samples, _ = decode(data)
    capsule_times = samples.device_time_us[::64]
    # One capsule of 64 samples of 31.25 us every 2000 us of the device's clock.
    np.testing.assert_array_equal(np.diff(capsule_times), 2000)
    assert (samples.device_time_us.reshape(-1, 64) == capsule_times[:, None]).all()


def test_capsules_cut_short_give_no_wrong_sample():
    data = ultra_dense_stream(seconds=1.0, faults=Faults(cut_rate=0.05))
    samples, counts = decode(data, np.random.default_rng(2))
    truth = 1000.0 * true_ranges(math.pi - np.radians(samples.angle_deg))
    returns = samples.distance_mm > 0
    assert counts.damaged_frames > 0 and returns.sum() > 0.85 * 32000 * 0.8
    assert np.abs(samples.distance_mm[returns] - truth[returns]).max() <= 3.5


def test_corrupted_bytes_give_almost_no_wrong_sample():
    data = damaged(ultra_dense_stream(seconds=1.0, seed=3), np.random.default_rng(4),
                   corrupt=0.002, drop=0.001)
    samples, counts = decode(data, np.random.default_rng(5))
    truth = 1000.0 * true_ranges(math.pi - np.radians(samples.angle_deg))
    returns = samples.distance_mm > 0
    error = np.abs(samples.distance_mm[returns] - truth[returns])
    # A damaged capsule keeps the samples its neighbours vouch for: a corrupted low bit may
    # pass (a few mm), a wrong return (10 cm off) almost never.
    assert counts.damaged_frames > 0
    assert np.count_nonzero(error <= 3.5) >= 0.95 * returns.sum()
    assert np.count_nonzero(error > 100.0) <= 0.001 * returns.sum()


def test_the_driver_scans_an_ultra_dense_mode_end_to_end_with_device_times():
    turns, log = [], LogLines()
    with serving(MODEL, baudrate=MODEL.baudrate) as path:
        driver = RplidarDriver(DriverConfig(serial_port=path), lambda t, m: turns.append(t), log)
        driver.start()
        try:
            wait_for(lambda: len(turns) >= 3, what='3 ultra-dense turns')
        finally:
            driver.close()
    assert driver.status().mode.answer_type == AnswerType.ULTRA_DENSE_CAPSULE
    for turn in turns[1:3]:
        # 10 Hz at 32 kHz: 3200 samples a turn.
        assert len(turn.distance_mm) == pytest.approx(3200, abs=64)
        returns = turn.distance_mm > 0
        truth = 1000.0 * true_ranges(math.pi - np.radians(turn.angle_deg[returns]))
        assert np.median(np.abs(turn.distance_mm[returns] - truth)) < 2.0
    # Consecutive turns a period apart on the device's clock.
    periods_us = np.diff([t.device_time_us for t in turns[1:3]])
    assert periods_us == pytest.approx(1e6 * turns[2].period_s, abs=2000 + 64 * 31.25)


# A scene with noise, gaps and far points (as the ultra round trip's) whose far points two at a
# time lie a flipped bit from their neighbours' prediction: once taken for two bits flipped
# where the checksum cannot see, and the batch's clutter rejected (37 samples).
@pytest.mark.parametrize('count, seed', [(6, 94)])
def test_clutter_on_an_intact_link_is_not_taken_for_bits_flipped(count, seed):
    rng = np.random.default_rng(seed)
    starts = (rng.integers(0, 23040) + 461 * np.arange(count)) % 23040
    walk = np.cumsum(rng.normal(0, 250.0, count * 64)) + 25000.0
    distances = np.clip(np.rint(walk), 0, 40000)
    distances[rng.random(distances.size) < 0.1] = 0
    far = rng.random(distances.size) < 0.05
    distances[far] = rng.integers(1, 40000, far.sum())
    distances = distances.reshape(count, 64)
    data = encode_ultra_dense_capsules(starts, distances, np.full((count, 64), 200),
                                       np.arange(count) == 0, 3200 * np.arange(count))
    samples, counts = decode(data, rng)
    # Every sample of all but the last capsule (it waits for its successor) is published.
    assert len(samples) == 64 * (count - 1)
    assert counts.rejected_samples == counts.damaged_frames == counts.lost_frames == 0
    np.testing.assert_array_equal(samples.distance_mm > 0, distances[:-1].ravel() > 0)
