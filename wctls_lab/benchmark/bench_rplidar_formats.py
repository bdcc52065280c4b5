#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark the driver's decoding of every RPLIDAR scan format at its native rate.

For each format, a stream from the emulated device (noiseless scene, in this process, produced
before the clock starts) is fed to the driver's decoder and turn assembler in the chunks of
50 ms the driver reads: the decode CPU per turn (ms, and % of one core at the stream's rate).
Then the same stream length with 5 % of its bytes corrupted (the emulator's fault injection):
the turns kept (assembled with at least 80 % of a clean turn's correct beams, as a share of the
clean run's turns), the beams kept (correct beams, returns within 1 cm of the scene at their
angle, as a share of the clean run's) and the share of published returns more than 10 cm off
(wrong). Usage: python bench_rplidar_formats.py [seconds per format] (default 10).
"""

import math
import pathlib
import sys
import time

import numpy as np
from wctls_rplidar.driver import stream_decoder
from wctls_rplidar.emulator.device import A_SERIES_MODES, EMULATED_MODELS, Faults, MODES
from wctls_rplidar.protocol import AnswerType, ScanMode
from wctls_rplidar.turns import TurnAssembler

# The stream generator and the scene oracle are the tests' own.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / 'wctls_rplidar' / 'test'))
from rplidar_testing import emulated_stream, true_ranges  # noqa: E402, I100

READ_PERIOD_S = 0.05
CORRUPT_RATE = 0.05
GOOD_TOLERANCE_MM = 10.0
WRONG_MM = 100.0
GOOD_TURN_SHARE = 0.8
# Format, the device's modes and the mode streamed: each at a rate a model streams it at.
FORMATS = (
    ('0x81 standard, S1 4.1 kHz', MODES, 0),
    ('0x82 express, A2 4 kHz', A_SERIES_MODES, 1),
    ('0x83 HQ, 8 kHz', (ScanMode(0, 'HQ', 125.0, 25.0, AnswerType.HQ_CAPSULE),), 0),
    ('0x84 ultra, A2 Boost 8 kHz', A_SERIES_MODES, 2),
    ('0x84 ultra, A3 Sensitivity 16 kHz', EMULATED_MODELS['a3'].modes, 3),
    ('0x85 dense, S1 DenseBoost 9.3 kHz', MODES, 1),
    ('0x85 dense, S2 DenseBoost 32 kHz', EMULATED_MODELS['s2'].modes, 1),
    ('0x86 ultra-dense, 32 kHz', (ScanMode(0, 'UltraDense', 31.25, 40.0,
                                           AnswerType.ULTRA_DENSE_CAPSULE),), 0),
)


def run(mode: ScanMode, data: bytes, seconds: float) -> tuple:
    """Decode ``data`` as the driver does; return the CPU time (s) and the turns."""
    decoder = stream_decoder(mode)
    assembler = TurnAssembler(mode.us_per_sample, decoder.FRAME_SIZE * 1e-5)
    chunk = max(int(len(data) / seconds * READ_PERIOD_S), 1)
    turns = []
    started = time.process_time()
    for n, at in enumerate(range(0, len(data), chunk)):
        samples = decoder.feed(data[at:at + chunk])
        if len(samples):
            turns += assembler.push(samples, np.full(len(samples), n * READ_PERIOD_S))
    return time.process_time() - started, turns


def beam_counts(turns) -> tuple:
    """Return the correct returns of each turn and the wrong returns of all."""
    correct, wrong = [], 0
    for turn in turns:
        returns = turn.distance_mm > 0
        truth = 1000.0 * true_ranges(math.pi - np.radians(turn.angle_deg[returns]))
        error = np.abs(turn.distance_mm[returns] - truth)
        correct.append(int(np.count_nonzero(error <= GOOD_TOLERANCE_MM)))
        wrong += int(np.count_nonzero(error > WRONG_MM))
    return np.array(correct), wrong


def main():
    """Print the table."""
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    print(f'{seconds:g} s of stream per format; load average {open("/proc/loadavg").read()[:14]}')
    print('| format | decode CPU per turn (ms) | % of a core | turns kept at 5 % corrupted | '
          'beams kept | wrong returns |')
    print('|---|---|---|---|---|---|')
    for name, modes, mode_id in FORMATS:
        mode = modes[mode_id]
        clean = emulated_stream(modes, mode_id, seconds=seconds)[7:]
        corrupted = emulated_stream(modes, mode_id, seconds=seconds,
                                    faults=Faults(corrupt_rate=CORRUPT_RATE))[7:]
        cpu_s, turns = run(mode, clean, seconds)
        _, damaged_turns = run(mode, corrupted, seconds)
        good, _ = beam_counts(turns)
        kept, wrong = beam_counts(damaged_turns)
        good_turns = np.count_nonzero(kept >= GOOD_TURN_SHARE * np.mean(good))
        published = sum(int(np.count_nonzero(t.distance_mm > 0)) for t in damaged_turns)
        print(f'| {name} | {1000.0 * cpu_s / max(len(turns), 1):.2f} | '
              f'{100.0 * cpu_s / seconds:.1f} | {good_turns / max(len(turns), 1):.1%} | '
              f'{kept.sum() / max(good.sum(), 1):.1%} | {wrong / max(published, 1):.2%} |',
              flush=True)


if __name__ == '__main__':
    main()
