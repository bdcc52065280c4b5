#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark process_bag: scans per second, --jobs over several bags, memory on a long bag.

Compares this tree with baselines (other checkouts of wctls_ros, built, e.g. an older commit
unpacked with ``git archive <commit> | tar -x -C ../old`` and ``make build`` there) in one
run, all measured alternately so that a busy machine slows them alike:

1. Throughput: the 360-scan Hokuyo URG-04LX office bag (ROS 2 mcap, 681 beams) from data/,
   processed by ``process()`` in a process of its own after a warm-up (no start-up cost), one
   method (wctls) and all four, markers on (the defaults); this tree with one job and with
   two worker processes. Median of the rounds, and the ratios to the baselines' medians;
   and how fast two CPU-bound processes run at once on this (shared) machine, which bounds
   what a second worker process can add.
2. Several bags: the installed command on two bags of 1,500 scans (the office scans over and
   over) and of ``--several-scans`` (default 6,000, ten minutes at 10 Hz), ``--jobs 1`` against
   ``--jobs 2``, wall time including start-up; and the start-up alone (the command on a
   one-scan bag), which no worker shares: with start-up S and one job's time T, two jobs can
   at best take S + (T - S) / 2, and that bound is printed too.
3. Memory: peak resident memory of the command on the 360-scan bag and on a 10,000-scan one;
   equal peaks mean the bag is streamed, not held.

Usage: python bench_process_bag.py [--baseline TREE]... [--rounds N] [--long-scans N]
       [--several-scans N]
