# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The S1 codec: the spec's byte examples, round trips, node resynchronisation as in the SDK."""

import struct

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from wctls_rplidar.protocol import (
    AnswerType, Command, ConfType, decode_conf_request, decode_conf_value, DeviceHealth,
    DeviceInfo, encode_answer, encode_conf_request, encode_conf_value, encode_dense_capsules,
    encode_express_scan, encode_motor_speed, encode_request, encode_standard_nodes,
    find_descriptor, model_name, ProtocolError, Request, RequestParser, ResponseDescriptor,
    SampleRate, SendMode, StandardNodeDecoder)


def h(text):
    """Bytes from the spec's hex notation."""
    return bytes.fromhex(text)


@pytest.mark.parametrize('encoded, expected', [
    (encode_express_scan(1), 'A5 82 05 01 00 00 00 00 23'),
    (encode_motor_speed(600), 'A5 A8 02 58 02 55'),
    (encode_motor_speed(0), 'A5 A8 02 00 00 0F'),
    (encode_conf_request(ConfType.TYPICAL_MODE), 'A5 84 04 7C 00 00 00 59'),
    (encode_conf_request(ConfType.US_PER_SAMPLE, 1), 'A5 84 06 71 00 00 00 01 00 57'),
    (encode_request(Command.STOP), 'A5 25'),
    (encode_request(Command.RESET), 'A5 40'),
    (ResponseDescriptor(5, SendMode.MULTIPLE, AnswerType.MEASUREMENT).encode(),
     'A5 5A 05 00 00 40 81'),
    (ResponseDescriptor(84, SendMode.MULTIPLE, AnswerType.DENSE_CAPSULE).encode(),
     'A5 5A 54 00 00 40 85'),
    (encode_answer(AnswerType.DEVICE_HEALTH, DeviceHealth(0, 0).encode()),
     'A5 5A 03 00 00 00 06 00 00 00'),
    (encode_answer(AnswerType.SAMPLE_RATE, SampleRate(244, 108).encode()),
     'A5 5A 04 00 00 00 15 F4 00 6C 00'),
    (encode_answer(AnswerType.LIDAR_CONF, encode_conf_value(ConfType.TYPICAL_MODE, 1)),
     'A5 5A 06 00 00 00 20 7C 00 00 00 01 00'),
    (encode_conf_value(ConfType.US_PER_SAMPLE, 108.0), '71 00 00 00 00 6C 00 00'),
])
def test_encoding_reproduces_the_spec_bytes(encoded, expected):
    assert encoded == h(expected)


def test_spec_answers_decode_to_their_values():
    info_answer = h('A5 5A 14 00 00 00 04 61 1C 01 12') + bytes(range(16))
    descriptor, end = find_descriptor(info_answer)
    assert (descriptor.length, descriptor.send_mode, descriptor.answer_type) == (20, 0, 0x04)
    info = DeviceInfo.decode(info_answer[end:])
    assert (info.model, info.firmware, info.hardware) == (0x61, (1, 28), 18)
    assert info.serial_number == bytes(range(16))
    assert DeviceHealth.decode(h('00 00 00')) == DeviceHealth(0, 0)
    assert SampleRate.decode(h('F4 00 6C 00')) == SampleRate(244, 108)
    assert decode_conf_value(ConfType.TYPICAL_MODE, h('7C 00 00 00 01 00')) == 1
    assert decode_conf_value(ConfType.US_PER_SAMPLE, h('71 00 00 00 00 6C 00 00')) == 108.0


def test_spec_standard_nodes_decode():
    samples = StandardNodeDecoder().feed(h('BD 01 03 A0 0F 3E 01 2D 11 27 02 01 5A 00 00'))
    assert samples.start.tolist() == [True, False, False]
    assert samples.quality.tolist() == [47, 15, 0]
    assert samples.angle_deg.tolist() == [6.0, 90.0, 180.0]
    assert samples.distance_mm.tolist() == [1000.0, 2500.25, 0.0]
    assert samples.frame_end.tolist() == [5, 10, 15]
    assert samples.slot.tolist() == [0, 1, 2]


