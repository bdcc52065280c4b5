#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark feature_node's message path and end-to-end latency, against baselines in one run.

Scans: 1080-beam full turns of simulated environment A (10 mm range noise), 50 different ones
over and over; the node runs with its defaults (all methods' outputs, markers without text ids)
and ``range_sigma_m: 0.01``. Trees (this one and each ``--baseline``, a built wctls_ros
checkout) are measured alternately, round after round, so that a busy machine slows them alike.

1. Message path, in one process per tree and case: feature_node's own scan callback, fed the
   scans as the executor feeds it (deserialised from CDR, timed too), paced at 50 Hz, its
   outputs received by a listener process that subscribes corners and lines, and markers or
   not. The core, extract_features, is timed inside the callback (this benchmark wraps it);
   the message path is everything else. Printed: the core's median, and the message path as a
   ratio to the core (their sums over the scans), median of the rounds; with baselines, also
   this tree's message path over each tree's core (mean time per scan), since the message path's
   targets were set against the numpy core of its day (e.g. ``--baseline`` a build of 0109046).
   Next to them the path's floor, measured the same way: a callback that only publishes an
   empty CornerArray and LineSegmentArray for each scan (deserialising it included), i.e. what
   rclpy takes for the scan in and two messages out, whatever is built.
2. End to end: the tree's installed feature_node as its own process; this process publishes
   the scans at 10 Hz and at 40 Hz (reliable, like sllidar_ros2), subscribes all three outputs
   and takes latency = CornerArray received - the scan's stamp (its publish time), both when
   its bytes arrive and when rclpy has decoded them (the listener's own work, which grows with
   the corners). Next to the floor: a node (in its own process) that receives the same scans
   and publishes an empty CornerArray each, i.e. what an rclpy executor hop costs. Printed per
   rate: median and p99 latency, scans without a CornerArray (dropped), and the median over
   (core + floor), arrived and decoded.

Usage: python bench_feature_node.py [--baseline TREE]... [--rounds N] [--path-scans N]
       [--seconds S]
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import threading
import time

import numpy as np

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
RATES_HZ = (10.0, 40.0)
PATH_RATE_HZ = 50.0
NODE_ARGUMENTS = ['--ros-args', '-p', 'range_sigma_m:=0.01', '--log-level', 'warn']
WARM_UP_SCANS = 20
DISCOVERY_TIMEOUT_S = 30.0


def scan_messages(count=50, beams=1080):
    """Return ``count`` different simulated LaserScans of environment A (10 mm range noise)."""
    from sensor_msgs.msg import LaserScan
    from wctls_lab.simulation import (full_turn_bearings, load_floor_plan, NoiseModel,
                                      simulate_ranges)
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


def in_tree(tree: pathlib.Path, command: list) -> list:
    """Return a shell command that runs ``command`` in the environment of a built tree."""
    quoted = ' '.join(f"'{part}'" for part in command)
    return ['bash', '-c', f'source {tree}/tools/env.sh && exec {quoted}']


def wait_until(predicate, timeout_s=DISCOVERY_TIMEOUT_S, what='discovery'):
    """Poll ``predicate`` until it holds; exit with a message when it never does."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            sys.exit(f'bench_feature_node: timed out waiting for {what}')
        time.sleep(0.05)


# --- 1. the message path, in the process of one tree ------------------------------------------

def listen(markers: bool) -> None:
    """Run a listener of the node's outputs until stdin closes (a process of its own)."""
    import rclpy
    from rclpy.node import Node
    from visualization_msgs.msg import MarkerArray
    from wctls_msgs.msg import CornerArray, LineSegmentArray
    rclpy.init()
    node = Node('feature_node_listener')
    topics = [('corners', CornerArray), ('lines', LineSegmentArray)]
    topics += [('markers', MarkerArray)] if markers else []
    for topic, kind in topics:
        node.create_subscription(kind, topic, lambda message: None, 10)
    threading.Thread(target=rclpy.spin, args=(node,), daemon=True).start()
    sys.stdin.read()


# The stages of the callback that are timed, by the function that does each (module,
# attribute) and by the publisher's topic; what is left of the callback is 'rest'.
BUILDERS = (('wctls_ros.conversions', 'extract_features', 'extract_features'),
            ('wctls_ros.feature_node', 'corner_array', 'build corners'),
            ('wctls_ros.feature_node', 'line_segment_array', 'build lines'),
            ('wctls_ros.feature_node', 'marker_array', 'build markers'))
STAGES = ('deserialize', 'extract_features', 'build corners', 'build lines', 'build markers',
          'publish corners', 'publish lines', 'publish markers', 'rest')


def empty_outputs_node(name: str, lines: bool):
    """
    Return a node that answers each scan with an empty CornerArray (and LineSegmentArray).

    The floor of both measurements: what rclpy takes for a scan in and empty messages out.

    :param name: the node's name
    :param lines: also publish an empty LineSegmentArray on ``lines``, as feature_node does
    :return: the node
    """
    from rclpy.node import Node
    from sensor_msgs.msg import LaserScan
    from wctls_msgs.msg import CornerArray, LineSegmentArray
    from wctls_ros.feature_node import SCAN_QOS
    node = Node(name)
    corners = node.create_publisher(CornerArray, 'corners', 10)
    line_publisher = node.create_publisher(LineSegmentArray, 'lines', 10) if lines else None

    def on_scan(scan, info=None):         # info: measure_path passes it, as to feature_node's
        corners.publish(CornerArray(header=scan.header, method='none'))
        if line_publisher is not None:
            line_publisher.publish(LineSegmentArray(header=scan.header, method='none'))
    node.create_subscription(LaserScan, 'scan', on_scan, SCAN_QOS)
    return node


def measure_path(markers: bool, count: int, floor: bool = False) -> None:
    """
    Print the seconds of each stage of feature_node's callback, per scan, as JSON.

    :param markers: whether the listener subscribes the markers
    :param count: scans measured (after :data:`WARM_UP_SCANS`)
    :param floor: measure the callback of :func:`empty_outputs_node` (named and wired as
        feature_node) instead of feature_node's
    """
    import importlib
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.publisher import Publisher
    from rclpy.serialization import deserialize_message, serialize_message
    from rosbags.typesys.store import Typestore
    from sensor_msgs.msg import LaserScan
    from wctls_ros.feature_node import FeatureNode

    seconds = {}                              # stage -> seconds in the current scan

    def timed(function, stage_of):
        def run(*args, **kwargs):
            started = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                stage = stage_of(*args)
                seconds[stage] = seconds.get(stage, 0.0) + time.perf_counter() - started
        return run
    for module_name, attribute, stage in BUILDERS:
        module = importlib.import_module(module_name)
        setattr(module, attribute, timed(getattr(module, attribute),
                                         lambda *args, stage=stage: stage))
    Publisher.publish = timed(Publisher.publish, lambda publisher, message:
                              'publish ' + publisher.topic_name.rsplit('/', 1)[1])
    # A node that takes the scan's CDR bytes (raw) decodes it in its callback, with rosbags.
    Typestore.deserialize_cdr = timed(Typestore.deserialize_cdr, lambda *args: 'deserialize')

    rclpy.init()
    node = empty_outputs_node('feature_node', lines=True) if floor else FeatureNode(
        parameter_overrides=[Parameter('range_sigma_m', value=0.01)])
    listener = subprocess.Popen([sys.executable, __file__, '--listen', str(int(markers))],
                                stdin=subprocess.PIPE)
    try:
        wait_until(lambda: node.count_subscribers('corners') and node.count_subscribers('lines')
                   and bool(node.count_subscribers('markers')) == markers)
        time.sleep(1.0)                       # let discovery settle both ways
        subscription = next(s for s in node.subscriptions if s.topic_name.endswith('/scan'))
        scans = [serialize_message(scan) for scan in scan_messages()]
        period = 1.0 / PATH_RATE_HZ
        stages = {stage: [] for stage in STAGES}
        start = time.monotonic()
        for index in range(WARM_UP_SCANS + count):
            time.sleep(max(0.0, start + index * period - time.monotonic()))
            data = scans[index % len(scans)]
            seconds.clear()
            started = time.perf_counter()
            if not subscription.raw:          # what rclpy's executor does before the callback
                data = deserialize_message(data, LaserScan)
                seconds['deserialize'] = time.perf_counter() - started
            subscription.callback(data, {'publication_sequence_number': index + 1,
                                         'reception_sequence_number': index + 1})
            total = time.perf_counter() - started
            if index >= WARM_UP_SCANS:
                for stage in STAGES[:-1]:
                    stages[stage].append(seconds.get(stage, 0.0))
                stages['rest'].append(total - sum(seconds.values()))
        if not floor and node.counters.processed != WARM_UP_SCANS + count:
            sys.exit(f'feature_node processed {node.counters.processed} scans')
    finally:
        listener.stdin.close()
        listener.wait(timeout=10)
        node.destroy_node()
        rclpy.try_shutdown()
    print(json.dumps(stages))


def message_path(tree: pathlib.Path, markers: bool, count: int, floor: bool = False) -> dict:
    """Run :func:`measure_path` in a fresh process of a tree; return stage -> seconds array."""
    result = subprocess.run(in_tree(tree, [sys.executable, __file__, '--measure-path',
                                           str(int(markers)), str(count), str(int(floor))]),
                            capture_output=True, text=True, env=_path_environment())
    if result.returncode != 0:
        sys.exit(f'the message path measurement failed in {tree}:\n{result.stderr}')
    return {stage: np.array(values)
            for stage, values in json.loads(result.stdout.splitlines()[-1]).items()}


# --- 2. end to end ------------------------------------------------------------------------------

def floor_node() -> None:
    """Run the floor: receive each scan and publish an empty CornerArray with its header."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    rclpy.init()
    node = empty_outputs_node('floor_node', lines=False)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):     # terminated: rclpy's handler
        pass


class Peer:
    """This process's side: publishes scans, receives all three outputs of the node."""

    def __init__(self):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        rclpy.init()
        self.node = Node('feature_node_benchmark')
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.spinner = threading.Thread(target=self._spin, daemon=True)
        self.spinner.start()
        self.scans = scan_messages()

    def _spin(self):
        from rclpy.executors import ExternalShutdownException
        try:
            self.executor.spin()
        except ExternalShutdownException:
            pass

    def run(self, rate_hz: float, count: int) -> tuple:
        """
        Publish ``count`` scans at ``rate_hz`` (after a few to warm up), stamped when published.

        :return: latencies (s) of the CornerArrays received, shape (K, 2): when their bytes
            arrived and when rclpy had decoded them; scans without one
        """
        from rclpy.serialization import deserialize_message
        from sensor_msgs.msg import LaserScan
        from visualization_msgs.msg import MarkerArray
        from wctls_msgs.msg import CornerArray, LineSegmentArray
        node = self.node
        publisher = node.create_publisher(LaserScan, 'scan', 10)
        latencies = {}

        # Taken as bytes, so that arrival is told apart from the listener's own decoding: rclpy
        # takes 0.29 ms to decode a 17-corner CornerArray into Python objects (in a loop, on
        # the development VM), 7 us for the floor's empty one.
        def on_corners(data):
            arrived = time.time_ns()
            message = deserialize_message(data, CornerArray)
            decoded = time.time_ns()
            stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
            latencies[stamp] = (arrived - stamp, decoded - stamp)
        subscriptions = [node.create_subscription(CornerArray, 'corners', on_corners, 100,
                                                  raw=True)]
        subscriptions += [node.create_subscription(kind, topic, lambda message: None, 100)
                          for topic, kind in (('lines', LineSegmentArray),
                                              ('markers', MarkerArray))]
        wait_until(lambda: publisher.get_subscription_count() > 0
                   and node.count_publishers('corners') > 0)
        time.sleep(1.0)                       # let discovery settle both ways
        sent = []
        period = 1.0 / rate_hz
        start = time.monotonic()
        for index in range(WARM_UP_SCANS + count):
            time.sleep(max(0.0, start + index * period - time.monotonic()))
            scan = self.scans[index % len(self.scans)]
            now = time.time_ns()
            scan.header.stamp.sec, scan.header.stamp.nanosec = divmod(now, 1_000_000_000)
            publisher.publish(scan)
            if index >= WARM_UP_SCANS:
                sent.append(now)
        time.sleep(1.0)                       # the last scans' outputs
        for subscription in subscriptions:
            node.destroy_subscription(subscription)
        node.destroy_publisher(publisher)
        received = np.array([latencies[stamp] for stamp in sent if stamp in latencies],
                            dtype=float).reshape(-1, 2) * 1e-9
        return received, len(sent) - len(received)

    def close(self):
        """Stop spinning and shut rclpy down."""
        import rclpy
        # Join the spinning thread before rclpy goes: a thread still in spin() at exit aborts
        # the process ("terminate called without an active exception").
        self.executor.shutdown()
        self.spinner.join(timeout=10.0)
        self.node.destroy_node()
        rclpy.try_shutdown()


def end_to_end(peer: Peer, command: list, counts: dict) -> dict:
    """Start a node process, measure every rate; return rate -> (latencies s, dropped)."""
    process = subprocess.Popen(command)
    try:
        return {rate: peer.run(rate, counts[rate]) for rate in RATES_HZ}
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            # Seen once with the floor node (2026-11-26): its main thread stayed in rcl_wait
            # after SIGTERM, woken only when gdb attached. Its figures are complete by then.
            print(f'{" ".join(command)[-60:]} did not end within 20 s of SIGTERM: killed',
                  file=sys.stderr)
            process.kill()
            process.wait()


def _path_environment() -> dict:
    """Return the environment of a message path measurement: a ROS domain of its own."""
    return dict(os.environ, ROS_DOMAIN_ID=str(int(os.environ['ROS_DOMAIN_ID']) + 1))


def main():
    """Print the figures."""
    cli = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    cli.add_argument('--baseline', type=pathlib.Path, action='append', default=[],
                     help='a built wctls_ros tree to compare with (repeat for several)')
    cli.add_argument('--rounds', type=int, default=3, help='alternating rounds (default: 3)')
    cli.add_argument('--path-scans', type=int, default=400,
                     help='scans through the callback per tree, case and round (default: 400)')
    cli.add_argument('--seconds', type=float, default=30.0,
                     help='seconds of scans per rate, node and round (default: 30)')
    cli.add_argument('--listen', type=int, help=argparse.SUPPRESS)
    cli.add_argument('--measure-path', nargs=3, type=int, help=argparse.SUPPRESS)
    cli.add_argument('--floor-node', action='store_true', help=argparse.SUPPRESS)
    args = cli.parse_args()
    if args.listen is not None:
        return listen(bool(args.listen))
    if args.measure_path:
        markers, count, floor = args.measure_path
        return measure_path(bool(markers), count, bool(floor))
    if args.floor_node:
        return floor_node()

    os.environ.setdefault('ROS_DOMAIN_ID', str(150 + 2 * (os.getpid() % 40)))
    trees = [(tree.resolve().name, tree.resolve()) for tree in args.baseline]
    trees.append(('this tree', REPOSITORY))
    counts = {rate: int(rate * args.seconds) for rate in RATES_HZ}
    nodes = [('floor', [sys.executable, __file__, '--floor-node'])]
    nodes += [(label, in_tree(tree, [str(tree / 'install' / 'wctls_ros' / 'lib' / 'wctls_ros'
                                         / 'feature_node')] + NODE_ARGUMENTS))
              for label, tree in trees]
    cores = {label: [] for label, _ in trees}
    core_means = {label: [] for label, _ in trees}         # s per scan, per round and case
    path_means = {(label, markers): [] for label, _ in trees for markers in (True, False)}
    # (tree, markers subscribed) -> per round: stage -> its sum over the scans / the core's
    shares = {(label, markers): [] for label, _ in trees for markers in (True, False)}
    floor_means = []                                       # s per scan, per round
    latencies = {(label, rate): [] for label, _ in nodes for rate in RATES_HZ}
    dropped = {(label, rate): 0 for label, _ in nodes for rate in RATES_HZ}
    peer = Peer()
    try:
        for _ in range(args.rounds):
            floor_means.append(sum(values.mean() for values in message_path(
                REPOSITORY, False, args.path_scans, floor=True).values()))
            for label, tree in trees:
                for markers in (True, False):
                    stages = message_path(tree, markers, args.path_scans)
                    core = stages['extract_features']
                    cores[label].append(np.median(core))
                    core_means[label].append(core.mean())
                    path_means[(label, markers)].append(
                        sum(values.mean() for values in stages.values()) - core.mean())
                    shares[(label, markers)].append(
                        {stage: values.sum() / core.sum() for stage, values in stages.items()})
            for label, command in nodes:
                for rate, (seconds, lost) in end_to_end(peer, command, counts).items():
                    latencies[(label, rate)].append(seconds)
                    dropped[(label, rate)] += lost
    finally:
        peer.close()

    print(f'feature_node on {os.cpu_count()} CPUs, 1080-beam scans of environment A; '
          f'{args.rounds} alternating rounds, medians of the rounds.')
    print(f'1. message path = callback (deserialising the scan included) - extract_features, '
          f'{args.path_scans} scans per round at {PATH_RATE_HZ:.0f} Hz, as a ratio of '
          'extract_features (sums over the scans):')
    print(f'   {"tree":12s} {"core ms":>8s} {"markers subscribed":>19s} '
          f'{"without markers":>16s}')
    for label, _ in trees:
        path = {markers: statistics.median(sum(share.values()) - share['extract_features']
                                           for share in shares[(label, markers)])
                for markers in (True, False)}
        print(f'   {label:12s} {1e3 * statistics.median(cores[label]):8.3f} '
              f'{path[True]:18.2f}x {path[False]:15.2f}x')
    # The message path's targets were set against the core of its day (a baseline's numpy core):
    # this tree's message path in ms over each tree's core time, same scans, same run; and
    # the floor's (no markers to publish, so one column).
    this = trees[-1][0]
    path = {markers: statistics.median(path_means[(this, markers)]) for markers in (True, False)}
    floor_path = statistics.median(floor_means)
    print(f"   this tree's message path ({1e3 * path[True]:.3f} / {1e3 * path[False]:.3f} ms) "
          f'and its floor (deserialise, publish an empty CornerArray and LineSegmentArray: '
          f'{1e3 * floor_path:.3f} ms), mean per scan, over the core of each tree:')
    print(f'   {"tree":12s} {"core ms":>8s} {"markers subscribed":>19s} '
          f'{"without markers":>16s} {"floor":>8s}')
    for label, _ in trees:
        core = statistics.median(core_means[label])
        print(f'   {label:12s} {1e3 * core:8.3f} {path[True] / core:18.2f}x '
              f'{path[False] / core:15.2f}x {floor_path / core:7.2f}x')
    print('   each stage, markers subscribed ("rest": scan checks, headers, serialising outside '
          'publish, counting):')
    print(f'   {"stage":18s}' + ''.join(f'{label:>14s}' for label, _ in trees))
    for stage in STAGES:
        print(f'   {stage:18s}' + ''.join(
            f'{statistics.median(share[stage] for share in shares[(label, True)]):13.2f}x'
            for label, _ in trees))
    floor = {rate: np.median(np.concatenate(latencies[('floor', rate)]), axis=0)
             for rate in RATES_HZ}
    print(f'2. end to end: scan published -> CornerArray received, all three outputs '
          f'subscribed, {args.seconds:.0f} s per rate and round; "arrived": its bytes reached '
          'the listener, "decoded": rclpy has made it a Python message there:')
    print(f'   {"node":12s} {"rate Hz":>7s} {"received":>9s} {"dropped":>8s} '
          f'{"arrived: median ms":>19s} {"p99 ms":>7s} {"/ (core + floor)":>17s} '
          f'{"decoded: median ms":>19s} {"/ (core + floor)":>17s}')
    for label, _ in nodes:
        for rate in RATES_HZ:
            seconds = np.concatenate(latencies[(label, rate)])
            median = np.median(seconds, axis=0)
            ratios = ['', ''] if label == 'floor' else [
                f'{median[k] / (statistics.median(cores[label]) + floor[rate][k]):.2f}'
                for k in range(2)]
            print(f'   {label:12s} {rate:7.0f} {len(seconds):9d} {dropped[(label, rate)]:8d} '
                  f'{1e3 * median[0]:19.2f} {1e3 * np.percentile(seconds[:, 0], 99):7.2f} '
                  f'{ratios[0]:>17s} {1e3 * median[1]:19.2f} {ratios[1]:>17s}')
    return None


if __name__ == '__main__':
    main()
