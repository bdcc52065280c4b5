#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark process_bag: scans per second on the real office bag, and memory on a long bag.

1. Throughput: the 360-scan Hokuyo URG-04LX office bag (ROS 2 mcap, 681 beams) from
   data/, processed in this process (no start-up cost) with one method (wctls) and with
   all four; median of a few runs, markers on (the defaults).
2. Memory: a 10,000-scan bag (the office scans over and over, 0.1 s apart) processed by
   process_bag in a process of its own; its peak resident memory is compared with that of the
   same command on the 360-scan bag. Equal peaks mean the bag is streamed, not held.
Usage: python bench_process_bag.py [runs] [long bag scans] (defaults 3 and 10000; 0 skips 2).
"""

import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

from wctls_ros.bags import BagWriter, read_scans, typestore
from wctls_ros.bags.process_bag import process
from wctls_ros.conversions import laser_scan, MessageTypes
from wctls_ros.core import METHODS
from wctls_ros.params import load_parameters

OFFICE = pathlib.Path(__file__).resolve().parents[2] / 'data' / 'urg04lx_office'


def throughput(bag, methods, runs, workdir):
    """Return the median scans per second of `runs` in-process runs and the scan count."""
    parameters = load_parameters(None)
    rates = []
    for run in range(runs):
        started = time.perf_counter()
        summary = process(bag, workdir / f'{"-".join(methods)}-{run}', parameters, methods,
                          progress=False)
        rates.append(summary.scans / (time.perf_counter() - started))
    return statistics.median(rates), summary.scans


def write_long_bag(source, path, count):
    """Write `count` scans of `source` over and over, 0.1 s apart, with matching stamps."""
    types = MessageTypes.from_typestore(typestore())
    scans = [laser_scan(record.scan, types) for record in read_scans(source)]
    start_ns = 1_700_000_000_000_000_000
    with BagWriter(path) as bag:
        for index in range(count):
            scan = scans[index % len(scans)]
            log_ns = start_ns + index * 100_000_000
            scan.header.stamp.sec, scan.header.stamp.nanosec = divmod(log_ns, 1_000_000_000)
            bag.write('/scan', log_ns, scan)


def peak_memory_mb(bag, output):
    """Run process_bag in a new process on a bag; return (peak RSS in MB, wall time in s)."""
    started = time.perf_counter()
    child = subprocess.Popen([sys.executable, '-m', 'wctls_ros.bags.process_bag', str(bag),
                              '-o', str(output), '--no-progress'], stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        sys.exit(f'process_bag failed on {bag} with status {child.returncode}')
    return usage.ru_maxrss / 1024.0, time.perf_counter() - started


def main():
    """Print the figures."""
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    long_count = int(sys.argv[2]) if len(sys.argv) > 2 else 10000
    with tempfile.TemporaryDirectory() as folder:
        workdir = pathlib.Path(folder)
        print(f'process_bag on {OFFICE.name} (ROS 2 mcap, Hokuyo URG-04LX, 681 beams), '
              f'median of {runs} runs, markers on:')
        for methods in (('wctls',), METHODS):
            rate, scans = throughput(OFFICE, methods, runs, workdir)
            label = 'all four methods' if len(methods) > 1 else f'method {methods[0]}'
            print(f'  {label:18s} {rate:7.0f} scans/s  ({scans} scans, '
                  f'{rate * len(methods):.0f} scan-method pairs/s)')
        if long_count <= 0:
            return
        write_long_bag(OFFICE, workdir / 'long', long_count)
        short_mb, short_s = peak_memory_mb(OFFICE, workdir / 'short_out')
        long_mb, long_s = peak_memory_mb(workdir / 'long', workdir / 'long_out')
        print('process_bag (wctls) in its own process, peak resident memory:')
        print(f'  {scans:6d} scans: {short_mb:6.1f} MB in {short_s:5.1f} s')
        print(f'  {long_count:6d} scans: {long_mb:6.1f} MB in {long_s:5.1f} s '
              f'({long_count / long_s:.0f} scans/s with start-up)')


if __name__ == '__main__':
    main()
