# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
process_bag: LaserScans of a bag in; corners, lines and markers out, with no middleware.

Reads a ROS 2 (sqlite3, mcap) or ROS 1 bag one scan at a time, runs feature_node's pipeline on
every scan with the same parameters (a feature_node YAML file) and writes, with rosbags alone
(neither rclpy nor any ROS message package is imported):

- an mcap ROS 2 bag (Foxglove and ``ros2 bag play`` open it) with the original scans on their
  topic and, per scan, a wctls_msgs/CornerArray on ``/corners``, a wctls_msgs/LineSegmentArray
  on ``/lines`` and a visualization_msgs/MarkerArray on ``/markers``, each with the scan's
  header and log time; with ``--method all`` every method on its own topics
  (``/corners/wctls``, ...);
- ``corners.csv`` (one row per corner) and ``corners.json`` (one entry per scan) inside the bag
  folder.

Memory stays constant however long the bag is, and the output appears only when complete.
"""

import argparse
import contextlib
import csv
from dataclasses import dataclass, field
import json
import math
import os
import pathlib
import signal
import sys
import time
from typing import Callable, Optional


from .bag_io import bag_info, BagError, BagWriter, choose_scan_topic, read_scans, typestore
from ..conversions import (corner_array, laser_scan, line_segment_array, marker_array,
                           MessageTypes, scan_features)
from ..core import CornerSet, METHODS
from ..params import ConfigError, feature_settings, load_parameters

ALL = 'all'
CSV_NAME = 'corners.csv'
JSON_NAME = 'corners.json'
# Every output folder holds this file, which lists the files process_bag wrote there: --force
# replaces a folder only when it holds this file and nothing else than the files it lists.
MARKER_NAME = '.process_bag'
CSV_COLUMNS = ('scan', 'stamp', 'frame_id', 'method', 'index', 'x_m', 'y_m', 'yaw_rad',
               'var_x_m2', 'cov_xy_m2', 'cov_x_yaw_m_rad', 'var_y_m2', 'cov_y_yaw_m_rad',
               'var_yaw_rad2', 'opening_angle_rad', 'first_line', 'second_line')
# Upper triangle of the (x, y, yaw) covariance, in the order of the CSV columns.
_TRIANGLE = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
# A progress bar appears only on runs longer than this, s.
PROGRESS_DELAY_S = 1.0


class Interrupted(Exception):
    """A run stopped by a signal (nothing of it is left)."""

    def __init__(self, signal_number: int):
        super().__init__(f'interrupted by {signal.Signals(signal_number).name}')
        self.signal_number = signal_number


class StopSignals:
    """
    While active, SIGINT and SIGTERM only ask the run to stop, which it does between two scans.

    A signal never lands inside a write, the cleanup or the rename that completes the output:
    the run ends either complete or with nothing left. Use as a context manager, and call
    :meth:`check` where stopping is safe.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.received = None
        self._previous = {}

    def _note(self, number, frame):
        self.received = self.received or number

    def __enter__(self) -> 'StopSignals':
        self._previous = {number: signal.signal(number, self._note) for number in self.SIGNALS}
        return self

    def __exit__(self, kind, value, traceback):
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        return False

    def check(self) -> None:
        """
        Raise :class:`Interrupted` when a signal has asked the run to stop.

        :raises Interrupted: after SIGINT or SIGTERM
        """
        if self.received is not None:
            raise Interrupted(self.received)


@dataclass
class Summary:
    """
    What one run wrote.

    :ivar output: the output bag folder
    :ivar topic: the LaserScan topic read
    :ivar scans: scans read and written
    :ivar malformed: scans whose features could not be extracted (written with no features)
    :ivar corners: method -> corners found in all scans
    :ivar segments: method -> segments found in all scans
    :ivar seconds: wall time of the run, s
    """

    output: pathlib.Path
    topic: str
    scans: int = 0
    malformed: int = 0
    corners: dict = field(default_factory=dict)
    segments: dict = field(default_factory=dict)
    seconds: float = 0.0


