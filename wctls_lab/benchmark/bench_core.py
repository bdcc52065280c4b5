#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark extract_features per scan on simulated RPLIDAR S1 scans of a furnished room.

First, side by side in one run on the same scans: the compiled core, the numpy core (the
fallback where numba is missing, wctls_ros.core.numpy_core) and, when given, the C++
laser_line_extraction (``--peer BINARY``: a timing driver built outside this repository from its
public source, reading the scans file this script writes; see docs/performance.md), on 1080- and
4320-beam room scans with 5 mm of range noise and on the real 541-beam SICK LMS1xx scans of data/;
then both cores again in alternating fresh processes (``WCTLS_ROS_CORE=numba`` and ``numpy``), and
the start-up of a fresh process to its first extracted scan, with numba's cache warm and cold.
Then median and p99 time per scan (one core) for 1080-beam scans and 4x denser ones, for every
method, and the mean number of segments and corners. Then, for wctls, how the time grows with the
beam count from 270 to 8640 beams: the exponent between each doubling (1 is linear; below 1 is
slower growth than N, let alone N log N) and a least-squares split of the time into a fixed per-
scan cost and a cost per beam. Last, the worst case: a crafted scan (a wall whose every other
return lies a growing few cm behind it, which made IEPF quadratic before its pass bound) next to a
room scan of as many beams, with the default noise model (5 cm, which makes the crafted wall one
chain), 1080 to 100 000 beams.
Usage: python bench_core.py [scans] [--peer BINARY]
"""

import argparse
import os

# One core: keep any BLAS thread pool from spreading the work.
for variable in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(variable, '1')
# extract_features below is the compiled core's (an error if numba cannot give it).
os.environ['WCTLS_ROS_CORE'] = 'numba'

import pathlib  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from wctls_lab.evaluation.scans import load_scans  # noqa: E402
from wctls_lab.simulation import (full_turn_bearings, load_floor_plan, NoiseModel,  # noqa: E402
                                  simulate_ranges)
from wctls_lab.simulation.adversarial import peeling_wall  # noqa: E402
from wctls_ros.core import extract_features, FeatureConfig, METHODS, numpy_core  # noqa: E402

RANGE_NOISE_M = 0.01
SIDE_BY_SIDE_NOISE_M = 0.005
DATA = pathlib.Path(__file__).resolve().parents[2] / 'data'
SWEEP_BEAMS = (270, 540, 1080, 2160, 4320, 8640)
WORST_CASE_BEAMS = (1080, 4320, 16000, 64000, 100000)


def scans(beams, count, seed=1, range_noise_m=RANGE_NOISE_M):
    """Return `count` noisy full-turn scans of environment A and their geometry."""
    walls, _ = load_floor_plan('environment_a').in_sensor_frame()
    angle_min, increment, bearings = full_turn_bearings(beams)
    noise = NoiseModel(range_sigma_m=range_noise_m, bearing_sigma_rad=0.0)
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


def median_ms(extract, ranges, angle_min, increment, config):
    """Return the median time per scan (ms) of an extract_features function, after a warm-up."""
    for r in ranges[:20]:
        extract(r, angle_min, increment, config)
    times = []
    for r in ranges:
        start = time.perf_counter()
        extract(r, angle_min, increment, config)
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def peer_ms(peer, ranges, angle_min, increment):
    """Return the C++ peer's median time per scan (ms) and lines per scan on the same scans."""
    with tempfile.NamedTemporaryFile(suffix='.scans') as scans_file:
        header = np.array([len(ranges), ranges.shape[1]], dtype=np.int32).tobytes()
        scans_file.write(header + np.array([angle_min, increment]).tobytes()
                         + np.ascontiguousarray(ranges, dtype=np.float64).tobytes())
        scans_file.flush()
        lines, median, _ = subprocess.run([peer, scans_file.name], check=True,
                                          capture_output=True, text=True).stdout.split()
    return float(median), float(lines)


def side_by_side(count, peer):
    """Print ours, the numpy reference and the peer on the same scans, and the ratios."""
    cases = []
    for beams in (1080, 4320):
        angle_min, increment, ranges = scans(beams, count, range_noise_m=SIDE_BY_SIDE_NOISE_M)
        cases.append((f'room {beams}', np.array(ranges), angle_min, increment,
                      FeatureConfig(range_sigma_m=SIDE_BY_SIDE_NOISE_M, bearing_sigma_rad=0.0)))
    sick = load_scans(DATA / 'sick_lms1xx_static')
    cases.append(('SICK 541', sick.ranges, sick.angle_min, sick.angle_increment,
                  FeatureConfig(range_sigma_m=0.012, bearing_sigma_rad=0.0)))
    print(f'side by side, median ms per scan ({count} room scans, {len(sick.ranges)} real);'
          f' peer: {peer or "not given (--peer BINARY)"}')
    print(f'{"scans":>9} ' + ' '.join(f'{m:>6}' for m in METHODS)
          + f' {"numpy":>7} {"peer":>7} {"wctls/peer":>10} {"numpy/wctls":>11} '
          f'{"ml/wctls":>8} {"peer lines":>10}')
    for name, ranges, angle_min, increment, config in cases:
        ours = {method: median_ms(extract_features, ranges, angle_min, increment,
                                  config.replace(method=method)) for method in METHODS}
        reference = median_ms(numpy_core.extract_features, ranges, angle_min, increment, config)
        peer_time, peer_lines = (peer_ms(peer, ranges, angle_min, increment) if peer
                                 else (float('nan'), float('nan')))
        print(f'{name:>9} ' + ' '.join(f'{ours[m]:>6.3f}' for m in METHODS)
              + f' {reference:>7.3f} {peer_time:>7.3f} {ours["wctls"] / peer_time:>10.2f} '
              f'{reference / ours["wctls"]:>11.1f} {ours["ml"] / ours["wctls"]:>8.2f} '
              f'{peer_lines:>10.1f}')


