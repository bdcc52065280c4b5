# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The ultra capsule stream (0x84): the SDK's layout and output, and capsules cut short."""

import json
import math
import struct
import subprocess
import sys

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from rplidar_testing import (emulated_stream, range_band, sdk_framed_capsules, serving,
                             true_ranges)
from test_rplidar_emulator import SDK_CLIENT
from test_rplidar_protocol import feed_in_chunks
from wctls_rplidar.emulator.device import A_SERIES_MODES
from wctls_rplidar.protocol import Samples
from wctls_rplidar.ultra import (encode_ultra_capsules, offset_deg, ULTRA_MAX_DISTANCE_MM,
                                 UltraCapsuleDecoder, varbitscale_decode, varbitscale_encode)

# Runs nodes, emulators or signals against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime

US_PER_SAMPLE = 125.0            # an A2's or A3's Boost mode: 8000 samples per second
STEP_Q6 = round(10 * 23040 * 96 * US_PER_SAMPLE * 1e-6)       # one capsule's sweep at 10 Hz
# Capsule 1 by hand from the SDK's layout, starting at 4 degrees: cabin 0 is 0x017FD3E8, major
# 1000 (0x3E8: 512 + (1000 - 512) * 2 = 1488 mm, level 1), predictions -3 (0x3FD: 1488 - 3 * 2 =
# 1482 mm) and 5 (from cabin 1's major: 5760 + 5 * 8 = 5800 mm); cabin 1 is 0x7FDFF7D0, major
# 2000 (4096 + (2000 - 1792) * 8 = 5760 mm, level 3), both predictions 0x1FF (no return); all
# else 0. XOR of bytes 2-131: 0xC3. Capsule 2 starts at 8 degrees, empty (checksum 0x02), and
# capsule 3's header at 12 degrees frames it.
HAND_CAPSULES = (bytes.fromhex('A3 5C 00 01 E8 D3 7F 01 D0 F7 DF 7F') + bytes(120)
                 + bytes.fromhex('A2 50 00 02') + bytes(128) + bytes.fromhex('A3 50 00 03'))


def sdk_ultra_reference(data):
    """
    Port of the SDK's UnpackerHandler_UltraCapsuleNode (onData, _onScanNodeUltraCapsuleData).

    :return: ``(angle_q6, distance_mm)`` per sample, as the SDK computes them
    """
    def scale(value):
        for first, level, base in ((3328, 4, 1 << 14), (1792, 3, 1 << 12), (1280, 2, 1 << 11),
                                   (512, 1, 1 << 9), (0, 0, 0)):
            if value >= first:
                return base + ((value - first) << level), level

    def signed10(value):
        return value - 1024 if value & 0x200 else value

    out, previous = [], None
    for capsule in sdk_framed_capsules(data, 132):
        if capsule is None:
            previous = None
            continue
        start_field, *cabins = struct.unpack('<H32I', capsule[2:])
        if start_field & 0x8000:
            previous = None
        start_q8 = (start_field & 0x7FFF) << 2
        if previous is not None:
            diff = start_q8 - previous[0] + ((360 << 8) if previous[0] > start_q8 else 0)
            increment_q16, raw_q16 = (diff << 3) // 3, previous[0] << 8
            majors = [c & 0xFFF for c in previous[1]] + [cabins[0] & 0xFFF]
            for pos, combined in enumerate(previous[1]):
                major, level = scale(majors[pos])
                major2, level2 = scale(majors[pos + 1])
                base1, level1 = (major2, level2) if major == 0 and major2 else (major, level)
                distances = [major]
                for prediction, base, shift in ((signed10((combined >> 12) & 0x3FF), base1,
                                                 level1),
                                                (signed10(combined >> 22), major2, level2)):
                    distances.append(0 if prediction in (511, -512)
                                     else base + prediction * (1 << shift))
                for distance in distances:
                    q2 = distance * 4
                    offset = 8578
                    if q2 >= 200:
                        k = 98361 // q2
                        offset = 9150 - (k << 6) - k ** 3 // 98304
                    angle_q6 = ((raw_q16 - int(offset * 180 / 3.14159265)) >> 10) % (360 << 6)
                    out.append((angle_q6, distance))
                    raw_q16 += increment_q16
        previous = (start_q8, cabins)
    return out