def output_topics(methods) -> dict:
    """
    Name the output topics of each method.

    :param methods: the methods run (one: plain names; several: one namespace per method)
    :return: method -> (corners topic, lines topic, markers topic)
    """
    if len(methods) == 1:
        return {methods[0]: ('/corners', '/lines', '/markers')}
    return {m: (f'/corners/{m}', f'/lines/{m}', f'/markers/{m}') for m in methods}


def _stamp(header) -> str:
    return f'{header.stamp.sec}.{header.stamp.nanosec:09d}'


def _finite(value: float):
    return value if math.isfinite(value) else None


def _corner_rows(corners: CornerSet):
    """Yield one dict per corner: position, yaw, covariance terms, opening angle, lines."""
    for i, corner in enumerate(corners):
        cov = corner.covariance
        yield {'index': i, 'x_m': float(corner.x_m), 'y_m': float(corner.y_m),
               'yaw_rad': float(corner.yaw_rad),
               **{name: _finite(float(cov[r, c])) for name, (r, c) in
                  zip(CSV_COLUMNS[8:14], _TRIANGLE)},
               'opening_angle_rad': float(corner.opening_angle_rad),
               'first_line': int(corner.first_segment), 'second_line': int(corner.second_segment)}


def _refuse_to_replace(output: pathlib.Path, bag, force: bool) -> None:
    """
    Refuse an output that exists, unless --force may replace it: a folder process_bag wrote.

    :param output: the output folder
    :param bag: the input bag
    :param force: --force was given
    :raises BagError: with the reason, when the output must not be written
    """
    target, source = output.resolve(), pathlib.Path(bag).resolve()
    if source == target or target in source.parents:
        raise BagError(f'the output {output} holds the input bag {bag}: choose another --output')
    if not output.exists() and not output.is_symlink():
        return
    if not force:
        raise BagError(f'{output} exists: refusing to overwrite it (--force replaces an '
                       'earlier output of process_bag)')
    marker = output / MARKER_NAME
    try:
        written = set(json.loads(marker.read_text())['files'])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise BagError(f'--force refused: {output} is not an output of process_bag (no readable '
                       f'{MARKER_NAME}): remove it yourself or choose another --output') from error
    others = sorted(path.name for path in output.iterdir() if path.name not in written)
    if others:
        raise BagError(f'--force refused: {output} holds files process_bag did not write '
                       f'({", ".join(others)}): remove them or choose another --output')


class _CornerTables:
    """Streams corners.csv and corners.json (an array written one scan at a time)."""

    def __init__(self, bag_writer: BagWriter, header: dict):
        self._paths = bag_writer.sidecar(CSV_NAME), bag_writer.sidecar(JSON_NAME)
        self._header = header
        self._first = True

    def __enter__(self) -> '_CornerTables':
        csv_path, json_path = self._paths
        with contextlib.ExitStack() as files:
            self._csv = csv.DictWriter(files.enter_context(csv_path.open('w', newline='')),
                                       CSV_COLUMNS)
            self._json = files.enter_context(json_path.open('w'))
            self._files = files.pop_all()
        self._csv.writeheader()
        head = json.dumps(self._header, indent=1)
        self._json.write(head[:head.rindex('}')].rstrip() + ',\n "scans": [')
        return self

    def add(self, index: int, log_time_ns: int, header, problems: list, features: dict):
        """Append one scan's corners for every method."""
        common = {'scan': index, 'stamp': _stamp(header), 'frame_id': header.frame_id}
        entry = {**common, 'log_time_ns': log_time_ns, 'problems': problems, 'corners': {}}
        for method, result in features.items():
            rows = list(_corner_rows(result.corners))
            self._csv.writerows({**common, 'method': method, **row} for row in rows)
            entry['corners'][method] = rows
        self._json.write(('\n  ' if self._first else ',\n  ') + json.dumps(entry))
        self._first = False

    def __exit__(self, kind, value, traceback):
        if kind is None:
            self._json.write('\n ]\n}\n')
            self._files.close()
        else:
            with contextlib.suppress(OSError):  # the files are thrown away; flushing may fail
                self._files.close()
        return False


