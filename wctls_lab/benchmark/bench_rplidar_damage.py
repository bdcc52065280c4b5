#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark what the driver publishes from damaged links: beams published and beams wrong.

For each scan format (:data:`bench_rplidar_formats.FORMATS`), each kind of damage the emulator
injects (corrupted, dropped and inserted bytes, frames cut short, one bit flipped in two bytes
of a frame, replayed frames, 64-byte USB packets swapped and duplicated) and each rate (1, 5,
10, 20 and 30 %), a stream of the emulated device (noiseless scene, in this process) is decoded
as the driver decodes it, in the chunks of 50 ms it reads, and each turn it would publish is
judged by the driver's own publish check (:class:`~wctls_rplidar.turns.PublishGate`). A
published beam (a return) is wrong when it lies more than 10 cm outside the scene's ranges
within 1/32 degree of its own bearing (the exact band, rplidar_testing.range_band). Printed per
format and damage kind: the beams published at each rate, as a share of the clean stream's,
with the share of them that is wrong; a published scan sweeping more than one rotation (plus
5 %), or starting less than 0.9 of a rotation period after the one before it, is a bad
scan, marked with its count.
Usage: python bench_rplidar_damage.py [seconds per stream] [format] (default 2; every format, or
those whose name holds the text given).
"""

import math
import pathlib
import sys

import numpy as np
from wctls_rplidar.turns import PublishGate, sweep_deg

HERE = pathlib.Path(__file__).resolve().parent
# The formats and the driver-like decoding loop are the format benchmark's; the stream
# generator and the scene oracle are the tests' own.
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / 'test'))
from bench_rplidar_formats import FORMATS, run  # noqa: E402, I100
from rplidar_testing import emulated_stream, range_band  # noqa: E402
from wctls_rplidar.emulator.device import Faults, STREAM_FAULTS  # noqa: E402

RATES = (0.01, 0.05, 0.10, 0.20, 0.30)
WRONG_M = 0.1
BEARING_TOLERANCE_RAD = math.radians(1.0 / 32.0)
# More than a rotation, beyond the scatter of corrected angles (express and ultra capsules).
LONG_SWEEP_DEG = 378.0
EARLY_SHARE = 0.9


def judge(turns, period_s: float) -> tuple:
    """
    Return the beams published, those wrong, and the bad scans, of the turns that pass.

    :param turns: the turns assembled
    :param period_s: the rotation period, s
    :return: ``(published, wrong, bad_scans)``
    """
    published = wrong = bad_scans = 0
    previous_s = -math.inf
    gate = PublishGate()
    for turn in turns:
        if not gate.admit(turn):
            continue
        bad_scans += (sweep_deg(turn.angle_deg) > LONG_SWEEP_DEG
                      or turn.first_sample_s - previous_s < EARLY_SHARE * period_s)
        previous_s = turn.first_sample_s
        returns = turn.distance_mm > 0
        bearing = math.pi - np.radians(turn.angle_deg[returns])
        low, high = range_band(bearing - BEARING_TOLERANCE_RAD, bearing + BEARING_TOLERANCE_RAD)
        distance_m = turn.distance_mm[returns] / 1000.0
        published += int(returns.sum())
        wrong += int(np.count_nonzero((distance_m < low - WRONG_M)
                                      | (distance_m > high + WRONG_M)))
    return published, wrong, bad_scans


def main():
    """Print the table."""
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 2.0
    only = sys.argv[2] if len(sys.argv) > 2 else ''
    print(f'{seconds:g} s of stream per case; load average {open("/proc/loadavg").read()[:14]}')
    print("Each cell: beams published (share of the clean stream's) / wrong (share of those "
          'published); !N: N bad scans (sweeping more than a turn, or early).')
    print('| format | damage | ' + ' | '.join(f'{rate:.0%}' for rate in RATES) + ' |')
    print('|---|---|' + '---|' * len(RATES))
    for name, modes, mode_id in FORMATS:
        if only not in name:
            continue
        mode = modes[mode_id]
        _, clean_turns = run(mode, emulated_stream(modes, mode_id, seconds=seconds), seconds)
        period_s = float(np.median([t.period_s for t in clean_turns]))
        clean_published, _, _ = judge(clean_turns, period_s)
        for kind in STREAM_FAULTS:
            cells = []
            for rate in RATES:
                data = emulated_stream(modes, mode_id, seconds=seconds, seed=3,
                                       faults=Faults(**{f'{kind}_rate': rate}))
                _, turns = run(mode, data, seconds)
                published, wrong, bad_scans = judge(turns, period_s)
                bad = f' !{bad_scans}' if bad_scans else ''
                cells.append(f'{published / max(clean_published, 1):.0%} / '
                             f'{wrong / max(published, 1):.2%}{bad}')
            print(f'| {name} | {kind} | ' + ' | '.join(cells) + ' |', flush=True)


if __name__ == '__main__':
    main()
