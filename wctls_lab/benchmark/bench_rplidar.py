#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark rplidar_node against the S1 emulator (its own process) on a pseudo-terminal.

First, for DenseBoost and Standard on a clean link: the CPU time the node's reader thread
(reading, decoding, turn assembly and publishing) and the whole node process spend per second of
stream, and the delay from a turn's last byte to its LaserScan being published (median, p99).
Then DenseBoost with 0, 1 and 5 % of the streamed bytes corrupted, or dropped, and with 5 and
20 % of the capsules cut short at a random byte (runs of lost bytes), against the emulator's
noiseless scene: the turns published (of those the emulator streamed), the share of streamed
turns published with >= 80 % of their samples correct (within 1 cm of the range band of the
1080 beams' bins; each of a turn's 926 samples has a bin of its own), the correct and the
filled beams per published turn, the beams kept (correct beams of all the samples streamed),
the published beams wrong by more than 10 cm, and the CPU. Shares are of a turn's samples.
Usage: python bench_rplidar.py [seconds per run] (default 10).
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
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from wctls_rplidar.rplidar_node import RplidarNode

# The emulator harness and the scene oracle are the tests' own.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / 'wctls_rplidar' / 'test'))
from rplidar_testing import (compensated_beam_bands, EMULATOR_TURN_S,  # noqa: E402, I100
                             EMULATOR_TURN_SAMPLES, start_emulator)

WARM_UP_S = 1.5
FAULTS = (('clean', ()), ('1% corrupted', ('--corrupt-rate', '0.01')),
          ('5% corrupted', ('--corrupt-rate', '0.05')), ('1% dropped', ('--drop-rate', '0.01')),
          ('5% dropped', ('--drop-rate', '0.05')), ('5% cut short', ('--cut-rate', '0.05')),
          ('20% cut short', ('--cut-rate', '0.2')))
GOOD_TOLERANCE_M = 0.01
WRONG_M = 0.1
GOOD_TURN_SHARE = 0.8


def measure(link, seconds, scan_mode):
    """Run the node on ``link`` for ``seconds`` after a warm-up; return its figures."""
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = RplidarNode(context=context, use_global_arguments=False, parameter_overrides=[
        Parameter('serial_port', value=link), Parameter('scan_mode', value=scan_mode)])
    listener = rclpy.create_node('bench_listener', context=context)
    scans = []
    recording = threading.Event()
    listener.create_subscription(
        LaserScan, 'scan',
        lambda m: recording.is_set() and scans.append(np.array(m.ranges, np.float32)),
        qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(listener)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        time.sleep(WARM_UP_S)
        latencies = len(node.publish_latencies_s())
        reader, process, wall = node.driver.reader_cpu_s(), time.process_time(), time.monotonic()
        recording.set()
        time.sleep(seconds)
        recording.clear()
        wall = time.monotonic() - wall
        return {'reader_cpu': (node.driver.reader_cpu_s() - reader) / wall,
                'process_cpu': (time.process_time() - process) / wall,
                'latency_s': np.array(node.publish_latencies_s()[latencies:]),
                'scans': list(scans), 'wall_s': wall}
    finally:
        executor.shutdown()
        listener.destroy_node()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        spinner.join()


def beam_figures(scans, wall_s, bands):
    """Score the published 1080-beam scans against the scene; return the figures."""
    low, high = bands
    streamed = wall_s / EMULATOR_TURN_S
    ranges = np.array(scans).reshape(-1, 1080)
    filled = np.isfinite(ranges)
    good = filled & (ranges >= low - GOOD_TOLERANCE_M) & (ranges <= high + GOOD_TOLERANCE_M)
    wrong = filled & ((ranges < low - WRONG_M) | (ranges > high + WRONG_M))
    good_share = good.sum(axis=1) / EMULATOR_TURN_SAMPLES
    return {'published': len(ranges) / streamed,
            'good_turns': np.count_nonzero(good_share >= GOOD_TURN_SHARE) / streamed,
            'good': good_share.mean() if len(ranges) else 0.0,
            'filled': filled.sum(axis=1).mean() / EMULATOR_TURN_SAMPLES if len(ranges) else 0.0,
            'kept': good.sum() / (EMULATOR_TURN_SAMPLES * streamed),
            'wrong': int(wrong.sum()), 'filled_beams': int(filled.sum()), 'turns': len(ranges),
            'streamed': streamed}


def main():
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    bands = compensated_beam_bands()
    with tempfile.TemporaryDirectory() as directory:
        directory = pathlib.Path(directory)
        link = str(directory / 'ttyS1')
        print(f'rplidar_node on the S1 emulator (pseudo-terminal), {seconds:g} s per run')
        print(f'{"mode":>10} {"reader CPU":>11} {"process CPU":>12} {"turns/s":>8} '
              f'{"latency median":>15} {"p99":>8}')
        with start_emulator(directory):
            for mode in ('DenseBoost', 'Standard'):
                r = measure(link, seconds, mode)
                print(f'{mode:>10} {100 * r["reader_cpu"]:>10.2f}% '
                      f'{100 * r["process_cpu"]:>11.2f}% {len(r["scans"]) / r["wall_s"]:>8.2f} '
                      f'{1e3 * np.median(r["latency_s"]):>12.2f} ms '
                      f'{1e3 * np.percentile(r["latency_s"], 99):>5.2f} ms')
        print('(CPU in % of one core per second of stream; latency from the last byte of a '
              'turn to publish())')
        print(f'\nDenseBoost on a damaged link (noiseless scene; {GOOD_TOLERANCE_M * 100:g} cm '
              'of the range band = correct)')
        print(f'{"link":>13} {"published":>10} {">=80% ok":>9} {"correct":>8} {"filled":>7} '
              f'{"kept":>6} {">10cm wrong":>22} {"reader CPU":>11} {"process CPU":>12}')
        for name, options in FAULTS:
            with start_emulator(directory, *options):
                r = measure(link, seconds, 'DenseBoost')
            b = beam_figures(r['scans'], r['wall_s'], bands)
            wrong = f'{b["wrong"]} of {b["filled_beams"]}'
            print(f'{name:>13} {100 * b["published"]:>9.1f}% {100 * b["good_turns"]:>8.1f}% '
                  f'{100 * b["good"]:>7.1f}% {100 * b["filled"]:>6.1f}% {100 * b["kept"]:>5.1f}% '
                  f'{wrong:>13} {100 * b["wrong"] / max(b["filled_beams"], 1):>6.3f}% '
                  f'{100 * r["reader_cpu"]:>9.2f}% {100 * r["process_cpu"]:>11.2f}%')
        print('(published and >=80% ok: shares of the turns streamed; correct and filled: '
              'shares of the samples of the published turns; kept: correct beams of all the '
              'samples streamed; wrong: of the published (finite) beams)')


if __name__ == '__main__':
    main()