"""

import argparse
import json
import os
import pathlib
import resource
import statistics
import subprocess
import sys
import tempfile
import time

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
OFFICE = REPOSITORY / 'data' / 'urg04lx_office'
WARM_UP = REPOSITORY / 'data' / 'sick_lms1xx_static'
START_NS = 1_700_000_000_000_000_000


def measure(methods: str, jobs: int, output: pathlib.Path) -> None:
    """Print the scans per second of one process() run on the office bag (after a warm-up)."""
    from wctls_ros.bags.process_bag import process
    from wctls_ros.core import METHODS
    from wctls_ros.params import load_parameters
    parameters = load_parameters(None)
    chosen = METHODS if methods == 'all' else (methods,)
    options = {'jobs': jobs} if jobs > 1 else {}        # a baseline may not know --jobs
    process(WARM_UP, output / 'warm-up', parameters, chosen, **options)
    cpu, started = cpu_seconds(), time.perf_counter()
    summary = process(OFFICE, output / 'office', parameters, chosen, **options)
    wall = time.perf_counter() - started
    print(json.dumps([summary.scans / wall, 1000.0 * (cpu_seconds() - cpu) / summary.scans]))


def cpu_seconds() -> float:
    """Return the CPU time of this process and of its ended worker processes, s."""
    usages = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    return sum(usage.ru_utime + usage.ru_stime for usage in usages)


def in_tree(tree: pathlib.Path, command: list) -> list:
    """Return a shell command that runs ``command`` in the environment of a built tree."""
    quoted = ' '.join(f"'{part}'" for part in command)
    return ['bash', '-c', f'source {tree}/tools/env.sh && exec {quoted}']


def throughput(tree: pathlib.Path, methods: str, jobs: int, workdir: pathlib.Path) -> list:
    """Run :func:`measure` in a fresh process of a tree; return [scans/s, CPU ms per scan]."""
    with tempfile.TemporaryDirectory(dir=workdir) as output:
        result = subprocess.run(in_tree(tree, [sys.executable, __file__, '--measure', methods,
                                               str(jobs), output]),
                                capture_output=True, text=True, check=True)
    return json.loads(result.stdout.splitlines()[-1])


def write_long_bag(path: pathlib.Path, count: int) -> None:
    """Write ``count`` scans of the office bag over and over, 0.1 s apart, with their stamps."""
    from wctls_ros.bags import BagWriter, read_scans, typestore
    from wctls_ros.conversions import laser_scan, MessageTypes
    types = MessageTypes.from_typestore(typestore())
    scans = [laser_scan(record.scan, types) for record in read_scans(OFFICE)]
    with BagWriter(path) as bag:
        for index in range(count):
            scan = scans[index % len(scans)]
            log_ns = START_NS + index * 100_000_000
            scan.header.stamp.sec, scan.header.stamp.nanosec = divmod(log_ns, 1_000_000_000)
            bag.write('/scan', log_ns, scan)


def run_command(tree: pathlib.Path, arguments: list) -> tuple:
    """Run a tree's process_bag; return (peak resident memory in MB, wall time in s)."""
    started = time.perf_counter()
    command = tree / 'install' / 'wctls_ros' / 'lib' / 'wctls_ros' / 'process_bag'
    child = subprocess.Popen(in_tree(tree, [str(command), '--no-progress'] + arguments),
                             stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        sys.exit(f'process_bag {arguments} failed in {tree} with status {child.returncode}')
    return usage.ru_maxrss / 1024.0, time.perf_counter() - started


def parallel_efficiency() -> float:
    """Return how fast two CPU-bound processes run at once, each, against one alone (1: ideal)."""
    loop = [sys.executable, '-c', 'import time; t = time.perf_counter(); '
            'x = sum(range(3 * 10**7)); print(time.perf_counter() - t)']
    alone = float(subprocess.run(loop, capture_output=True, text=True, check=True).stdout)
    pair = [subprocess.Popen(loop, stdout=subprocess.PIPE, text=True) for _ in range(2)]
    together = max(float(process.communicate()[0]) for process in pair)
    return alone / together


def main():
    """Print the figures."""
    cli = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    cli.add_argument('--baseline', type=pathlib.Path, action='append', default=[],
                     help='a built wctls_ros tree to compare with (repeat for several; '
                          'default: none)')
    cli.add_argument('--rounds', type=int, default=5, help='alternating rounds (default: 5)')
    cli.add_argument('--long-scans', type=int, default=10000,
                     help='scans of the long bag for the memory figure; 0 skips it '
                          '(default: 10000)')
    cli.add_argument('--several-scans', type=int, default=6000,
                     help='scans of each of the two longer bags of the --jobs figure, beside '
                          'two of 1500 (default: 6000)')
    cli.add_argument('--measure', nargs=3, metavar=('METHODS', 'JOBS', 'OUTPUT'),
                     help=argparse.SUPPRESS)
    args = cli.parse_args()
    if args.measure:
        methods, jobs, output = args.measure
        return measure(methods, int(jobs), pathlib.Path(output))
    trees = [(tree.resolve().name, tree) for tree in args.baseline]
    trees.append(('this tree', REPOSITORY))
    cases = [(label, tree, methods, jobs) for label, tree in trees
             for jobs in ((1,) if tree != REPOSITORY else (1, 2)) for methods in ('wctls', 'all')]
    with tempfile.TemporaryDirectory() as folder:
        workdir = pathlib.Path(folder)
        efficiency = [parallel_efficiency()]
        rates = {case: [] for case in cases}
        for _ in range(args.rounds):
            for case in cases:
                label, tree, methods, jobs = case
                rates[case].append(throughput(tree, methods, jobs, workdir))
        efficiency.append(parallel_efficiency())
        print(f'process_bag on {OFFICE.name} (360 scans, ROS 2 mcap, Hokuyo URG-04LX, 681 '
              f'beams), markers on, in-process after a warm-up; median of {args.rounds} '
              f'alternating rounds on {os.cpu_count()} CPUs (CPU: all processes of the run):')
        medians = {case: statistics.median(rate for rate, _ in rates[case]) for case in cases}
        for case in cases:
            label, tree, methods, jobs = case
            speeds = [rate for rate, _ in rates[case]]
            cpu = statistics.median(ms for _, ms in rates[case])
            ratios = ', '.join(f'{medians[case] / medians[(base, base_tree, methods, 1)]:.2f}x '
                               f'{base}' for base, base_tree in trees[:-1])
            print(f'  {label:10s} {"method wctls" if methods == "wctls" else "all four":12s} '
                  f'--jobs {jobs}  {medians[case]:5.0f} scans/s ({min(speeds):4.0f}-'
                  f'{max(speeds):4.0f}), CPU {cpu:5.2f} ms/scan  {ratios}')
        print('  two CPU-bound processes at once ran at '
              + ' and '.join(f'{100 * e:.0f} %' for e in efficiency)
              + ' of the speed of one alone (before and after): what a second process can add')

        sizes = (1500, args.several_scans)
        bags = {size: [workdir / f'{size}-{name}' for name in ('first', 'second')]
                for size in sizes}
        for size, pair in bags.items():
            for bag in pair:
                write_long_bag(bag, size)
        write_long_bag(workdir / 'one-scan', 1)
        times = {(size, jobs): [] for size in sizes for jobs in (1, 2)}
        start_up = []
        for round_number in range(args.rounds):
            start_up.append(run_command(REPOSITORY, [str(workdir / 'one-scan'), '-o', str(
                workdir / f'one-scan-{round_number}'), '-j', '1'])[1])
            for size, jobs in times:
                out = workdir / f'jobs{jobs}-{size}-{round_number}'
                times[(size, jobs)].append(run_command(REPOSITORY, [
                    str(b) for b in bags[size]] + ['-d', str(out), '-j', str(jobs)])[1])
        start = statistics.median(start_up)
        print(f'this tree, two office bags, whole command (start-up included), median of '
              f'{args.rounds}; start-up (a one-scan bag) {start:.2f} s:')
        for size in sizes:
            one, two = statistics.median(times[(size, 1)]), statistics.median(times[(size, 2)])
            bound = one / (start + (one - start) / 2)
            print(f'  {size:6d} scans each: --jobs 1 {one:5.1f} s, --jobs 2 {two:5.1f} s: '
                  f'{one / two:.2f}x (at best {bound:.2f}x with this start-up)')

        if args.long_scans <= 0:
            return None
        write_long_bag(workdir / 'long', args.long_scans)
        print('peak resident memory of the command (default --jobs), short bag and long bag:')
        for label, tree in trees:
            short_mb, short_s = run_command(tree, [str(OFFICE), '-o',
                                                   str(workdir / f'{label}-short')])
            long_mb, long_s = run_command(tree, [str(workdir / 'long'), '-o',
                                                 str(workdir / f'{label}-long')])
            print(f'  {label:10s}   360 scans: {short_mb:6.1f} MB in {short_s:5.1f} s; '
                  f'{args.long_scans} scans: {long_mb:6.1f} MB in {long_s:5.1f} s')
    return None


if __name__ == '__main__':
    main()
