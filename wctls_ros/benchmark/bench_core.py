#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark extract_features per scan on simulated RPLIDAR S1 scans of a furnished room.

Prints median and p99 time per scan (one core) for 1080-beam scans and 4x denser ones, for
every method, and the mean number of segments and corners. Then, for wctls, how the time grows
with the beam count from 270 to 8640 beams: the exponent between each doubling (1 is linear; below
1 is slower growth than N, let alone N log N) and a least-squares split of the time into a fixed
per-scan cost and a cost per beam. Last, the worst case: a crafted scan (a wall whose every
other return lies a growing few cm behind it, which made IEPF quadratic before its pass bound)
next to a room scan of as many beams, with the default noise model (5 cm, which makes the crafted
wall one chain), 1080 to 100 000 beams. Usage: python bench_core.py [scans]
"""

import os

# One core: keep any BLAS thread pool from spreading the work.
for variable in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(variable, '1')

import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from wctls_ros.core import extract_features, FeatureConfig, METHODS  # noqa: E402
from wctls_ros.simulation import (full_turn_bearings, load_floor_plan, NoiseModel,  # noqa: E402
                                  simulate_ranges)
from wctls_ros.simulation.adversarial import peeling_wall  # noqa: E402

RANGE_NOISE_M = 0.01
SWEEP_BEAMS = (270, 540, 1080, 2160, 4320, 8640)
WORST_CASE_BEAMS = (1080, 4320, 16000, 64000, 100000)


def scans(beams, count, seed=1):
    """Return `count` noisy full-turn scans of environment A and their geometry."""
    walls, _ = load_floor_plan('environment_a').in_sensor_frame()
    angle_min, increment, bearings = full_turn_bearings(beams)
    noise = NoiseModel(range_sigma_m=RANGE_NOISE_M, bearing_sigma_rad=0.0)
    rng = np.random.default_rng(seed)
    return angle_min, increment, [simulate_ranges(walls, bearings, noise, rng)
                                  for _ in range(count)]


def time_per_scan(beams, count, config):
    """Return per-scan times (s) and mean segment / corner counts."""
    angle_min, increment, ranges = scans(beams, count)
    for r in ranges[:20]:                                  # warm up caches and allocators
        extract_features(r, angle_min, increment, config)
    times, segments, corners = [], [], []
    for r in ranges:
        start = time.perf_counter()
        features = extract_features(r, angle_min, increment, config)
        times.append(time.perf_counter() - start)
        segments.append(len(features.segments))
        corners.append(len(features.corners))
    return np.array(times), np.mean(segments), np.mean(corners)


def main():
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    print(f'extract_features per scan: environment A, {RANGE_NOISE_M * 1e3:.0f} mm range noise,'
          f' {count} scans, one core')
    print(f'{"beams":>6} {"method":>6} {"median ms":>10} {"p99 ms":>8} {"p99/med":>8} '
          f'{"segments":>9} {"corners":>8}')
    for beams in (1080, 4320):
        for method in METHODS:
            config = FeatureConfig(method=method, range_sigma_m=RANGE_NOISE_M,
                                   bearing_sigma_rad=0.0)
            times, segments, corners = time_per_scan(beams, count, config)
            median, p99 = np.median(times) * 1e3, np.percentile(times, 99) * 1e3
            print(f'{beams:>6} {method:>6} {median:>10.3f} {p99:>8.3f} {p99 / median:>8.2f} '
                  f'{segments:>9.1f} {corners:>8.1f}')
    print('growth with the beam count, wctls')
    print(f'{"beams":>6} {"median ms":>10} {"exponent":>9} {"segments":>9} {"corners":>8}')
    config = FeatureConfig(range_sigma_m=RANGE_NOISE_M, bearing_sigma_rad=0.0)
    medians = []
    for beams in SWEEP_BEAMS:
        times, segments, corners = time_per_scan(beams, count, config)
        medians.append(np.median(times) * 1e3)
        # log2 of the time ratio over one doubling of the beams
        exponent = f'{np.log2(medians[-1] / medians[-2]):.2f}' if len(medians) > 1 else '-'
        print(f'{beams:>6} {medians[-1]:>10.3f} {exponent:>9} {segments:>9.1f} {corners:>8.1f}')
    per_beam_ms, fixed_ms = np.polyfit(SWEEP_BEAMS, medians, 1)
    print(f'least squares: {fixed_ms * 1e3:.0f} us per scan + {per_beam_ms * 1e6:.0f} ns per beam')
    worst_case(max(count // 50, 5))


def worst_case(repeats):
    """Print the crafted scan's time next to a room scan's, the default configuration."""
    print(f'worst case: crafted scan vs room scan, default configuration, min of {repeats} runs')
    print(f'{"beams":>6} {"crafted ms":>11} {"room ms":>8} {"ratio":>6} {"work bound hit":>15}')
    config = FeatureConfig()
    for beams in WORST_CASE_BEAMS:
        crafted = peeling_wall(beams)
        angle_min, increment, (room,) = scans(beams, 1)
        crafted_s, room_s = [], []
        for _ in range(repeats):
            start = time.perf_counter()
            features = extract_features(*crafted, config)
            crafted_s.append(time.perf_counter() - start)
            start = time.perf_counter()
            extract_features(room, angle_min, increment, config)
            room_s.append(time.perf_counter() - start)
        print(f'{beams:>6} {min(crafted_s) * 1e3:>11.2f} {min(room_s) * 1e3:>8.2f} '
              f'{min(crafted_s) / min(room_s):>6.2f} {str(features.work_limited):>15}')


if __name__ == '__main__':
    main()
