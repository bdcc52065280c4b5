#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark rplidar_node against the S1 emulator (its own process) on a pseudo-terminal.

For DenseBoost and Standard, in one run each: the CPU time the node's reader thread (reading,
decoding, turn assembly and publishing) and the whole node process spend per second of stream,
and the delay from a turn's last byte to its LaserScan being published (median, p99). Then the
share of turns still published with 1% of the streamed bytes corrupted, or dropped (against the
clean run's turn rate).
Usage: python bench_rplidar.py [seconds per run]
"""

import pathlib
import sys
import tempfile
import threading
import time

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from wctls_ros.rplidar.emulator import EmulatorProcess
from wctls_ros.rplidar.rplidar_node import RplidarNode

WARM_UP_S = 1.5


def measure(link, seconds, scan_mode):
    """Run the node on ``link`` for ``seconds`` after a warm-up; return its figures."""
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = RplidarNode(context=context, use_global_arguments=False, parameter_overrides=[
        Parameter('serial_port', value=link), Parameter('scan_mode', value=scan_mode)])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        time.sleep(WARM_UP_S)
        turns, latencies = node.driver.status().turns, len(node.publish_latencies_s())
        reader, process, wall = node.driver.reader_cpu_s(), time.process_time(), time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - wall
        return {'reader_cpu': (node.driver.reader_cpu_s() - reader) / wall,
                'process_cpu': (time.process_time() - process) / wall,
                'latency_s': np.array(node.publish_latencies_s()[latencies:]),
                'turns': node.driver.status().turns - turns, 'wall_s': wall}
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        spinner.join()


def main():
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    with tempfile.TemporaryDirectory() as directory:
        link = str(pathlib.Path(directory) / 'ttyS1')
        print(f'rplidar_node on the S1 emulator (pseudo-terminal), {seconds:g} s per run')
        print(f'{"mode":>10} {"reader CPU":>11} {"process CPU":>12} {"turns/s":>8} '
              f'{"latency median":>15} {"p99":>8}')
        rates = {}
        with EmulatorProcess(['--link', link]):
            for mode in ('DenseBoost', 'Standard'):
                r = measure(link, seconds, mode)
                rates[mode] = r['turns'] / r['wall_s']
                print(f'{mode:>10} {100 * r["reader_cpu"]:>10.2f}% '
                      f'{100 * r["process_cpu"]:>11.2f}% {r["turns"] / r["wall_s"]:>8.2f} '
                      f'{1e3 * np.median(r["latency_s"]):>12.2f} ms '
                      f'{1e3 * np.percentile(r["latency_s"], 99):>5.2f} ms')
        print('(CPU in % of one core per second of stream; latency from the last byte of a '
              'turn to publish())')
        for fault, what in (('--corrupt-rate', 'corrupted'), ('--drop-rate', 'dropped')):
            with EmulatorProcess(['--link', link, fault, '0.01']):
                r = measure(link, seconds, 'DenseBoost')
            expected = rates['DenseBoost'] * r['wall_s']
            print(f'1% {what} bytes, DenseBoost: {r["turns"]} turns published of '
                  f'{expected:.1f} ({100 * r["turns"] / expected:.1f}%), reader CPU '
                  f'{100 * r["reader_cpu"]:.2f}%')


if __name__ == '__main__':
    main()