def test_spec_dense_capsule_bytes():
    capsule = encode_dense_capsules([640], np.arange(1000, 1040)[None], [True])
    assert capsule[:8] == h('A2 50 80 82 E8 03 E9 03')
    assert len(capsule) == 84


@pytest.mark.parametrize('conf_type, value', [
    (ConfType.MODE_COUNT, 2), (ConfType.TYPICAL_MODE, 1), (ConfType.US_PER_SAMPLE, 244.0),
    (ConfType.MAX_DISTANCE, 40.0), (ConfType.ANSWER_TYPE, 0x85),
    (ConfType.MODE_NAME, 'DenseBoost'), (ConfType.DESIRED_ROTATION, (600, 0)),
])
def test_conf_values_round_trip(conf_type, value):
    assert decode_conf_value(conf_type, encode_conf_value(conf_type, value)) == value


def test_conf_request_round_trip_and_errors():
    request = RequestParser().feed(encode_conf_request(ConfType.MODE_NAME, 1))[0]
    assert decode_conf_request(request.payload) == (ConfType.MODE_NAME, 1)
    assert decode_conf_request(struct.pack('<I', 0x70)) == (ConfType.MODE_COUNT, None)
    with pytest.raises(ProtocolError, match='too short'):
        decode_conf_request(b'\x70')
    with pytest.raises(ProtocolError, match='0x7C'):
        decode_conf_value(ConfType.TYPICAL_MODE, encode_conf_value(ConfType.MODE_COUNT, 2))
    with pytest.raises(ProtocolError, match='value is 1 bytes'):
        decode_conf_value(ConfType.TYPICAL_MODE, h('7C 00 00 00 01'))
    with pytest.raises(ProtocolError, match='needs 3 bytes'):
        DeviceHealth.decode(b'\x00')
    with pytest.raises(ProtocolError, match='payload'):
        encode_request(Command.STOP, b'\x01')


def test_request_parser_skips_garbage_and_bad_checksums_in_any_chunking():
    good = [encode_request(Command.GET_INFO), encode_motor_speed(600), encode_express_scan(1)]
    corrupted = bytearray(encode_motor_speed(300))
    corrupted[-1] ^= 0xFF
    stream = b'\x00\x13' + good[0] + bytes(corrupted) + b'\x99' + good[1] + good[2]
    rng = np.random.default_rng(4)
    for _ in range(20):
        parser = RequestParser()
        cuts = np.sort(rng.integers(0, len(stream), 5))
        requests = []
        for piece in np.split(np.frombuffer(stream, np.uint8), cuts):
            requests += parser.feed(piece.tobytes())
        assert requests == [Request(Command.GET_INFO), Request(Command.MOTOR_SPEED, h('58 02')),
                            Request(Command.EXPRESS_SCAN, h('01 00 00 00 00'))]
        assert parser.checksum_errors == 1


def test_find_descriptor_skips_stale_bytes_and_waits_for_a_whole_one():
    answer = encode_answer(AnswerType.DEVICE_HEALTH, DeviceHealth(1, 0x1234).encode())
    stale = b'\x12\xa5\x00\x5a'
    assert find_descriptor(stale) == (None, 3)
    descriptor, end = find_descriptor(stale + answer)
    assert descriptor == ResponseDescriptor(3, SendMode.SINGLE, AnswerType.DEVICE_HEALTH)
    assert DeviceHealth.decode((stale + answer)[end:]) == DeviceHealth(1, 0x1234)
    assert find_descriptor(stale + answer[:5]) == (None, len(stale))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 23039), st.integers(0, 65535), st.integers(0, 63),
                          st.booleans()), min_size=1, max_size=50))
