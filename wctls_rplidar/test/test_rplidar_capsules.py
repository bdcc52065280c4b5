# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The dense capsule stream: the SDK's output on intact streams, far more of a damaged one."""

import math
import struct

import numpy as np
import pytest
from rplidar_testing import (ANOTHER_POSE, denseboost_stream, sdk_framed_capsules, SENSOR_POSE,
                             true_ranges)
from test_rplidar_protocol import damaged, feed_in_chunks
from wctls_rplidar.capsules import DenseCapsuleDecoder
from wctls_rplidar.emulator.device import Faults
from wctls_rplidar.protocol import CAPSULE_SIZE, encode_dense_capsules, Samples

STEP_Q6 = 995                    # the emulator's capsule sweep at 10 Hz, 1/64 degree


def sdk_capsule_reference(data, us_per_sample=108):
    """Port of the SDK's UnpackerHandler_DenseCapsuleNode::onData, one byte at a time."""
    out, previous = [], None
    limit_q8 = (360 * 100 * 40 // (1000000 // us_per_sample)) << 8
    for capsule in sdk_framed_capsules(data, 84):
        if capsule is None:
            previous = None
            continue
        start_field, *distances = struct.unpack('<41H', capsule[2:])
        if start_field & 0x8000:
            previous = None
        start_q8 = (start_field & 0x7FFF) << 2
        if previous is not None:
            diff = start_q8 - previous[0] + ((360 << 8) if previous[0] > start_q8 else 0)
            if diff <= limit_q8:
                out += [(((previous[0] + k * diff / 40) / 256) % 360, previous[1][k])
                        for k in range(40)]
        previous = (start_q8, distances)
    return out


def decode(data, rng=None):
    """Decode a whole stream (in random chunks when given a generator); return samples, counts."""
    decoder = DenseCapsuleDecoder(108)
    if rng is None:
        return decoder.feed(data), decoder.counts
    return Samples.concat(feed_in_chunks(decoder, data, rng)), decoder.counts


def smooth_capsules(count, first_q6=0):
    """Return capsules of a smooth wall, their start angles and distances (mm)."""
    starts = (first_q6 + STEP_Q6 * np.arange(count)) % 23040
    distances = np.rint(2000 + 300 * np.sin(np.arange(count * 40) / 60.0)).reshape(count, 40)
    return encode_dense_capsules(starts, distances, np.arange(count) == 0), starts, distances


def test_dense_capsules_decode_at_interpolated_angles_across_the_wrap():
    starts_q6 = np.array([22000, 22995, 950, 1945])       # 995 q6 apart, wrapping after 360 deg
    distances = np.arange(160).reshape(4, 40) + 500
    samples, _ = decode(encode_dense_capsules(starts_q6, distances, [True, False, False, False]))
    # Three capsules decode (the last waits for its successor), each at start + k * 995 / 40.
    expected = (starts_q6[:3, None] + 995 * np.arange(40) / 40) / 64.0 % 360.0
    np.testing.assert_allclose(samples.angle_deg, expected.ravel(), atol=1e-12)
    np.testing.assert_array_equal(samples.distance_mm, distances[:3].ravel())
    assert set(samples.quality.tolist()) == {47}
    assert samples.frame_end.tolist() == np.repeat([84, 168, 252], 40).tolist()
    assert samples.samples_after.tolist()[:41] == list(range(39, -1, -1)) + [39]
    assert samples.slot.tolist() == list(range(120))
    # The turn starts at the first sample past 360 degrees, and only there.
    assert np.flatnonzero(samples.start).tolist() == [int(np.argmin(expected.ravel()))]


def test_dense_capsules_far_apart_or_restarted_are_dropped_as_by_the_sdk():
    decoder = DenseCapsuleDecoder(108)
    # 160 deg between starts exceeds the SDK's 155-degree limit at 108 us/sample.
    far = encode_dense_capsules([0, 160 * 64, 160 * 64 + 995], np.ones((3, 40)), [0, 0, 0])
    assert len(decoder.feed(far)) == 40
    restart = encode_dense_capsules([2000, 2995], np.ones((2, 40)), [True, False])
    assert len(decoder.feed(restart)) == 40        # the capsule before the S flag is dropped


@pytest.mark.parametrize('pose', [SENSOR_POSE, ANOTHER_POSE], ids=['mid-room', 'off-centre'])
def test_an_intact_stream_decodes_as_the_sdk_does_and_nothing_is_rejected(pose):
    data = denseboost_stream(pose, seconds=5.0, noisy=True)
    samples, counts = decode(data, np.random.default_rng(1))
    reference = sdk_capsule_reference(data)
    assert len(samples) == len(reference) > 5 * 9000
    np.testing.assert_allclose(np.c_[samples.angle_deg, samples.distance_mm],
                               np.array(reference), atol=1e-9)
    assert counts.frames == len(data) // 84 - 1 and counts.samples == len(samples)
    assert (counts.damaged_frames, counts.lost_frames, counts.rejected_samples,
            counts.replaced_angles, counts.resyncs, counts.discarded_bytes) == (0,) * 6


@pytest.mark.parametrize('pose', [SENSOR_POSE, ANOTHER_POSE], ids=['mid-room', 'off-centre'])
def test_checked_as_on_a_damaged_link_real_geometry_is_rarely_rejected(pose):
    # Every checksum nibble damaged, nothing else: each capsule fails its checksum, so every
    # real sample goes through the plausibility check, and each rejection is real geometry
    # lost (thin panels seen end on, noisy edges). Beams are filled by neighbouring samples.
    intact = denseboost_stream(pose, seconds=5.0, noisy=True)
    data = np.frombuffer(intact, np.uint8).copy()
    data[::84] ^= 0x01
    samples, counts = decode(data.tobytes())
    # The first capsule, damaged with nothing before it, has no believable start angle.
    reference = np.array(sdk_capsule_reference(intact))[40:]
    assert counts.damaged_frames == counts.frames and counts.lost_frames == 1
    assert counts.replaced_angles == 0 and counts.rejected_samples <= 0.015 * counts.samples
    kept = samples.distance_mm > 0
    np.testing.assert_allclose(samples.angle_deg, reference[:, 0], atol=1e-9)
    np.testing.assert_array_equal(samples.distance_mm[kept], reference[kept, 1])


# At 5 % (and 2 + 2 %) the damage measured reaches the heavy-damage bound (8 %) at times: those
# stretches are withheld.
@pytest.mark.parametrize('corrupt, drop, right_share', [(0.01, 0.0, 0.96), (0.05, 0.0, 0.8),
                                                        (0.0, 0.01, 0.96), (0.0, 0.05, 0.74),
                                                        (0.02, 0.02, 0.8)])
def test_a_damaged_stream_keeps_most_samples_right_and_almost_none_wrong(corrupt, drop,
                                                                         right_share):
    intact = denseboost_stream(seconds=5.0)
    truth, _ = decode(intact)
    by_slot = dict(zip(truth.slot.tolist(), zip(truth.angle_deg, truth.distance_mm)))
    rng = np.random.default_rng(3)
    data = damaged(intact, rng, corrupt=corrupt, drop=drop)
    samples, counts = decode(data, rng)
    true_angle, true_distance = np.array([by_slot.get(n, (np.nan, np.nan))
                                          for n in samples.slot.tolist()]).T
    # Right: the true distance within 1/8 of a sample step (0.05 degree) of its angle. Wrong:
    # more than 10 cm off, or half a sample step.
    angle_error = np.abs((samples.angle_deg - true_angle + 180.0) % 360.0 - 180.0)
    filled = samples.distance_mm > 0
    right = filled & (angle_error < 0.05) & (samples.distance_mm == true_distance)
    wrong = filled & ~((angle_error < 0.2) & (np.abs(samples.distance_mm - true_distance) <= 100))
    assert right.sum() >= right_share * len(truth) > len(sdk_capsule_reference(data))
    assert wrong.sum() <= 0.002 * len(truth), f'{wrong.sum()} samples wrong'
    assert counts.damaged_frames > 0 and counts.rejected_samples > 0


def test_a_capsule_that_lost_bytes_is_realigned_sample_by_sample():
    data, starts, distances = smooth_capsules(4)
    raw = np.frombuffer(data, np.uint8)
    # Capsule 1 loses the high byte of sample 10 and the low byte of sample 25. (Were a sample
    # to lose both bytes, its place among smooth neighbours could not be told.)
    lost = 84 + 4 + np.array([2 * 10 + 1, 2 * 25])
    samples, counts = decode(np.delete(raw, lost).tobytes())
    assert counts.realigned_frames == 1 and counts.rejected_samples == 2
    np.testing.assert_array_equal(samples.slot, np.arange(120))
    expected = distances[:3].ravel().astype(float)
    expected[[50, 65]] = 0                                 # the samples the bytes took
    np.testing.assert_array_equal(samples.distance_mm, expected)
    np.testing.assert_allclose(samples.angle_deg, ((starts[:3, None] + STEP_Q6 * np.arange(40)
                                                    / 40) / 64.0 % 360.0).ravel(), atol=1e-9)


def test_a_lost_header_byte_loses_no_capsule():
    data, _, distances = smooth_capsules(5)
    raw = np.frombuffer(data, np.uint8)
    samples, counts = decode(np.delete(raw, 2 * 84 + 1).tobytes())   # capsule 2's sync byte
    np.testing.assert_array_equal(samples.distance_mm, distances[:4].ravel())
    assert counts.realigned_frames == 2 and counts.rejected_samples == 0


def test_an_out_of_sequence_start_angle_is_replaced_by_the_predicted_one():
    data, starts, distances = smooth_capsules(6)
    raw = np.frombuffer(data, np.uint8).copy()
    raw[3 * 84 + 3] ^= 0x21                                # capsule 3's start angle
    samples, counts = decode(raw.tobytes())
    np.testing.assert_allclose(samples.angle_deg, ((starts[:5, None] + STEP_Q6 * np.arange(40)
                                                    / 40) / 64.0 % 360.0).ravel(), atol=1e-9)
    np.testing.assert_array_equal(samples.distance_mm, distances[:5].ravel())
    assert counts.replaced_angles == 1 and counts.damaged_frames == 1


def test_capsules_lost_without_a_trace_in_the_bytes_are_counted_from_the_start_angles():
    data, starts, distances = smooth_capsules(12)
    raw = np.frombuffer(data, np.uint8)
    samples, counts = decode(np.delete(raw, np.arange(5 * 84, 8 * 84)).tobytes())
    assert np.unique(samples.slot // 40).tolist() == [0, 1, 2, 3, 4, 8, 9, 10]
    np.testing.assert_allclose(samples.angle_deg, ((starts[:, None] + STEP_Q6 * np.arange(40)
                                                    / 40) / 64.0 % 360.0).ravel()[samples.slot],
                               atol=1e-9)
    assert counts.lost_frames == 3 and counts.frames == 11 and counts.replaced_angles == 0


def test_a_distance_beyond_the_range_is_rejected_even_when_the_checksum_passes():
    data, _, distances = smooth_capsules(3)
    distances[1, 7] = 56000                                # what a checksum collision let by
    data = encode_dense_capsules((STEP_Q6 * np.arange(3)), distances, [True, False, False])
    samples, counts = decode(data)
    assert samples.distance_mm[47] == 0 and counts.rejected_samples == 1
    assert counts.damaged_frames == 0


def test_a_corrupted_capsule_keeps_its_samples_and_every_sample_its_stream_position():
    data, _, distances = smooth_capsules(6)
    raw = np.frombuffer(data, np.uint8).copy()
    raw[2 * 84 + 10] ^= 0x40                               # capsule 2, sample 3: 64 mm off
    samples, counts = decode(raw.tobytes())
    assert samples.slot.tolist() == list(range(200))
    expected = distances[:5].ravel().astype(float)
    expected[83] = 0
    np.testing.assert_array_equal(samples.distance_mm, expected)
    assert counts.damaged_frames == 1 and counts.rejected_samples == 1


def test_pure_garbage_yields_nothing_and_is_counted():
    rng = np.random.default_rng(9)
    garbage = rng.integers(0, 256, 20000, np.uint8).tobytes()
    samples, counts = decode(garbage, rng)
    assert len(samples) == len(sdk_capsule_reference(garbage)) == 0
    # Random sync nibbles an 84-byte step apart frame some garbage, which no start angle places.
    assert counts.samples == 0 and counts.lost_frames == counts.frames
    assert counts.discarded_bytes + 84 * counts.frames > 19000


def test_the_emulator_cuts_capsules_short_keeping_their_first_bytes():
    intact = np.frombuffer(denseboost_stream(seconds=1.0, seed=4), np.uint8)
    cut = np.frombuffer(denseboost_stream(seconds=1.0, seed=4, faults=Faults(cut_rate=0.5)),
                        np.uint8)
    capsules = intact.reshape(-1, CAPSULE_SIZE)
    # Walk the cut stream capsule by capsule: each is a prefix (0 to 83 bytes) of the intact
    # one or the whole of it.
    pos, kept = 0, []
    for capsule in capsules:
        rest = cut[pos:pos + CAPSULE_SIZE]
        length = next((n for n in range(CAPSULE_SIZE + 1)
                       if n == CAPSULE_SIZE or n == len(rest) or rest[n] != capsule[n]),
                      CAPSULE_SIZE)
        if length < CAPSULE_SIZE and length < len(rest):
            # Cut short: the next capsule's sync follows.
            assert rest[length] >> 4 == 0xA
        kept.append(length)
        pos += length
    assert pos == cut.size
    kept = np.array(kept)
    assert 0.4 < np.mean(kept < CAPSULE_SIZE) < 0.6
    assert kept.min() == 0 and kept[kept < CAPSULE_SIZE].max() >= 80


@pytest.mark.parametrize('cut_rate, kept_share, wrong_share', [(0.05, 0.9, 1e-3),
                                                               (0.2, 0.8, 5e-3)])
def test_capsules_cut_short_give_no_wrong_sample(cut_rate, kept_share, wrong_share):
    # Runs of lost bytes: a share of the capsules ends at a random byte and the next one
    # follows at once. A sample published is the scene's range at its angle, or absent.
    for seed in (0, 1):
        data = denseboost_stream(seconds=4.0, seed=seed, faults=Faults(cut_rate=cut_rate))
        samples, counts = decode(data, np.random.default_rng(seed))
        streamed = round(4.0 / (40 * 108e-6)) * 40
        truth_mm = 1000.0 * true_ranges(math.pi - np.radians(samples.angle_deg))
        filled = samples.distance_mm > 0
        wrong = filled & (np.abs(samples.distance_mm - truth_mm) > 100.0)
        assert filled.sum() >= kept_share * streamed, f'{filled.sum()} of {streamed} kept'
        assert wrong.sum() <= wrong_share * filled.sum(), (
            f'{wrong.sum()} of {filled.sum()} samples more than 10 cm off')
        assert counts.realigned_frames > 0 and counts.rejected_samples > 0


def test_a_capsule_cut_short_keeps_its_first_samples_and_loses_the_rest():
    data, starts, distances = smooth_capsules(4)
    raw = np.frombuffer(data, np.uint8)
    # Capsule 1 keeps its header and 25 samples; the 30 bytes after are lost.
    samples, counts = decode(np.delete(raw, np.arange(84 + 4 + 50, 84 + 84)).tobytes())
    expected = distances[:3].ravel().astype(float)
    expected[65:80] = 0
    np.testing.assert_array_equal(samples.distance_mm, expected)
    np.testing.assert_allclose(samples.angle_deg, ((starts[:3, None] + STEP_Q6 * np.arange(40)
                                                    / 40) / 64.0 % 360.0).ravel(), atol=1e-9)
    assert counts.realigned_frames == 1 and counts.lost_frames == 0


def test_a_capsule_cut_to_its_header_does_not_lend_its_successor_its_angle():
    data, starts, distances = smooth_capsules(5)
    raw = np.frombuffer(data, np.uint8)
    # Capsule 2 keeps only its sync bytes: what follows is capsule 3 from its header on.
    samples, counts = decode(np.delete(raw, np.arange(2 * 84 + 2, 3 * 84)).tobytes())
    by_capsule = samples.slot // 40
    assert 2 not in by_capsule[samples.distance_mm > 0].tolist()
    kept = samples.distance_mm > 0
    np.testing.assert_array_equal(samples.distance_mm[kept],
                                  distances.ravel()[samples.slot[kept]])


def test_a_capsule_cut_within_its_header_after_another_cut_short_is_not_misread():
    data, starts, distances = smooth_capsules(6)
    raw = np.frombuffer(data, np.uint8)
    # Capsule 2 keeps its header and 8 samples, capsule 3 only its two sync bytes: the header
    # after capsule 2's samples starts capsule 4, two sweeps on.
    lost = np.r_[np.arange(2 * 84 + 20, 3 * 84), np.arange(3 * 84 + 2, 4 * 84)]
    samples, counts = decode(np.delete(raw, lost).tobytes())
    kept = samples.distance_mm > 0
    np.testing.assert_array_equal(samples.distance_mm[kept], distances.ravel()[samples.slot[kept]])
    np.testing.assert_allclose(samples.angle_deg, ((starts[:, None] + STEP_Q6 * np.arange(40)
                                                    / 40) / 64.0 % 360.0).ravel()[samples.slot],
                               atol=1e-9)
    assert {0, 1, 4} <= set(np.unique(samples.slot[kept] // 40).tolist()) <= {0, 1, 2, 4}


def right_or_absent(samples, starts, distances):
    """Tell whether every published sample is its slot's true one (angle and distance)."""
    true_angle = ((starts[:, None] + STEP_Q6 * np.arange(40) / 40) / 64.0 % 360.0).ravel()
    filled = samples.distance_mm > 0
    return (np.allclose(samples.angle_deg[filled], true_angle[samples.slot[filled]], atol=1e-9)
            and (samples.distance_mm[filled] == distances.ravel()[samples.slot[filled]]).all())


def test_a_replayed_capsule_is_taken_out_and_its_s_flag_restarts_nothing():
    data, starts, distances = smooth_capsules(12)
    capsules = np.frombuffer(data, np.uint8).reshape(12, 84)
    # The first capsule (S flag set) sent again after capsule 5, capsule 3 again after 8: what a
    # USB-serial adapter sending a buffer twice does. Each is intact, its checksum passes.
    replayed = np.concatenate([capsules[:6], capsules[:1], capsules[6:9], capsules[3:4],
                               capsules[9:]])
    samples, counts = decode(replayed.tobytes())
    np.testing.assert_array_equal(samples.slot, np.arange(11 * 40))
    np.testing.assert_array_equal(samples.distance_mm, distances[:11].ravel())
    assert right_or_absent(samples, starts, distances)


@pytest.mark.parametrize('packet', [(4 * 84 + 10, 64), (5 * 84 - 10, 64), (6 * 84 - 20, 40)],
                         ids=['no header', 'a header', 'a short packet'])
def test_a_packet_delivered_twice_is_never_read_as_a_capsule_that_lost_bytes(packet):
    # Bytes are gained, not lost: a capsule with a packet twice is longer than its start
    # angles allow, and one cut at a repeated header is a copy of its own first bytes.
    data, starts, distances = smooth_capsules(14)
    raw = np.frombuffer(data, np.uint8)
    at, size = packet
    samples, counts = decode(np.insert(raw, at + size, raw[at:at + size]).tobytes())
    assert right_or_absent(samples, starts, distances)
    assert len(np.unique(samples.slot[samples.distance_mm > 0] // 40)) >= 11


@pytest.mark.parametrize('first', [4 * 84 + 40, 5 * 84 + 60, 6 * 84 + 1])
def test_swapped_packets_give_no_capsule_another_ones_samples(first):
    # A packet swapped with the next moves the headers in both by a packet.
    data, starts, distances = smooth_capsules(12)
    raw = np.frombuffer(data, np.uint8).copy()
    raw[first:first + 128] = np.roll(raw[first:first + 128], 64)
    samples, counts = decode(raw.tobytes())
    assert right_or_absent(samples, starts, distances)
    assert len(np.unique(samples.slot[samples.distance_mm > 0] // 40)) >= 8


def test_two_bits_flipped_at_one_position_make_every_capsule_checked():
    # The same bit flipped in two bytes of a capsule leaves its XOR checksum as it was. Two
    # lone spikes that one flipped bit each explains, at one bit position, tell the line
    # flips bits: from then on every capsule is checked by its neighbours, also one whose
    # second flip moved a distance too little to see (its spike is rejected all the same).
    data, starts, distances = smooth_capsules(12)
    raw = np.frombuffer(data, np.uint8).copy()
    for at, bit in ((4 * 84 + 4 + 2 * 10 + 1, 0x02), (4 * 84 + 4 + 2 * 25 + 1, 0x02),
                    (7 * 84 + 4 + 2 * 5 + 1, 0x08), (7 * 84 + 4 + 2 * 30, 0x08)):
        raw[at] ^= bit
    assert (np.frombuffer(encode_dense_capsules(starts, distances, np.arange(12) == 0),
                          np.uint8).reshape(12, 84)[:, :2] == raw.reshape(12, 84)[:, :2]).all()
    samples, counts = decode(raw.tobytes())
    assert counts.damaged_frames == 0
    np.testing.assert_array_equal(samples.slot, np.arange(11 * 40))
    published = samples.distance_mm > 0
    error = np.abs(samples.distance_mm - distances[:11].ravel())[published]
    assert error.max() == 8                                # the flip too small to see
    assert samples.distance_mm[[4 * 40 + 10, 4 * 40 + 25, 7 * 40 + 5]].tolist() == [0, 0, 0]
    assert counts.rejected_samples == 3


# A scene with noise, gaps and far points (as the ultra round trip's) whose far points two at a
# time lie a flipped bit from their neighbours' prediction: once taken for two bits flipped
# where the checksum cannot see, and the batch's clutter rejected (16 samples).
@pytest.mark.parametrize('count, seed, scale', [(6, 27, 25000)])
def test_clutter_on_an_intact_link_is_not_taken_for_bits_flipped(count, seed, scale):
    rng = np.random.default_rng(seed)
    starts = (rng.integers(0, 23040) + STEP_Q6 * np.arange(count)) % 23040
    walk = np.cumsum(rng.normal(0, 0.01 * scale, count * 40)) + scale
    distances = np.clip(np.rint(walk), 0, 40000)
    distances[rng.random(distances.size) < 0.1] = 0
    far = rng.random(distances.size) < 0.05
    distances[far] = rng.integers(1, 40000, far.sum())
    distances = distances.reshape(count, 40)
    samples, counts = decode(encode_dense_capsules(starts, distances, np.arange(count) == 0),
                             rng)
    np.testing.assert_array_equal(samples.distance_mm, distances[:count - 1].ravel())
    assert counts.rejected_samples == counts.damaged_frames == counts.lost_frames == 0


def test_on_an_intact_line_a_noisy_scenes_sign_of_flipped_bits_counts_when_it_comes_again():
    # In a scene as noisy as this (sigma 100 mm: two far points forge the sign now and then) a
    # line with no other damage needs the sign twice: the first double flip is published as
    # read, the second, a batch later, makes every capsule checked by its neighbours.
    rng = np.random.default_rng(4)
    count = 12
    starts = STEP_Q6 * np.arange(count)
    distances = np.rint(2000 + rng.normal(0, 100, (count, 40)))
    raw = np.frombuffer(encode_dense_capsules(starts, distances, np.arange(count) == 0),
                        np.uint8).copy()
    for capsule, samples in ((3, (10, 25)), (8, (8, 30))):
        for k in samples:
            raw[capsule * 84 + 4 + 2 * k + 1] ^= 0x10          # 4096 mm
    decoder = DenseCapsuleDecoder(108)
    samples = Samples.concat([decoder.feed(raw[:6 * 84].tobytes()),
                              decoder.feed(raw[6 * 84:].tobytes())])
    assert decoder.counts.damaged_frames == 0
    np.testing.assert_array_equal(samples.slot, np.arange(11 * 40))
    published = samples.distance_mm.reshape(11, 40)
    assert published[3, [10, 25]].tolist() == (distances[3, [10, 25]] + 4096).tolist()
    assert published[8, [8, 30]].tolist() == [0, 0]
    # Before the second sign every other sample is published as sent.
    sent = distances[:6].copy()
    sent[3, [10, 25]] += 4096
    np.testing.assert_array_equal(published[:6], sent)
