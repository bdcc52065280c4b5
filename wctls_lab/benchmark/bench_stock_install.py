#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark what a stock install gets: the first CornerArray after a cold start, the message path.

1. Cold start: the installed feature_node started with an empty numba cache (the first start on
   a machine) while this process publishes a 1080-beam scan every 100 ms from the node's launch;
   the time from launching the process to the first CornerArray received, and the node's log
   lines with their times. ``WCTLS_ROS_CORE=numba`` compiles before the first scan (as every
   start did before the numpy fallback), ``auto`` answers with the numpy core while numba
   compiles in another process; with a warm cache for comparison. Alternating, ``--rounds``.
2. The message path with and without rosbags: feature_node's scan callback fed CDR bytes of the
   same scans in a fresh process each (rosbags hidden from the second), the compiled core in
   both; the callback's time minus the core's, median ms per scan, alternating processes.

Usage: python bench_stock_install.py [--rounds N] [--scans N]
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import threading
import time

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
SCAN_PERIOD_S = 0.1
COLD_START_TIMEOUT_S = 600.0
WARM_UP_SCANS = 20


def room_scans(count=20):
    """Return ``count`` simulated 1080-beam LaserScans of environment A (10 mm range noise)."""
    import numpy as np
    from sensor_msgs.msg import LaserScan
    from wctls_lab.simulation import (full_turn_bearings, load_floor_plan, NoiseModel,
                                      simulate_ranges)
    walls, _ = load_floor_plan('environment_a').in_sensor_frame()
    angle_min, increment, bearings = full_turn_bearings(1080)
    rng = np.random.default_rng(5)
    noise = NoiseModel(range_sigma_m=0.01, bearing_sigma_rad=0.0)
    scans = []
    for _ in range(count):
        scan = LaserScan(angle_min=angle_min, angle_max=angle_min + 1079 * increment,
                         angle_increment=increment, range_min=0.05, range_max=40.0)
        scan.header.frame_id = 'laser'
        scan.ranges = simulate_ranges(walls, bearings, noise, rng).astype(np.float32).tolist()
        scans.append(scan)
    return scans


def first_corner_array(core: str, cache: str) -> dict:
    """
    Launch feature_node and time its first CornerArray; return the seconds and its log lines.

    :param core: WCTLS_ROS_CORE for the node
    :param cache: NUMBA_CACHE_DIR for the node ('': the install's own cache, warm)
    """
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import LaserScan
    from wctls_msgs.msg import CornerArray

    rclpy.init()
    node = rclpy.create_node('cold_start_bench')
    arrived = threading.Event()
    node.create_subscription(CornerArray, 'corners', lambda message: arrived.set(), 10)
    publisher = node.create_publisher(LaserScan, 'scan', qos_profile_sensor_data)
    scans = room_scans()
    executable = REPOSITORY / 'install' / 'wctls_ros' / 'lib' / 'wctls_ros' / 'feature_node'
    environment = dict(os.environ, WCTLS_ROS_CORE=core)
    if cache:
        environment['NUMBA_CACHE_DIR'] = cache
    lines = []
    launched = time.monotonic()
    process = subprocess.Popen([str(executable), '--ros-args', '-p', 'range_sigma_m:=0.01'],
                               env=environment, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)

    def keep_lines():
        for line in process.stdout:
            lines.append((time.monotonic() - launched, line.strip()))
    reader = threading.Thread(target=keep_lines, daemon=True)
    reader.start()
    try:
        sent = 0
        while not arrived.is_set() and time.monotonic() - launched < COLD_START_TIMEOUT_S:
            publisher.publish(scans[sent % len(scans)])
            sent += 1
            deadline = time.monotonic() + SCAN_PERIOD_S
            while time.monotonic() < deadline and not arrived.is_set():
                rclpy.spin_once(node, timeout_sec=0.01)
        first = time.monotonic() - launched if arrived.is_set() else float('nan')
    finally:
        process.terminate()
        process.wait(timeout=30)
        reader.join(timeout=5)
        node.destroy_node()
        rclpy.try_shutdown()
    return {'first_s': first, 'lines': lines}