def test_standard_nodes_round_trip_and_agree_with_the_rplidar_package(nodes):
    rplidar = pytest.importorskip('rplidar')
    angle_q6, distance_q2, quality, start = (np.array(column) for column in zip(*nodes))
    data = encode_standard_nodes(angle_q6, distance_q2, quality, start)
    samples = StandardNodeDecoder().feed(data)
    np.testing.assert_array_equal(samples.angle_deg, angle_q6 / 64.0)
    np.testing.assert_array_equal(samples.distance_mm, distance_q2 / 4.0)
    np.testing.assert_array_equal(samples.quality, quality)
    np.testing.assert_array_equal(samples.start, start)
    oracle = [rplidar._process_scan(data[i:i + 5]) for i in range(0, len(data), 5)]
    assert [(bool(s), int(q), float(a), float(d)) for s, q, a, d in oracle] == list(zip(
        samples.start.tolist(), samples.quality.tolist(), samples.angle_deg.tolist(),
        samples.distance_mm.tolist()))


def sdk_node_reference(data):
    """Port of the SDK's UnpackerHandler_NormalNode::onData, one byte at a time."""
    out, buffer = [], []
    for byte in data:
        if len(buffer) == 0 and not ((byte >> 1) ^ byte) & 1:
            continue
        if len(buffer) == 1 and not byte & 1:
            buffer = []
            continue
        buffer.append(byte)
        if len(buffer) == 5:
            angle = ((buffer[1] | buffer[2] << 8) >> 1) / 64.0
            out.append((angle, (buffer[3] | buffer[4] << 8) / 4.0, buffer[0] >> 2,
                        bool(buffer[0] & 1)))
            buffer = []
    return out


def damaged(data, rng, corrupt=0.0, drop=0.0, garbage=0):
    """Corrupt and drop bytes at random and splice in runs of random garbage."""
    raw = np.frombuffer(data, np.uint8).copy()
    hit = rng.random(raw.size) < corrupt
    raw[hit] ^= rng.integers(1, 256, hit.sum(), dtype=np.uint8)
    raw = raw[rng.random(raw.size) >= drop]
    for _ in range(garbage):
        at = rng.integers(raw.size)
        raw = np.concatenate([raw[:at], rng.integers(0, 256, rng.integers(1, 200), np.uint8),
                              raw[at:]])
    return raw.tobytes()


def feed_in_chunks(decoder, data, rng):
    """Feed random-sized chunks (1 byte to 1 KB); return the samples of each feed."""
    cuts = np.cumsum(rng.integers(1, 1024, len(data) // 100 + 2))
    return [decoder.feed(data[a:b]) for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(data)])]


@pytest.mark.parametrize('seed', range(6))
def test_node_resync_is_the_sdk_state_machine(seed):
    rng = np.random.default_rng(seed)
    n = 2000
    clean = encode_standard_nodes((np.arange(n) * 56) % 23040, rng.integers(0, 65536, n),
                                  rng.integers(0, 64, n), np.arange(n) % 411 == 0)
    data = damaged(clean, rng, corrupt=0.01, drop=0.005, garbage=5)
    decoder = StandardNodeDecoder()
    pieces = feed_in_chunks(decoder, data, rng)
    got = [(a, d, q, s) for p in pieces for a, d, q, s in zip(
        p.angle_deg.tolist(), p.distance_mm.tolist(), p.quality.tolist(), p.start.tolist())]
    assert got == sdk_node_reference(data)
    assert decoder.counts.discarded_bytes > 0 and decoder.counts.resyncs > 0


@pytest.mark.parametrize('model, name', [(0x18, 'A1M8'), (0x28, 'A2M8'), (0x31, 'A3M1'),
                                         (0x41, 'C1M1'), (0x61, 'S1M1'), (0x71, 'S2M1'),
                                         (0x81, 'S3M1'), (0x51, 'unknown (0x51)'),
                                         (0x00, 'unknown (0x00)')])
def test_models_are_named_by_their_major_id_as_slamtec_does(model, name):
    assert model_name(model) == name
    info = DeviceInfo(model, 28, 1, 18, bytes(16))
    assert info.model_name == name and info.firmware_version == '1.28'
    assert info.describe().startswith(f'RPLIDAR {name} (model 0x{model:02X}), firmware 1.28')
