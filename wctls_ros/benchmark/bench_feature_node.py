#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark feature_node end to end: LaserScan published here -> CornerArray received here.

The node runs as its own process (the installed executable, as `ros2 run` starts it); this
process publishes 1080-beam scans of the simulated room at a fixed rate (reliable QoS, like
sllidar_ros2) and receives the CornerArrays. Latency = receive time - the scan's header stamp
(set to the publish time). Prints median, p99 and drops per rate.
Usage: python bench_feature_node.py [scans per rate] (default 1000).
"""

import os
import pathlib
import subprocess
import sys
import threading
import time

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import LaserScan
from wctls_msgs.msg import CornerArray
from wctls_ros.simulation import (full_turn_bearings, load_floor_plan, NoiseModel,
                                  simulate_ranges)

RATES_HZ = (10.0, 40.0)


def scan_messages(count=50, beams=1080):
    """Return `count` different simulated scans of environment A (10 mm range noise)."""
    walls, _ = load_floor_plan('environment_a').in_sensor_frame()
    angle_min, increment, bearings = full_turn_bearings(beams)
    rng = np.random.default_rng(3)
    messages = []
    for _ in range(count):
        ranges = simulate_ranges(walls, bearings, NoiseModel(range_sigma_m=0.01), rng)
        scan = LaserScan(angle_min=angle_min, angle_max=angle_min + (beams - 1) * increment,
                         angle_increment=increment, scan_time=0.1, range_min=0.05,
                         range_max=40.0, ranges=ranges.astype(np.float32))
        scan.header.frame_id = 'laser'
        messages.append(scan)
    return messages


def feature_node_executable():
    """Find the installed feature_node (after `make build` and `source tools/env.sh`)."""
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        path = pathlib.Path(prefix) / 'lib' / 'wctls_ros' / 'feature_node'
        if path.is_file():
            return path
    sys.exit('feature_node is not installed: run `make build` and `source tools/env.sh`')


def run_rate(node, executor, scans, rate_hz, count):
    """Publish `count` scans at `rate_hz`; return latencies (s) of the CornerArrays received."""
    publisher = node.create_publisher(LaserScan, 'scan', 10)
    latencies = {}
    done = threading.Event()

    def on_corners(message):
        stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
        latencies[stamp] = time.time_ns() - stamp
        if len(latencies) >= count:
            done.set()
    subscription = node.create_subscription(CornerArray, 'corners', on_corners, 100)
    deadline = time.monotonic() + 20.0
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)                                   # let discovery settle both ways
    period = 1.0 / rate_hz
    start = time.monotonic()
    for i in range(count):
        time.sleep(max(0.0, start + i * period - time.monotonic()))
        scan = scans[i % len(scans)]
        now = time.time_ns()
        scan.header.stamp.sec, scan.header.stamp.nanosec = divmod(now, 1_000_000_000)
        publisher.publish(scan)
    done.wait(timeout=5.0)
    node.destroy_subscription(subscription)
    node.destroy_publisher(publisher)
    return np.array(list(latencies.values())) * 1e-9


def main():
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    os.environ.setdefault('ROS_DOMAIN_ID', str(150 + os.getpid() % 50))
    process = subprocess.Popen([str(feature_node_executable()), '--ros-args', '-p',
                                'range_sigma_m:=0.01', '--log-level', 'warn'])
    rclpy.init()
    node = Node('feature_node_benchmark')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        scans = scan_messages()
        print(f'feature_node end to end: {count} scans of 1080 beams per rate, '
              'reliable QoS, node in its own process')
        print(f'{"rate Hz":>8} {"received":>9} {"dropped":>8} {"median ms":>10} {"p99 ms":>8} '
              f'{"max ms":>8}')
        for rate in RATES_HZ:
            latency = run_rate(node, executor, scans, rate, count) * 1e3
            print(f'{rate:>8.0f} {len(latency):>9d} {count - len(latency):>8d} '
                  f'{np.median(latency):>10.2f} {np.percentile(latency, 99):>8.2f} '
                  f'{latency.max():>8.2f}')
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        process.terminate()
        process.wait(timeout=10)


if __name__ == '__main__':
    main()