def process(bag, output, parameters: dict, methods=None, topic: Optional[str] = None,
            progress: Optional[bool] = None, overwrite: bool = False,
            after_scan: Optional[Callable[[], None]] = None) -> Summary:
    """
    Extract features from every scan of a bag into an output bag with corner tables.

    :param bag: a ROS 2 bag (sqlite3 or mcap) or a ROS 1 bag
    :param output: the output bag folder (must not exist unless ``overwrite``)
    :param parameters: feature_node parameter values (see :func:`load_parameters`)
    :param methods: the methods to run (None: the ``method`` parameter)
    :param topic: the LaserScan topic (None: the bag's only one)
    :param progress: show a progress bar (None: on a terminal only, after a second)
    :param overwrite: replace an existing output once the new one is complete, if it is an
        output of process_bag with nothing added (its marker file says what it wrote)
    :param after_scan: called after each scan; whatever it raises (e.g. :class:`Interrupted`)
        ends the run and leaves nothing
    :return: counts and timing
    :raises BagError: for a missing, unreadable or damaged bag, or one without LaserScans, or
        an output that exists (without ``overwrite``, or that process_bag did not write)
    :raises ValueError: for parameters that make no valid configuration
    """
    from tqdm import tqdm
    started = time.perf_counter()
    config, style, publish_markers = feature_settings(parameters)
    methods = tuple(methods or (config.method,))
    configs = {m: config.replace(method=m) for m in methods}
    topics = output_topics(methods)
    types = MessageTypes.from_typestore(typestore())
    info = bag_info(bag)
    topic = choose_scan_topic(bag, topic, info)
    output = pathlib.Path(output)
    _refuse_to_replace(output, bag, overwrite)
    summary = Summary(output, topic, corners=dict.fromkeys(methods, 0),
                      segments=dict.fromkeys(methods, 0))
    with BagWriter(output, overwrite=overwrite) as writer:
        writer.sidecar(MARKER_NAME).write_text(json.dumps({
            'written_by': 'process_bag of wctls_ros',
            'files': [MARKER_NAME, f'{output.name}.mcap', 'metadata.yaml', CSV_NAME, JSON_NAME]}))
        tables = _CornerTables(writer, {'bag': str(bag), 'topic': topic, 'methods': methods,
                                        'parameters': parameters})
        bar = tqdm(total=info.topics[topic][1], unit='scan', desc=pathlib.Path(bag).name,
                   disable=None if progress is None else not progress, delay=PROGRESS_DELAY_S,
                   file=sys.stderr)
        with tables, contextlib.closing(bar):
            for index, record in enumerate(read_scans(bag, topic)):
                scan = laser_scan(record.scan, types)
                time_ns = record.timestamp_ns
                writer.write(topic, time_ns, scan)
                results, problems = {}, []
                for method, (corners, lines, markers) in topics.items():
                    features, problems = scan_features(scan, configs[method])
                    results[method] = features
                    writer.write(corners, time_ns, corner_array(features, scan.header, types))
                    writer.write(lines, time_ns,
                                 line_segment_array(features, scan.header, types))
                    if publish_markers:
                        writer.write(markers, time_ns,
                                     marker_array(features, scan.header, style, types))
                    summary.corners[method] += len(features.corners)
                    summary.segments[method] += len(features.segments)
                tables.add(index, time_ns, scan.header, problems, results)
                summary.scans += 1
                summary.malformed += bool(problems)
                bar.update()
                if after_scan is not None:
                    after_scan()
    summary.seconds = time.perf_counter() - started
    return summary


def default_output(bag) -> pathlib.Path:
    """
    Name the output of a bag when none is given: ``<bag name>_features`` here.

    :param bag: the input bag path
    :return: the output folder
    """
    path = pathlib.Path(bag)
    name = path.stem if path.suffix in ('.bag', '.mcap', '.db3') else path.name
    return pathlib.Path(f'{name}_features')