def measure_path(count: int) -> None:
    """Print the callback's and the core's ms per scan of feature_node's scan callback, as JSON."""
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message
    import wctls_ros.feature_node as feature_node_module
    from wctls_ros.feature_node import FeatureNode

    core_seconds = []
    extract = feature_node_module.scan_features

    def timed_extract(*args, **kwargs):
        started = time.perf_counter()
        try:
            return extract(*args, **kwargs)
        finally:
            core_seconds.append(time.perf_counter() - started)
    feature_node_module.scan_features = timed_extract
    rclpy.init()
    node = FeatureNode(parameter_overrides=[Parameter('range_sigma_m', value=0.01),
                                            Parameter('publish_markers', value=False)])
    try:
        subscription = next(s for s in node.subscriptions if s.topic_name.endswith('/scan'))
        scans = [serialize_message(scan) for scan in room_scans()]
        callback_seconds = []
        for index in range(WARM_UP_SCANS + count):
            started = time.perf_counter()
            subscription.callback(scans[index % len(scans)],
                                  {'publication_sequence_number': index + 1})
            callback_seconds.append(time.perf_counter() - started)
        types = 'rosbags' if sys.modules.get('rosbags') is not None else 'rclpy'
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    callback = callback_seconds[WARM_UP_SCANS:]
    core = core_seconds[WARM_UP_SCANS:]
    print(json.dumps({'types': types, 'callback_ms': 1e3 * statistics.median(callback),
                      'path_ms': 1e3 * statistics.median(
                          [c - k for c, k in zip(callback, core)])}))


HIDE_ROSBAGS = "import sys; sys.modules['rosbags'] = None; "


def message_path(count: int, rosbags: bool) -> dict:
    """Run :func:`measure_path` in a fresh process, rosbags hidden or not; return its figures."""
    code = ('' if rosbags else HIDE_ROSBAGS) + (
        f'import runpy, sys; sys.argv = [{str(__file__)!r}, "--measure-path", "{count}"]; '
        f'runpy.run_path({str(__file__)!r}, run_name="__main__")')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            env=dict(os.environ, WCTLS_ROS_CORE='numba'))
    if result.returncode != 0:
        sys.exit(f'the message path measurement failed:\n{result.stderr}')
    return json.loads(result.stdout.splitlines()[-1])


def main():
    """Print the figures."""
    cli = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    cli.add_argument('--rounds', type=int, default=2, help='alternating rounds (default: 2)')
    cli.add_argument('--scans', type=int, default=500,
                     help='scans through the callback per process (default: 500)')
    cli.add_argument('--measure-path', type=int, help=argparse.SUPPRESS)
    cli.add_argument('--first-corner-array', nargs=2, help=argparse.SUPPRESS)
    args = cli.parse_args()
    if args.measure_path:
        return measure_path(args.measure_path)
    if args.first_corner_array:
        return print(json.dumps(first_corner_array(*args.first_corner_array)))
    os.environ.setdefault('ROS_DOMAIN_ID', str(150 + 2 * (os.getpid() % 40)))

    print(f'1. cold start, feature_node on {os.cpu_count()} CPUs: launch -> first CornerArray '
          f'(a scan every {1e3 * SCAN_PERIOD_S:.0f} ms from the launch)')
    firsts = {}
    for _ in range(args.rounds):
        for label, core, cold in (('numba, cold cache (compile first)', 'numba', True),
                                  ('auto, cold cache (numpy meanwhile)', 'auto', True),
                                  ('auto, warm cache', 'auto', False)):
            with tempfile.TemporaryDirectory() as empty:
                result = json.loads(subprocess.run(
                    [sys.executable, __file__, '--first-corner-array', core,
                     empty if cold else ''], capture_output=True, text=True, check=True
                ).stdout.splitlines()[-1])
            firsts.setdefault(label, []).append(result['first_s'])
            print(f'   {label:36s} {result["first_s"]:7.2f} s; the node said:')
            for seconds, line in result['lines']:
                if 'feature pipeline' in line:
                    print(f'     {seconds:6.2f} s  {line[line.find("]", 30) + 2:]}')
    for label, values in firsts.items():
        print(f'   {label:36s} median {statistics.median(values):7.2f} s over {len(values)}')

    print(f'2. message path (callback - core), {args.scans} scans per process, compiled core, '
          'markers off, median ms per scan:')
    paths = {True: [], False: []}
    for _ in range(args.rounds):
        for rosbags in (True, False):
            paths[rosbags].append(message_path(args.scans, rosbags))
    for rosbags in (True, False):
        figures = paths[rosbags]
        print(f'   {"with rosbags" if rosbags else "without (rclpy)":16s} '
              f'decoded with {figures[0]["types"]:7s} path '
              f'{statistics.median(f["path_ms"] for f in figures):.3f} ms, callback '
              f'{statistics.median(f["callback_ms"] for f in figures):.3f} ms')
    return None


if __name__ == '__main__':
    main()
