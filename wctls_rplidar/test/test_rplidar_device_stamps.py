# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Turn stamps on the device's clock for the formats that carry it (0x86 ultra-dense)."""

import numpy as np
from rplidar_testing import emulated_stream
from wctls_rplidar.checked import with_checksum
from wctls_rplidar.protocol import AnswerType, ScanMode
from wctls_rplidar.turns import TurnAssembler
from wctls_rplidar.ultradense import (ULTRA_DENSE_CAPSULE_SIZE,
                                      ULTRA_DENSE_SAMPLES_PER_CAPSULE,
                                      UltraDenseCapsuleDecoder)

US_PER_SAMPLE = 31.25
MODES = (ScanMode(0, 'UltraDense', US_PER_SAMPLE, 40.0, AnswerType.ULTRA_DENSE_CAPSULE),)
BYTE_S = 1e-5                   # 1 Mbaud


def test_turn_stamps_follow_the_device_timestamps_of_an_ultra_dense_stream():
    # A device whose samples come 0.3 % slower than the mode's nominal period, whose clock
    # starts 1.5 s before its 32-bit wrap, read with up to 3 ms of latency per capsule.
    stream = np.frombuffer(emulated_stream(MODES, 0, seconds=4.0, seed=1), np.uint8)
    capsules = stream.reshape(-1, ULTRA_DENSE_CAPSULE_SIZE).copy()
    sample_us = US_PER_SAMPLE * 1.003
    host_us = np.arange(len(capsules)) * ULTRA_DENSE_SAMPLES_PER_CAPSULE * sample_us
    device_us = (np.rint(host_us).astype(np.int64) + (1 << 32) - 1_500_000) % (1 << 32)
    capsules[:, 2:6] = device_us.astype('<u4').view(np.uint8).reshape(-1, 4)
    data = with_checksum(capsules)
    rng = np.random.default_rng(2)
    decoder = UltraDenseCapsuleDecoder(US_PER_SAMPLE)
    assembler = TurnAssembler(US_PER_SAMPLE, ULTRA_DENSE_CAPSULE_SIZE * BYTE_S)
    # Each capsule is received once its last sample is measured and it is sent; a sample is
    # timed by the read that completed its capsule, as the driver does.
    received_s = (1e-6 * (host_us + (ULTRA_DENSE_SAMPLES_PER_CAPSULE - 1) * sample_us)
                  + ULTRA_DENSE_CAPSULE_SIZE * BYTE_S + rng.uniform(0, 3e-3, len(capsules)))
    turns = []
    for i in range(len(capsules)):
        samples = decoder.feed(data[i * ULTRA_DENSE_CAPSULE_SIZE:(i + 1)
                                    * ULTRA_DENSE_CAPSULE_SIZE])
        if len(samples):
            turns += assembler.push(
                samples, received_s[samples.frame_end // ULTRA_DENSE_CAPSULE_SIZE - 1])
    assert len(turns) >= 35
    stamps_s = np.array([turn.first_sample_s for turn in turns])
    first_us = np.array([turn.device_time_us for turn in turns])
    # A turn's first sample is its samples after the one before's, at the device's period: the
    # stamps lie that far apart (the nominal period would put them 0.3 % short) ...
    durations_s = 1e-6 * sample_us * np.array([len(turn.angle_deg) for turn in turns[:-1]])
    assert np.abs(np.diff(stamps_s) - durations_s).max() < 50e-6
    # ... as the device's times of those samples, across its clock's wrap ...
    np.testing.assert_allclose(1e-6 * np.diff(first_us), durations_s, atol=10e-6)
    assert first_us[-1] > 1 << 32
    # ... and on the host's clock where the device measured them.
    offsets_s = stamps_s - 1e-6 * first_us
    assert np.abs(offsets_s - 1e-6 * (host_us[0] - device_us[0])).max() < 100e-6