class _OneLineErrors(argparse.ArgumentParser):
    """An argument parser whose errors are one line (the usage is in --help)."""

    def error(self, message):
        """Exit 2 with ``process_bag: error: <message>``."""
        self.exit(2, f'{self.prog}: error: {message} (see --help)\n')


def parser() -> argparse.ArgumentParser:
    """
    Build the command line interface.

    :return: the argument parser
    """
    cli = _OneLineErrors(
        prog='process_bag',
        description='Extract corners and line segments with covariances from the LaserScans '
                    'of a ROS 1 or ROS 2 bag, without ROS middleware. Writes an mcap ROS 2 bag '
                    '(open it in Foxglove) with the scans, corners, lines and markers, plus '
                    f'{CSV_NAME} and {JSON_NAME} inside the bag folder.',
        epilog='Exit status: 0 done; 2 a user error (bad argument, path, bag, parameter file, '
               'unwritable output), with one line on stderr and nothing written; 130 stopped by '
               'SIGINT (Ctrl-C), 143 by SIGTERM, with nothing written.')
    cli.add_argument('bag', help='ROS 2 bag folder (or its .mcap / .db3 file) or ROS 1 .bag')
    cli.add_argument('-o', '--output', type=pathlib.Path,
                     help='output bag folder (default: <bag name>_features in the current '
                          'folder); must not exist unless --force')
    cli.add_argument('-m', '--method', choices=METHODS + (ALL,),
                     help='line fit whose covariances are propagated, or all four on their '
                          'own topics (/corners/<method>, ...); default: the method of the '
                          'config file, else wctls')
    cli.add_argument('-c', '--config', type=pathlib.Path,
                     help='feature_node parameter file (YAML, as for --ros-args --params-file; '
                          "default: none, feature_node's defaults)")
    cli.add_argument('-t', '--topic', help='LaserScan topic (default: the only one in the bag)')
    cli.add_argument('-f', '--force', action='store_true',
                     help='replace an existing output once the new one is complete; only an '
                          f'output of process_bag (its {MARKER_NAME} file) with no file added')
    cli.add_argument('--progress', action=argparse.BooleanOptionalAction, default=None,
                     help='show a progress bar (default: on a terminal, for runs over 1 s)')
    return cli


def _report(summary: Summary) -> str:
    lines = [f'wrote {summary.output}: {summary.scans} scans of {summary.topic} in '
             f'{summary.seconds:.1f} s ({summary.scans / max(summary.seconds, 1e-9):.0f} '
             f'scans/s), with {CSV_NAME} and {JSON_NAME}']
    for method in summary.corners:
        lines.append(f'  {method}: {summary.corners[method]} corners, '
                     f'{summary.segments[method]} segments')
    if summary.malformed:
        lines.append(f'  {summary.malformed} malformed scans kept without features')
    return '\n'.join(lines)


def main(argv=None) -> int:
    """
    Run the command line tool.

    :param argv: arguments (None: sys.argv[1:])
    :return: exit status: 0 done, 2 user error (nothing written), 128 + the signal number when
        stopped by SIGINT or SIGTERM (nothing written)
    """
    with StopSignals() as stop:
        args = parser().parse_args(argv)
        try:
            overrides = {} if args.method in (None, ALL) else {'method': args.method}
            parameters = load_parameters(args.config, overrides=overrides)
            try:
                feature_settings(parameters)
            except ValueError as error:
                raise ConfigError(str(error)) from error
            summary = process(args.bag, args.output or default_output(args.bag), parameters,
                              METHODS if args.method == ALL else None, args.topic,
                              args.progress, args.force, stop.check)
        except (BagError, ConfigError) as error:
            print(f'process_bag: error: {error}', file=sys.stderr)
            return 2
        except Interrupted as interruption:
            print(f'process_bag: {interruption}; nothing written', file=sys.stderr)
            return 128 + interruption.signal_number
    try:
        print(_report(summary), flush=True)
    except OSError as error:
        # Python flushes stdout again at exit: give it a file that takes the rest quietly.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        print(f'process_bag: error: cannot print the summary ({error.strerror}); the output '
              f'{summary.output} is complete', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