def smooth_stream(count, seed=0):
    """Return ultra capsules of a smooth wall with edges, their start angles and sent ranges."""
    rng = np.random.default_rng(seed)
    starts = (1000 + STEP_Q6 * np.arange(count)) % 23040
    k = np.arange(count * 96 + 1)
    distances = np.rint(3000 + 2500 * np.sin(k / 200.0) + rng.normal(0, 5, k.size))
    distances[(k // 150) % 7 == 3] = 0                  # stretches with no return
    distances[(k // 150) % 7 == 5] += 9000              # a far wall behind an edge
    data, sent = encode_ultra_capsules(starts, distances[:-1].reshape(count, 96),
                                       np.arange(count) == 0, distances[-1])
    return data, starts, sent


def test_capsules_laid_out_by_hand_decode_to_their_samples():
    decoder = UltraCapsuleDecoder(US_PER_SAMPLE)
    samples = decoder.feed(HAND_CAPSULES)
    expected_mm = np.zeros(96)
    expected_mm[:4] = (1488, 1482, 5800, 5760)
    np.testing.assert_array_equal(samples.distance_mm, expected_mm)
    # Offsets (1/65536 degree): 465585 at 1488 and 1482 mm (k = 16: 9150 - 1024 rad/65536),
    # 509588 at 5800 and 5760 mm (k = 4: 9150 - 256), 491483 without a return (8578).
    offsets = np.full(96, 491483)
    offsets[:4] = (465585, 465585, 509588, 509588)
    expected_deg = (4.0 + np.arange(96) / 24.0 - offsets / 65536.0) % 360.0
    np.testing.assert_allclose(samples.angle_deg, expected_deg, atol=1e-12)
    assert samples.quality.tolist() == [47] * 4 + [0] * 92
    assert samples.slot.tolist() == list(range(96)) and samples.frame_end.tolist() == [132] * 96
    distances = np.zeros((1, 96))
    distances[0, :4] = expected_mm[:4]
    data, sent = encode_ultra_capsules([256], distances, [0], 0)
    # The encoder sends cabins 0 and 1 as laid out by hand (and no return as 0x1FF).
    assert data[2:12] == HAND_CAPSULES[2:12]
    np.testing.assert_array_equal(sent[0], expected_mm)


def test_every_scaled_distance_encodes_back_and_the_scale_is_monotone():
    scaled = np.arange(4096)
    distance, level = varbitscale_decode(scaled)
    assert (np.diff(distance) > 0).all() and distance[-1] == ULTRA_MAX_DISTANCE_MM == 28656
    np.testing.assert_array_equal(varbitscale_encode(distance), scaled)
    assert np.bincount(level).tolist() == [512, 768, 512, 1536, 768]
    # Every distance goes to a nearest one the scale has.
    every = np.arange(ULTRA_MAX_DISTANCE_MM + 1)
    nearest, _ = varbitscale_decode(varbitscale_encode(every))
    assert (np.abs(nearest - every) <= np.abs(
        distance[np.clip(np.searchsorted(distance, every), 0, 4095)] - every)).all()


@settings(max_examples=40, deadline=None)
@given(count=st.integers(2, 12), seed=st.integers(0, 2 ** 32 - 1),
       scale=st.sampled_from([300, 3000, 25000]))
def test_a_scan_round_trips_through_encoder_and_decoder(count, seed, scale):
    round_trip(count, seed, scale)


# Cluttered scenes whose far points two at a time lie a flipped bit (at one bit position) from
# their neighbours' prediction: once taken for two bits flipped where the checksum cannot see,
# and the batch's clutter rejected (49, 117 and 45 samples). In the first two, two far points
# side by side vouched for each other's repair; in the last each of two lies within the
# repair's tolerance of its neighbours on its own, on an intact line (the sign is then weak).
@pytest.mark.parametrize('count, seed, scale', [(6, 45, 3000), (12, 3325, 25000),
                                                (12, 173, 25000)])
def test_clutter_on_an_intact_link_is_not_taken_for_bits_flipped(count, seed, scale):
    round_trip(count, seed, scale)


def round_trip(count, seed, scale):
    """Encode and decode a noisy scene with gaps and far points; check every sample back."""
    rng = np.random.default_rng(seed)
    starts = (rng.integers(0, 23040) + STEP_Q6 * np.arange(count)) % 23040
    # A smooth surface with noise, gaps and random far points.
    walk = np.cumsum(rng.normal(0, 0.01 * scale, count * 96 + 1)) + scale
    distances = np.clip(np.rint(walk), 0, ULTRA_MAX_DISTANCE_MM)
    distances[rng.random(distances.size) < 0.1] = 0
    far = rng.random(distances.size) < 0.05
    distances[far] = rng.integers(1, ULTRA_MAX_DISTANCE_MM, far.sum())
    data, sent = encode_ultra_capsules(starts, distances[:-1].reshape(count, 96),
                                       np.arange(count) == 0, distances[-1])
    # What the device sends is within half a step of its scale, or no return.
    _, level = varbitscale_decode(varbitscale_encode(distances[:-1]))
    sent_flat = sent.ravel()
    assert (sent_flat >= 0).all()
    close = np.abs(sent_flat - distances[:-1]) <= (1 << level) / 2 + (1 << 4)
    assert (close | (sent_flat == 0)).all()
    decoder = UltraCapsuleDecoder(US_PER_SAMPLE, max_distance_m=30.0)
    samples = Samples.concat(feed_in_chunks(decoder, data, rng))
    # The last capsule waits for its successor, the one before for the last one's framing.
    decoded = count - 2
    np.testing.assert_array_equal(samples.distance_mm, sent[:decoded].ravel())
    uniform = (starts[:decoded, None] + STEP_Q6 * np.arange(96) / 96.0) / 64.0
    expected = (uniform - offset_deg(sent[:decoded])) % 360.0
    error = (samples.angle_deg - expected.ravel() + 180.0) % 360.0 - 180.0
    np.testing.assert_allclose(error, 0.0, atol=1e-9)
    assert decoder.counts.rejected_samples == decoder.counts.lost_frames == 0


def test_an_intact_stream_decodes_as_the_sdk_does():
    data, starts, sent = smooth_stream(200)
    decoder = UltraCapsuleDecoder(US_PER_SAMPLE, max_distance_m=30.0)
    samples = Samples.concat(feed_in_chunks(decoder, data, np.random.default_rng(1)))
    reference = np.array(sdk_ultra_reference(data))
    assert len(samples) == 198 * 96 and len(reference) == 199 * 96
    reference = reference[:len(samples)]
    np.testing.assert_array_equal(samples.distance_mm, reference[:, 1])
    # The SDK truncates the step between samples to 1/65536 degree (up to 95/65536 degree low
    # at a capsule's end), and the angle to 1/64 degree.
    q6 = samples.angle_deg * 64.0
    behind = (q6 - reference[:, 0] + 11520) % 23040 - 11520
    assert ((behind >= 0) & (behind < 1 + 95 * 64 / 65536)).all()
    assert np.mean(samples.distance_mm > 0) > 0.8


@pytest.mark.parametrize('cut_rate', [0.05, 0.2])
def test_capsules_cut_short_lose_only_themselves_and_give_no_wrong_sample(cut_rate):
    count = 400
    data, starts, sent = smooth_stream(count, seed=2)
    rng = np.random.default_rng(3)
    raw = np.frombuffer(data, np.uint8).reshape(count, 132)
    cut = rng.random(count) < cut_rate
    kept_bytes = np.where(cut, rng.integers(0, 132, count), 132)
    damaged = b''.join(capsule[:n].tobytes() for capsule, n in zip(raw, kept_bytes))
    decoder = UltraCapsuleDecoder(US_PER_SAMPLE, max_distance_m=30.0)
    samples = Samples.concat(feed_in_chunks(decoder, damaged, rng))
    truth = sent.ravel()[samples.slot]
    filled = samples.distance_mm > 0
    np.testing.assert_array_equal(samples.distance_mm[filled], truth[filled])
    uniform = (starts[samples.slot // 96] + STEP_Q6 * (samples.slot % 96) / 96.0) / 64.0
    expected = (uniform - offset_deg(np.where(filled, truth, 0))) % 360.0
    error = (samples.angle_deg - expected + 180.0) % 360.0 - 180.0
    assert (np.abs(error[filled]) < 1e-9).all()
    # Lost: the cut capsules, and the last cabin of each capsule before one (its last two
    # samples are read with the next capsule's first cabin).
    returns = np.count_nonzero(sent[:-2])
    lost = returns - filled.sum()
    assert lost <= np.count_nonzero(sent[:-2][cut[:-2]]) + 2 * cut.sum() + 96
    sdk_lost = returns - np.count_nonzero(np.array(sdk_ultra_reference(damaged))[:, 1])
    assert sdk_lost >= 2 * lost


def test_an_emulated_boost_stream_shows_the_scene_as_the_sdk_decodes_it():
    data = emulated_stream(A_SERIES_MODES, 2, seconds=3.0)
    decoder = UltraCapsuleDecoder(US_PER_SAMPLE, max_distance_m=12.0)
    samples = Samples.concat(feed_in_chunks(decoder, data, np.random.default_rng(4)))
    reference = np.array(sdk_ultra_reference(data))
    assert len(samples) == len(reference) - 96 == (len(data) // 132 - 2) * 96
    np.testing.assert_array_equal(samples.distance_mm, reference[:len(samples), 1])
    # Within half a step of the scale (up to 4 mm beyond 4 m) at the angle decoded.
    truth_mm = 1000.0 * true_ranges(math.pi - np.radians(samples.angle_deg))
    filled = samples.distance_mm > 0
    assert filled.mean() > 0.97 and decoder.counts.rejected_samples == 0
    assert (np.abs(samples.distance_mm[filled] - truth_mm[filled]) <= 4.0 + 1e-6).all()
    # One turn per 800 samples (10 Hz), started where the uncorrected angles wrap.
    assert set(np.diff(np.flatnonzero(samples.start)).tolist()) <= {799, 800, 801}


def test_the_official_sdk_reads_the_emulated_boost_stream_end_to_end():
    pytest.importorskip('pyrplidarsdk')
    with serving('a2', 2) as path:
        result = subprocess.run([sys.executable, '-c', SDK_CLIENT, path], timeout=60,
                                capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    for angles, ranges in json.loads(result.stdout)['turns']:
        angles, ranges = np.array(angles), np.array(ranges)
        assert len(angles) > 0.97 * 800                  # 8000 samples per second, at 10 Hz
        # The SDK truncates the step (up to 95/65536 degree), then each angle to 1/64 degree
        # and to 90/16384 degree; the scale sends ranges up to 4 mm off beyond 4 m.
        bearing = math.pi - angles
        low, high = range_band(bearing - math.radians(1 / 64 + 90 / 16384),
                               bearing + math.radians(95 / 65536))
        assert ((ranges >= low - 4.1e-3) & (ranges <= high + 4.1e-3)).all()


@settings(max_examples=60, deadline=None)
@given(garbage=st.binary(max_size=2000), seed=st.integers(0, 2 ** 32 - 1))
def test_any_bytes_decode_without_error_into_consistent_samples(garbage, seed):
    # Garbage between two runs of intact capsules: see the express decoder's test.
    data, _, _ = smooth_stream(20, seed=seed % 4)
    decoder = UltraCapsuleDecoder(US_PER_SAMPLE, max_distance_m=30.0)
    samples = Samples.concat(feed_in_chunks(decoder, data[:1320] + garbage + data[1320:],
                                            np.random.default_rng(seed)))
    assert ((samples.angle_deg >= 0) & (samples.angle_deg < 360)).all()
    assert (samples.distance_mm >= 0).all() and (samples.distance_mm <= 30000).all()
    assert (np.diff(samples.slot) > 0).all()
    assert decoder.counts.samples == len(samples)
