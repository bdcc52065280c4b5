#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark the core by stage, and against an earlier core and the C++ peer, in one process.

On the same scans, interleaved in blocks of BLOCK scans so that the machine's load falls on
every contender alike (and each runs with its own code and data in the CPU's caches, as in a
node that runs one of them): today's compiled pipeline split into its compiled call and the
Python around it; the numpy pipeline; and the core of an earlier commit (``--against COMMIT``,
default the 2026-11-27 core, e613b0c), taken out of git into a cache folder and compiled in this
process with the same numba (its first run compiles it, later runs load it), split alike. With
``--peer BINARY`` (the C++ laser_line_extraction's timing driver, built outside this repository:
docs/performance.md), the peer's time on the same scans. Prints the median per scan and the
ratios the speed goals are stated in; ``--profile`` adds the numpy pipeline's time by step
(cProfile, cumulative).
Scan sets: the real 360-beam RPLIDAR A-series scans and 541-beam SICK LMS111 scans of data/,
and simulated 1080- and 4320-beam room scans with 5 mm range noise. Last, the worst case the
speed goals name: star-shaped rooms of 64 and 80 walls (a segment on every wall, a corner at
every other vertex) against room scans of as many beams, both pipelines.
Usage: python bench_stages.py [scans] [--against COMMIT] [--peer BINARY] [--profile]
"""

import argparse
import cProfile
import importlib
import os

# One core: keep any BLAS thread pool from spreading the work.
for variable in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ.setdefault(variable, '1')
os.environ['WCTLS_ROS_CORE'] = 'numba'

import pathlib  # noqa: E402
import pstats  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

# bench_core.py beside this script: the scans and the peer's driver protocol.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_core import peer_ms, scans  # noqa: E402
from earlier import earlier_package  # noqa: E402
import numpy as np  # noqa: E402
from wctls_lab.evaluation.scans import load_scans  # noqa: E402
from wctls_lab.simulation import full_turn_bearings, NoiseModel, simulate_ranges  # noqa: E402
from wctls_ros.core import extract_features, FeatureConfig, numpy_core, warm_up  # noqa: E402
from wctls_ros.core.numba_core import pipeline  # noqa: E402

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
DATA = REPOSITORY / 'data'
# The last core before the per-scan Python grew (2026-11-27): the regression guard's reference.
REFERENCE_COMMIT = 'e613b0c'
ROOM_NOISE_M = 0.005
# Scans each contender runs in a row before the next takes its turn.
BLOCK = 10


def scan_sets(count):
    """Return (name, ranges (K, N), angle_min, increment, range_noise_m) of every scan set."""
    sets = []
    for name, folder, noise in (('RPLIDAR 360', 'rplidar_barc_moving', 0.01),
                                ('LMS111 541', 'sick_lms111_static', 0.012)):
        recorded = load_scans(DATA / folder, limit=count)
        sets.append((name, recorded.ranges, recorded.angle_min, recorded.angle_increment, noise))
    for beams in (1080, 4320):
        angle_min, increment, ranges = scans(beams, count, range_noise_m=ROOM_NOISE_M)
        sets.append((f'room {beams}', np.array(ranges), angle_min, increment, ROOM_NOISE_M))
    return sets


def earlier_core(commit):
    """
    Return the feature core of an earlier commit (:func:`earlier.earlier_package`).

    Cores before the split into numba_core/ and numpy_core/ (the 2026-11-27 one) are one flat
    package with the same entry points.
    """
    return importlib.import_module(f'{earlier_package(commit, "bench_stages")}.core')


class StageClock:
    """
    Time the compiled pipeline's call inside each extract_features call (stands in for it).

    The call goes to the one compiled version's entry point, past numba's dispatcher: with two
    cores in one process, whose records are alike, the dispatcher's typing of the arguments
    cost the core loaded second 60-400 us more per call than the first (the same code either
    way); this way neither pays it, nor the few us of that typing in a process of one core.
    Today's core calls that entry point itself, looked up when it prepares a configuration
    (``pipeline._LATEST``): the records prepared before the clock took its place are
    forgotten on the way in and out, so that it is the clock's that are called while it is in
    place, and the entry point's afterwards.
    """

    def __init__(self, module):
        self.module = module
        self.compiled = module._features_of_scan
        versions = list(self.compiled.overloads.values())
        self.entry_point = versions[0].entry_point if len(versions) == 1 else self.compiled
        self.inside_s = 0.0

    def __call__(self, *arguments):
        start = time.perf_counter()
        found = self.entry_point(*arguments)
        self.inside_s = time.perf_counter() - start
        return found

    def _forget_prepared(self):
        latest = getattr(self.module, '_LATEST', None)
        if latest is not None:
            latest.prepared = None

    def __enter__(self):
        self.module._features_of_scan = self
        self._forget_prepared()
        return self

    def __exit__(self, *_):
        self.module._features_of_scan = self.compiled
        self._forget_prepared()


def pipeline_of(core):
    """Return the module of a core that holds its compiled _features_of_scan."""
    return getattr(getattr(core, 'numba_core', None), 'pipeline', None) or core.pipeline


def side_by_side(sets, old, peer):
    """Return the median ms per scan of every contender on every set, interleaved by blocks."""
    rows = []
    for name, ranges, angle_min, increment, noise in sets:
        config = FeatureConfig(range_sigma_m=noise, bearing_sigma_rad=0.0)
        contenders = {'compiled': lambda r: extract_features(r, angle_min, increment, config),
                      'numpy': lambda r: numpy_core.extract_features(r, angle_min, increment,
                                                                     config)}
        if old is not None:
            old_config = old.FeatureConfig(range_sigma_m=noise, bearing_sigma_rad=0.0)
            contenders['earlier'] = lambda r: old.extract_features(r, angle_min, increment,
                                                                   old_config)
        times = {key: [] for key in contenders}
        outside = {'compiled': [], 'earlier': []}
        inside = []
        clocks = {'compiled': StageClock(pipeline)}
        if old is not None:
            clocks['earlier'] = StageClock(pipeline_of(old))
        for clock in clocks.values():
            clock.__enter__()
        try:
            for r in ranges[:10]:                       # warm caches and allocators
                for extract in contenders.values():
                    extract(r)
            for first in range(0, len(ranges), BLOCK):
                for key, extract in contenders.items():
                    for r in ranges[first:first + BLOCK]:
                        start = time.perf_counter()
                        extract(r)
                        times[key].append(time.perf_counter() - start)
                        if key in clocks:
                            outside[key].append(times[key][-1] - clocks[key].inside_s)
                        if key == 'compiled':
                            inside.append(clocks[key].inside_s)
        finally:
            for clock in clocks.values():
                clock.__exit__()
        row = {key: 1e3 * float(np.median(value)) for key, value in times.items()}
        row['inside'] = 1e3 * float(np.median(inside))
        row['outside_us'] = 1e6 * float(np.median(outside['compiled']))
        row['earlier_outside_us'] = (1e6 * float(np.median(outside['earlier']))
                                     if outside['earlier'] else float('nan'))
        row['peer'] = peer_ms(peer, ranges, angle_min, increment)[0] if peer else float('nan')
        rows.append((name, len(ranges), row))
    return rows


def star_walls(walls, inner_m=2.0, outer_m=2.8):
    """Return the walls of a star-shaped room around the sensor, vertices at alternate radii."""
    angle = 2.0 * np.pi * np.arange(walls) / walls
    radius = np.where(np.arange(walls) % 2 == 0, inner_m, outer_m)
    vertex = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    return np.hstack([vertex, np.roll(vertex, -1, axis=0)])


def worst_case(repeats):
    """Print the star rooms' median time per scan over a room scan's of as many beams."""
    print(f'worst case: star rooms against room scans of as many beams, {ROOM_NOISE_M * 1e3:.0f}'
          f' mm, median of {repeats} scans each, in turn')
    print(f'{"walls":>6} {"beams":>6} {"compiled":>9} {"room":>7} {"ratio":>6} {"numpy":>7} '
          f'{"room":>7} {"ratio":>6} {"segments":>9} {"corners":>8}')
    config = FeatureConfig(range_sigma_m=ROOM_NOISE_M, bearing_sigma_rad=0.0)
    noise = NoiseModel(range_sigma_m=ROOM_NOISE_M, bearing_sigma_rad=0.0)
    rng = np.random.default_rng(4)
    for walls in (64, 80):
        for beams in (1080, 4320):
            angle_min, increment, bearings = full_turn_bearings(beams)
            star = simulate_ranges(star_walls(walls), bearings, noise, rng)
            rooms = scans(beams, repeats, seed=walls, range_noise_m=ROOM_NOISE_M)[2]
            medians = []
            for extract in (extract_features, numpy_core.extract_features):
                star_s, room_s = [], []
                for room in rooms:
                    start = time.perf_counter()
                    found = extract(star, angle_min, increment, config)
                    star_s.append(time.perf_counter() - start)
                    start = time.perf_counter()
                    extract(room, angle_min, increment, config)
                    room_s.append(time.perf_counter() - start)
                medians += [1e3 * np.median(star_s), 1e3 * np.median(room_s)]
            print(f'{walls:>6} {beams:>6} {medians[0]:>9.3f} {medians[1]:>7.3f} '
                  f'{medians[0] / medians[1]:>6.2f} {medians[2]:>7.3f} {medians[3]:>7.3f} '
                  f'{medians[2] / medians[3]:>6.2f} {len(found.segments):>9} '
                  f'{len(found.corners):>8}')


def numpy_profile(ranges, angle_min, increment, noise, top=14):
    """Print the numpy pipeline's cumulative time by function over the scans, per scan."""
    config = FeatureConfig(range_sigma_m=noise, bearing_sigma_rad=0.0)
    profile = cProfile.Profile()
    profile.enable()
    for r in ranges:
        numpy_core.extract_features(r, angle_min, increment, config)
    profile.disable()
    statistics = pstats.Stats(profile)
    entries = []
    for (path, _, function), (_, calls, _, cumulative, _) in statistics.stats.items():
        if f'{os.sep}core{os.sep}' in path:
            entries.append((cumulative, calls, f'{pathlib.Path(path).stem}.{function}'))
    total_calls = sum(value[1] for value in statistics.stats.values())
    print(f'numpy pipeline by step, {len(ranges)} scans: {total_calls / len(ranges):.0f} '
          'function calls per scan (under cProfile, which slows calls)')
    for cumulative, calls, name in sorted(entries, reverse=True)[:top]:
        print(f'  {name:>44} {1e3 * cumulative / len(ranges):>8.3f} ms '
              f'{calls / len(ranges):>6.1f} calls per scan')


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('scans', type=int, nargs='?', default=200)
    parser.add_argument('--against', default=REFERENCE_COMMIT,
                        help='the earlier commit to compare with ("none": no comparison)')
    parser.add_argument('--peer', help='the C++ peer timing driver (optional)')
    parser.add_argument('--profile', action='store_true', help="the numpy pipeline's steps")
    args = parser.parse_args()
    old = None
    if args.against != 'none':
        started = time.perf_counter()
        old = earlier_core(args.against)
        old.extract_features(np.full(360, 2.0), -np.pi, 2 * np.pi / 360, old.FeatureConfig())
        print(f'core of {args.against} loaded and compiled in {time.perf_counter() - started:.1f}'
              ' s')
    warm_up()
    sets = scan_sets(args.scans)
    load = os.getloadavg()[0]
    rows = side_by_side(sets, old, args.peer)
    print(f'median ms per scan, contenders interleaved by {BLOCK} scans; load {load:.1f} before, '
          f'{os.getloadavg()[0]:.1f} after; {os.cpu_count()} CPUs')
    print(f'{"scans":>12} {"count":>5} {"peer":>7} {"earlier":>8} {"outside":>8} '
          f'{"compiled":>8} {"of which":>8} {"outside":>8} {"numpy":>7} {"compiled/":>9} '
          f'{"numpy/":>7} {"compiled/":>9}')
    print(f'{"":>12} {"":>5} {"":>7} {"":>8} {"us":>8} {"":>8} {"call":>8} {"us":>8} {"":>7} '
          f'{"peer":>9} {"peer":>7} {"earlier":>9}')
    for name, count, row in rows:
        earlier = row.get('earlier', float('nan'))
        print(f'{name:>12} {count:>5} {row["peer"]:>7.3f} {earlier:>8.3f} '
              f'{row["earlier_outside_us"]:>8.1f} '
              f'{row["compiled"]:>8.3f} {row["inside"]:>8.3f} {row["outside_us"]:>8.1f} '
              f'{row["numpy"]:>7.3f} {row["compiled"] / row["peer"]:>9.2f} '
              f'{row["numpy"] / row["peer"]:>7.2f} {row["compiled"] / earlier:>9.2f}')
    if args.profile:
        name, ranges, angle_min, increment, noise = sets[2]
        numpy_profile(ranges, angle_min, increment, noise)
    worst_case(max(args.scans // 10, 5))


if __name__ == '__main__':
    main()