# Prints the median ms per scan of the core WCTLS_ROS_CORE names (wctls, the scans' noise) on
# the scans of the .npz file named by its argument: median_ms's loop in a fresh process.
PER_SCAN = """
import sys, time
import numpy as np
from wctls_ros.core import extract_features, FeatureConfig, warm_up
warm_up()
saved = np.load(sys.argv[1])
angle_min, increment = float(saved['angle_min']), float(saved['increment'])
config = FeatureConfig(range_sigma_m=float(saved['noise']), bearing_sigma_rad=0.0)
for ranges in saved['ranges'][:20]:
    extract_features(ranges, angle_min, increment, config)
seconds = []
for ranges in saved['ranges']:
    start = time.perf_counter()
    extract_features(ranges, angle_min, increment, config)
    seconds.append(time.perf_counter() - start)
print(1e3 * np.median(seconds))
"""


def alternating_cores(count, rounds=5):
    """
    Print the compiled core's time per scan against the numpy core's, in alternating processes.

    The same 1080-beam room scans (5 mm), wctls, each process starting afresh: what a user gets
    with numba and without it.
    """
    angle_min, increment, ranges = scans(1080, count, range_noise_m=SIDE_BY_SIDE_NOISE_M)
    times = {'numba': [], 'numpy': []}
    with tempfile.TemporaryDirectory() as folder:
        saved = os.path.join(folder, 'scans.npz')
        np.savez(saved, ranges=np.array(ranges), angle_min=angle_min, increment=increment,
                 noise=SIDE_BY_SIDE_NOISE_M)
        for _ in range(rounds):
            for core in times:
                environment = dict(os.environ, WCTLS_ROS_CORE=core)
                times[core].append(float(subprocess.run(
                    [sys.executable, '-c', PER_SCAN, saved], env=environment, check=True,
                    capture_output=True, text=True).stdout))
    compiled, numpy_time = np.median(times['numba']), np.median(times['numpy'])
    ratios = np.array(times['numpy']) / np.array(times['numba'])
    print(f'numpy core against the compiled core: {count} 1080-beam room scans, medians of '
          f'{rounds} alternating processes: compiled {compiled:.4f} ms, numpy {numpy_time:.4f} '
          f'ms: {numpy_time / compiled:.1f}x (pairs of processes {ratios.min():.1f}x to '
          f'{ratios.max():.1f}x)')


# As the nodes and tools start (wctls_ros.core.start), then a scan; argv[1] 'wait' compiles
# before the first scan, 'auto' answers with the numpy core while a compile runs beside it.
FIRST_SCAN = ('import sys, time; start = time.perf_counter(); import numpy as np; '
              'from wctls_ros.core import extract_features, start as choose, status; '
              'choose(wait=sys.argv[1] == "wait"); '
              'b = -np.pi + 2 * np.pi / 1080 * np.arange(1080); '
              'extract_features(2.0 / np.maximum(abs(np.cos(b)), abs(np.sin(b))), -np.pi, '
              '2 * np.pi / 1080); print(time.perf_counter() - start, status().name)')


def start_up(repeats=3):
    """
    Print the time from a fresh interpreter to its first extracted scan, warm and cold.

    Cold twice, alternately: answering at once (the numpy core while the compiled one compiles
    in another process, as the nodes do) and waiting for the compile.
    """
    def first_scan_s(environment, mode='auto'):
        started = time.perf_counter()
        inside, core = subprocess.run(
            [sys.executable, '-c', FIRST_SCAN, mode], check=True, capture_output=True,
            text=True, env=dict(environment, WCTLS_ROS_CORE='auto')).stdout.split()
        return time.perf_counter() - started, float(inside), core

    warm = [first_scan_s(dict(os.environ)) for _ in range(repeats)]
    print(f'start-up to the first extracted scan (process wall time; after its imports): warm '
          f'cache {np.median([w[0] for w in warm]):.2f} s ({np.median([w[1] for w in warm]):.2f}'
          f' s, {warm[0][2]} core)')
    for mode in ('auto', 'wait', 'auto', 'wait'):
        with tempfile.TemporaryDirectory() as empty:
            cold = first_scan_s(dict(os.environ, NUMBA_CACHE_DIR=empty), mode)
        label = 'answering at once' if mode == 'auto' else 'waiting for the compile'
        print(f'  cold cache, {label}, {os.cpu_count()} CPUs: {cold[0]:.2f} s ({cold[1]:.2f} s, '
              f'{cold[2]} core)')


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('scans', type=int, nargs='?', default=1000)
    parser.add_argument('--peer', help='the C++ peer timing driver (optional)')
    args = parser.parse_args()
    count = args.scans
    side_by_side(min(count, 300), args.peer)
    alternating_cores(min(count, 300))
    start_up()
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
    """Print the crafted scan's time next to a room scan's, the paper's split distance."""
    print("worst case: crafted scan vs room scan, the paper's fixed split distance (4 cm), "
          f'min of {repeats} runs')
    print(f'{"beams":>6} {"crafted ms":>11} {"room ms":>8} {"ratio":>6} {"work bound hit":>15}')
    # The default split distance (4 sigma of the noise) sees the crafted zigzag as noise.
    config = FeatureConfig(iepf_noise_sigmas=0.0)
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
