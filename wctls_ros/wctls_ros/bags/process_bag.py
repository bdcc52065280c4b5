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
  folder;
- with ``--tracks``, every scan's landmarks with their track ids (:mod:`.track_bag`): a
  wctls_msgs/LandmarkArray on ``/landmarks`` and ``landmarks.csv`` (one row per observation).
- with ``--dock``, the dock feature_node would publish (the ``dock_*`` parameters of the config
  file, else the example dock of docs/docking.md) on ``/detected_dock_pose`` and
  ``/detected_dock_pose_with_covariance``, and ``dock.csv`` (one row per dock pose) beside
  ``corners.csv``.
- with ``--odometry``, the odometry from the features: nav_msgs/Odometry on ``/odom`` and
  ``odometry.csv`` (:mod:`.odometry_table`).

Memory stays constant however long the bag is, and the output appears only when complete.
"""

import argparse
import collections
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
import contextlib
import csv
from dataclasses import dataclass, field
import io
import itertools
import json
import math
import multiprocessing
import os
import pathlib
import signal
import sys
import time
from typing import Any, Callable, NamedTuple, Optional, Tuple

import numpy as np

from .bag_io import (bag_info, BagError, BagWriter, choose_scan_topic, LASER_SCAN, read_scans,
                     typestore)
from .odometry_table import (ODOMETRY_CSV, odometry_request, ODOMETRY_TOPIC, OdometryOutput,
                             OdometryTable)
from .track_bag import BagTracks, LANDMARKS_CSV, TrackOptions
from ..cli import bounded, Parser, start_core, USER_ERROR
from ..conversions import (corner_array, dock_pose_messages, laser_scan, line_segment_array,
                           marker_array, MessageTypes, scan_features)
from ..core import CornerSet, line_landmarks, METHODS, SegmentSet, start
from ..extras import explains_missing_extras
from ..frontend.dock import dock_returns, find_docks, track_dock, TrackerState
from ..frontend.frames import Landmarks, landmarks_from_features
from ..frontend.tracking import detections_of, View
from ..outputs import CORNERS, DOCK_OUTPUTS, FEATURES, LINES, MARKERS
from ..params import (ConfigError, DOCK_ENABLED, dock_settings, DockSettings, feature_settings,
                      load_parameters, SENSOR)
from ..process import (check_stop, die_with_parent, stop_requested, STOP_SIGNALS, stop_signals,
                       Stopped)
from ..sensors import DEFAULT_SENSOR, sensor_presets

ALL = 'all'
CSV_NAME = 'corners.csv'
JSON_NAME = 'corners.json'
# Every output folder holds this file, which lists the files process_bag wrote there: --force
# replaces a folder only when it holds this file and nothing else than the files it lists.
MARKER_NAME = '.process_bag'
CSV_COLUMNS = ('scan', 'stamp', 'frame_id', 'method', 'index', 'x_m', 'y_m', 'yaw_rad',
               'var_x_m2', 'cov_xy_m2', 'cov_x_yaw_m_rad', 'var_y_m2', 'cov_y_yaw_m_rad',
               'var_yaw_rad2', 'opening_angle_rad', 'first_line', 'second_line',
               'first_line_points', 'second_line_points', 'first_line_chi2_dof',
               'second_line_chi2_dof', 'first_end_seen', 'second_end_seen')
# Upper triangle of the (x, y, yaw) covariance, in the order of the CSV columns: rows, columns.
_TRIANGLE = (np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2]))
DOCK_CSV_NAME = 'dock.csv'
DOCK_CSV_COLUMNS = ('stamp_s', 'x_m', 'y_m', 'yaw_rad', 'cov_xx', 'cov_xy', 'cov_xyaw', 'cov_yy',
                    'cov_yyaw', 'cov_yawyaw')
# Scans sent to a worker process at once: enough to make the hand-over cost nothing, few enough
# to keep every worker busy to the end of a bag.
BATCH_SCANS = 16
# A progress bar appears only on runs longer than this, s.
PROGRESS_DELAY_S = 1.0


@dataclass
class Summary:
    """
    What one run wrote.

    :ivar bag: the bag read
    :ivar output: the output bag folder
    :ivar topic: the LaserScan topic read
    :ivar scans: scans read and written
    :ivar malformed: scans whose features could not be extracted (written with no features)
    :ivar corners: method -> corners found in all scans
    :ivar segments: method -> segments found in all scans
    :ivar line_landmarks: method -> of those, line landmarks (flagged ``landmark`` on the lines
        topic)
    :ivar seconds: wall time of the run, s
    :ivar docks: dock poses written (None: no ``--dock``)
    """

    bag: pathlib.Path
    output: pathlib.Path
    topic: str
    scans: int = 0
    malformed: int = 0
    corners: dict = field(default_factory=dict)
    segments: dict = field(default_factory=dict)
    line_landmarks: dict = field(default_factory=dict)
    seconds: float = 0.0
    docks: Optional[int] = None


def output_topics(methods) -> dict:
    """
    Name the output topics of each method.

    :param methods: the methods run (one: plain names; several: one namespace per method)
    :return: method -> (corners topic, lines topic, markers topic)
    """
    if len(methods) == 1:
        return {methods[0]: tuple(topic.in_bag for topic in FEATURES)}
    return {m: tuple(f'{topic.in_bag}/{m}' for topic in FEATURES) for m in methods}


def _refuse_to_replace(output: pathlib.Path, bags, force: bool) -> None:
    """
    Refuse an output that exists, unless --force may replace it: a folder process_bag wrote.

    :param output: the output folder
    :param bags: the input bags (of this run: none may be or lie in the output)
    :param force: --force was given
    :raises BagError: with the reason, when the output must not be written
    """
    target = output.resolve()
    for bag in bags:
        source = pathlib.Path(bag).resolve()
        if source == target or target in source.parents:
            raise BagError(f'the output {output} holds the input bag {bag}: choose another '
                           '--output')
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


class ScanOutput(NamedTuple):
    """
    What one scan becomes, ready to be written.

    :ivar messages: (topic, message type, serialised message) for every method's outputs
    :ivar csv_rows: its rows of corners.csv, as CSV text
    :ivar json_entry: its entry of corners.json, as JSON text
    :ivar corners: method -> corners found
    :ivar segments: method -> segments found
    :ivar line_landmarks: method -> of those, line landmarks
    :ivar malformed: whether the scan was unusable (written with no features)
    :ivar tracking: with --tracks, ((stamp sec, nanosec, frame_id), Detections, View) of the
        scan, else None
    :ivar dock: with a dock to look for, (the scan's header, this scan's dock candidates)
    :ivar odometry_input: with the odometry, the scan's header and the first method's
        landmarks (else None)
    """

    messages: list
    csv_rows: str
    json_entry: str
    corners: dict
    segments: dict
    line_landmarks: dict
    malformed: bool
    tracking: Optional[tuple] = None
    dock: Optional[tuple] = None
    odometry_input: Optional[Tuple[Any, Landmarks]] = None


def _corner_rows(corners: CornerSet, segments: SegmentSet) -> list:
    """Return one list per corner, in the order of CSV_COLUMNS[4:] (non-finite terms: None)."""
    triangle = corners.covariance[:, _TRIANGLE[0], _TRIANGLE[1]]
    walls = np.stack([corners.first_segment, corners.second_segment], axis=1)
    values = np.column_stack([corners.xy_m, corners.yaw_rad, triangle,
                              corners.opening_angle_rad]).tolist()
    if not np.isfinite(triangle).all():     # JSON has no NaN or infinity
        values = [[v if math.isfinite(v) else None for v in row] for row in values]
    return [[index, *row, *wall, *points, *chi2_dof, *seen]
            for index, row, wall, points, chi2_dof, seen in zip(
                range(len(values)), values, walls.tolist(), segments.num_points[walls].tolist(),
                segments.residual_chi2_dof[walls].tolist(), corners.end_seen.tolist())]


class ScanWork:
    """
    Turns one scan into its output: features by every method, messages, table rows.

    Made once per run; called here, or in worker processes that inherit it (``--jobs``).
    """

    def __init__(self, parameters: dict, methods=None, tracks: bool = False,
                 dock: Optional[DockSettings] = None, odometry: bool = False):
        """
        Prepare the work.

        :param parameters: feature_node parameter values (see :func:`load_parameters`)
        :param methods: the methods to run (None: the ``method`` parameter)
        :param tracks: also hand over each scan's landmarks for the tracker (one method)
        :param dock: the dock to look for (among the features of the ``method`` parameter's
            fit, or the first method's), or None
        :param odometry: also give each scan's landmarks (of the first method)
        :raises ValueError: for parameters that make no valid configuration
        """
        self.tracks = tracks
        config, self.style, self.publish_markers = feature_settings(parameters)
        self.methods = tuple(methods or (config.method,))
        self.dock = dock
        self.dock_method = config.method if config.method in self.methods else self.methods[0]
        self.odometry = odometry
        self.configs = {m: config.replace(method=m) for m in self.methods}
        self.topics = output_topics(self.methods)
        self.store = typestore()
        # Its (de)serialisers are made now, before worker processes are forked.
        self.types = MessageTypes.from_typestore(self.store)

    def __call__(self, index: int, log_time_ns: int, scan) -> ScanOutput:
        """
        Extract and convert the features of one scan by every method.

        :param index: the scan's number in the bag (from 0)
        :param log_time_ns: its log time, ns
        :param scan: the scan, a LaserScan of :attr:`types`
        :return: the output
        """
        header, types, serialize = scan.header, self.types, self.types.serialize
        stamp = f'{header.stamp.sec}.{header.stamp.nanosec:09d}'
        messages, csv_rows, corners_of, corners, segments, landmarks = [], [], {}, {}, {}, {}
        problems, dock, scan_landmarks = [], None, None
        for method, (corners_topic, lines_topic, markers_topic) in self.topics.items():
            features, problems = scan_features(scan, self.configs[method])
            if self.dock is not None and method == self.dock_method:
                returns = dock_returns(scan.ranges, scan.angle_min, scan.angle_increment,
                                       self.configs[method], features.range_sigma_m,
                                       scan.range_min, scan.range_max)
                dock = (header, find_docks(features.segments, features.corners,
                                           self.dock.shape, returns))
            if self.odometry and scan_landmarks is None:
                scan_landmarks = landmarks_from_features(
                    features, self.configs[method].max_landmark_angle_sigma_rad)
            is_landmark = line_landmarks(features.segments,
                                         self.configs[method].max_landmark_angle_sigma_rad)
            messages.append((corners_topic, CORNERS.type_name,
                             serialize(corner_array(features, header, types))))
            messages.append((lines_topic, LINES.type_name,
                             serialize(line_segment_array(features, header, types,
                                                          is_landmark=is_landmark))))
            if self.publish_markers:
                messages.append((markers_topic, MARKERS.type_name, serialize(
                    marker_array(features, header, self.style, types,
                                 is_landmark=is_landmark))))
            rows = _corner_rows(features.corners, features.segments)
            csv_rows.extend([index, stamp, header.frame_id, method, *row] for row in rows)
            corners_of[method] = [dict(zip(CSV_COLUMNS[4:], row)) for row in rows]
            corners[method], segments[method] = len(features.corners), len(features.segments)
            landmarks[method] = int(np.count_nonzero(is_landmark))
        tracking = None
        if self.tracks:
            bound = self.configs[method].max_landmark_angle_sigma_rad
            tracking = ((header.stamp.sec, header.stamp.nanosec, header.frame_id),
                        detections_of(features, bound),
                        View(scan.angle_min, scan.angle_increment, np.asarray(scan.ranges),
                             scan.range_max))
        table = io.StringIO()
        csv.writer(table).writerows(csv_rows)
        entry = json.dumps({'scan': index, 'stamp': stamp, 'frame_id': header.frame_id,
                            'log_time_ns': log_time_ns, 'problems': problems,
                            'corners': corners_of})
        return ScanOutput(messages, table.getvalue(), entry, corners, segments, landmarks,
                          bool(problems), tracking, dock,
                          None if scan_landmarks is None else (header, scan_landmarks))


# The work of a worker process, inherited from the process that started it.
_WORK: Optional[ScanWork] = None


def _start_worker(work: ScanWork, parent_pid: int) -> None:
    """
    Set up a worker process: its work, and no signals of its own (its parent stops it).

    :param work: the work, inherited
    :param parent_pid: the process that forked this one; if that is gone already, so is this
    """
    global _WORK
    _WORK = work
    for number in STOP_SIGNALS:
        signal.signal(number, signal.SIG_IGN)
    # A worker left waiting for work would wait for ever, on a queue lock a killed sibling may
    # hold.
    die_with_parent(parent_pid)


def _work_on(batch: list) -> list:
    """Run the work of this worker process on (index, log time, serialised scan) triples."""
    return [_WORK(index, log_time_ns, _WORK.store.deserialize_cdr(data, LASER_SCAN))
            for index, log_time_ns, data in batch]


def _batches(iterable, size: int):
    """Yield lists of up to ``size`` items."""
    iterator = iter(iterable)
    while batch := list(itertools.islice(iterator, size)):
        yield batch


def _outputs(work: ScanWork, records, jobs: int):
    """
    Yield batches of (log time, serialised scan, ScanOutput) in bag order.

    With one job everything runs here, a scan at a time; with more, batches of scans go to
    ``jobs`` worker processes, at most two batches per worker in flight (memory stays flat).
    """
    if jobs <= 1:
        for index, record in enumerate(records):
            scan = laser_scan(record.scan, work.types)
            yield [(record.timestamp_ns, work.types.serialize(scan),
                    work(index, record.timestamp_ns, scan))]
        return
    # Forked, the workers inherit the work and start at once; they die with this process. The
    # compiled core too, if it is loaded here first: otherwise each worker of each bag loads it
    # from the cache again (0.3 s of CPU each; once chosen, start returns at once).
    start(wait=True)
    pool = ProcessPoolExecutor(jobs, multiprocessing.get_context('fork'), _start_worker,
                               (work, os.getpid()))
    try:
        pending = collections.deque()
        for batch in _batches(enumerate(records), BATCH_SCANS):
            scans = [(index, record.timestamp_ns,
                      work.types.serialize(laser_scan(record.scan, work.types)))
                     for index, record in batch]
            pending.append((scans, pool.submit(_work_on, scans)))
            if len(pending) >= 2 * jobs:
                yield _collect(*pending.popleft())
        while pending:
            yield _collect(*pending.popleft())
    finally:
        pool.shutdown(cancel_futures=True)


def _collect(scans: list, future) -> list:
    try:
        outputs = future.result()
    except BrokenProcessPool as error:
        raise BagError(f'a worker process died ({error}): out of memory?') from error
    return [(log_time_ns, data, output)
            for (_, log_time_ns, data), output in zip(scans, outputs)]


class _CornerTables:
    """Streams corners.csv and corners.json (an array written one scan at a time)."""

    def __init__(self, bag_writer: BagWriter, header: dict):
        self._paths = bag_writer.sidecar(CSV_NAME), bag_writer.sidecar(JSON_NAME)
        self._header = header
        self._first = True

    def __enter__(self) -> '_CornerTables':
        csv_path, json_path = self._paths
        with contextlib.ExitStack() as files:
            self._csv = files.enter_context(csv_path.open('w', newline=''))
            self._json = files.enter_context(json_path.open('w'))
            self._files = files.pop_all()
        csv.writer(self._csv).writerow(CSV_COLUMNS)
        head = json.dumps(self._header, indent=1)
        self._json.write(head[:head.rindex('}')].rstrip() + ',\n "scans": [')
        return self

    def add(self, output: ScanOutput) -> None:
        """Append one scan's rows and entry."""
        self._csv.write(output.csv_rows)
        self._json.write(('\n  ' if self._first else ',\n  ') + output.json_entry)
        self._first = False

    def __exit__(self, kind, value, traceback):
        if kind is None:
            self._json.write('\n ]\n}\n')
            self._files.close()
        else:
            with contextlib.suppress(OSError):  # the files are thrown away; flushing may fail
                self._files.close()
        return False


class _DockTable:
    """Follows the dock over the scans in bag order; writes its poses to the bag and dock.csv."""

    def __init__(self, bag_writer: BagWriter, settings: DockSettings, types: MessageTypes):
        self._writer, self._settings, self._types = bag_writer, settings, types
        self._path = bag_writer.sidecar(DOCK_CSV_NAME)
        self._state = TrackerState()
        self.written = 0

    def __enter__(self) -> '_DockTable':
        self._file = self._path.open('w', newline='')
        self._csv = csv.writer(self._file)
        self._csv.writerow(DOCK_CSV_COLUMNS)
        return self

    def add(self, log_time_ns: int, output: ScanOutput) -> None:
        """Track one scan's candidates; write the dock the tracker reports."""
        header, candidates = output.dock
        stamp_s = header.stamp.sec + 1e-9 * header.stamp.nanosec
        self._state, dock = track_dock(self._state, candidates, stamp_s,
                                       self._settings.tracking)
        if dock is None:
            return
        for topic, message in zip(DOCK_OUTPUTS, dock_pose_messages(dock, header, self._types)):
            self._writer.write_serialized(topic.in_bag, topic.type_name, log_time_ns,
                                          self._types.serialize(message))
        self._csv.writerow([f'{header.stamp.sec}.{header.stamp.nanosec:09d}', dock.x_m, dock.y_m,
                            dock.yaw_rad, *dock.covariance[_TRIANGLE].tolist()])
        self.written += 1

    def __exit__(self, kind, value, traceback):
        with contextlib.suppress(OSError) if kind is not None else contextlib.nullcontext():
            self._file.close()
        return False


def process(bag, output, parameters: dict, methods=None, topic: Optional[str] = None,
            overwrite: bool = False, after_scans: Optional[Callable[[int], None]] = None,
            jobs: int = 1, tracks: Optional[TrackOptions] = None, dock: bool = False,
            odometry: Optional[OdometryOutput] = None) -> Summary:
    """
    Extract features from every scan of a bag into an output bag with corner tables.

    :param bag: a ROS 2 bag (sqlite3 or mcap) or a ROS 1 bag
    :param output: the output bag folder (must not exist unless ``overwrite``)
    :param parameters: feature_node parameter values (see :func:`load_parameters`)
    :param methods: the methods to run (None: the ``method`` parameter)
    :param topic: the LaserScan topic (None: the bag's only one)
    :param overwrite: replace an existing output once the new one is complete, if it is an
        output of process_bag with nothing added (its marker file says what it wrote)
    :param after_scans: called with the number of scans just written, after each scan (or
        batch of scans); whatever it raises (e.g. :class:`~wctls_ros.process.Stopped`) ends
        the run and leaves nothing
    :param jobs: processes that extract features (1: this one alone)
    :param tracks: track the landmarks (one method only) with this motion source, or None
    :param dock: also look for the dock the parameters describe (``dock_enabled`` or not) and
        write its poses and dock.csv
    :param odometry: also the odometry, with these settings (None: none)
    :return: counts and timing
    :raises BagError: for a missing, unreadable or damaged bag, or one without LaserScans, or
        an output that exists (without ``overwrite``, or that process_bag did not write)
    :raises ValueError: for parameters that make no valid configuration
    """
    started = time.perf_counter()
    work = ScanWork(parameters, methods, tracks is not None,
                    dock_settings({**parameters, DOCK_ENABLED: True}) if dock else None,
                    odometry is not None)
    if tracks is not None and len(work.methods) > 1:
        raise BagError('--tracks follows the landmarks of one method, not of --method all')
    info = bag_info(bag)
    topic = choose_scan_topic(bag, topic, info)
    output = pathlib.Path(output)
    _refuse_to_replace(output, [bag], overwrite)
    summary = Summary(pathlib.Path(bag), output, topic, corners=dict.fromkeys(work.methods, 0),
                      segments=dict.fromkeys(work.methods, 0),
                      line_landmarks=dict.fromkeys(work.methods, 0))
    with BagWriter(output, overwrite=overwrite) as writer:
        writer.sidecar(MARKER_NAME).write_text(json.dumps({
            'written_by': 'process_bag of wctls_ros',
            'files': [MARKER_NAME, f'{output.name}.mcap', 'metadata.yaml', CSV_NAME, JSON_NAME]
            + ([LANDMARKS_CSV] if tracks is not None else [])
            + ([DOCK_CSV_NAME] if dock else [])
            + ([ODOMETRY_CSV] if odometry is not None else [])}))
        tracker = BagTracks(writer, tracks, work.types) if tracks is not None else None
        tables = _CornerTables(writer, {'bag': str(bag), 'topic': topic,
                                        'methods': work.methods, 'parameters': parameters})
        docks = (_DockTable(writer, work.dock, work.types) if work.dock is not None
                 else contextlib.nullcontext())
        # Closed on the way out, whatever ends the run: the worker processes stop at once.
        batches = contextlib.closing(_outputs(work, read_scans(bag, topic), jobs))
        odometry_table = (OdometryTable(writer, odometry.config, odometry.mount)
                          if odometry is not None else contextlib.nullcontext())
        with tables, docks, batches as outputs, odometry_table, contextlib.closing(
                tracker or io.StringIO()):
            for batch in outputs:
                for log_time_ns, scan_data, scan_output in batch:
                    writer.write_serialized(topic, LASER_SCAN, log_time_ns, scan_data)
                    for message_topic, kind, data in scan_output.messages:
                        writer.write_serialized(message_topic, kind, log_time_ns, data)
                    tables.add(scan_output)
                    if tracker is not None:
                        tracker.add(log_time_ns, *scan_output.tracking)
                    if work.dock is not None:
                        docks.add(log_time_ns, scan_output)
                    if odometry is not None:
                        odometry_table.add(log_time_ns, *scan_output.odometry_input)
                    for method in work.methods:
                        summary.corners[method] += scan_output.corners[method]
                        summary.segments[method] += scan_output.segments[method]
                        summary.line_landmarks[method] += scan_output.line_landmarks[method]
                    summary.malformed += scan_output.malformed
                summary.scans += len(batch)
                if after_scans is not None:
                    after_scans(len(batch))
    summary.seconds = time.perf_counter() - started
    if work.dock is not None:
        summary.docks = docks.written
    return summary


def default_output(bag, folder='.') -> pathlib.Path:
    """
    Name the output of a bag when none is given: ``<bag name>_features`` in a folder.

    :param bag: the input bag path
    :param folder: where the outputs go
    :return: the output folder
    """
    path = pathlib.Path(bag)
    name = path.stem if path.suffix in ('.bag', '.mcap', '.db3') else path.name
    return pathlib.Path(folder) / f'{name}_features'


def usable_cpus() -> int:
    """
    Return how many CPUs this process may run on.

    :return: the count
    """
    return len(os.sched_getaffinity(0))


def parser() -> argparse.ArgumentParser:
    """
    Build the command line interface.

    :return: the argument parser
    """
    cli = Parser(
        prog='process_bag',
        description='Extract corners and line segments with covariances from the LaserScans '
                    'of ROS 1 or ROS 2 bags, without ROS middleware. Writes, per bag, an mcap '
                    'ROS 2 bag (open it in Foxglove) with the scans, corners, lines and '
                    f'markers, plus {CSV_NAME} and {JSON_NAME} inside the bag folder.',
        epilog='Exit status: 0 done; 2 a user error (bad argument, path, bag, parameter file, '
               'unwritable output), with one line on stderr and nothing written; 130 stopped by '
               'SIGINT (Ctrl-C), 143 by SIGTERM, 129 by SIGHUP (a closed terminal), with nothing '
               'written. With several bags, each output is complete or absent: a bag that turns '
               'out damaged midway is reported in one line and skipped, and the status is 2.')
    cli.add_argument('bags', nargs='+', metavar='bag',
                     help='ROS 2 bag folder (or its .mcap / .db3 file) or ROS 1 .bag; several '
                          'are processed one after the other')
    cli.add_argument('-o', '--output', type=pathlib.Path,
                     help='output bag folder of a single bag (default: <bag name>_features in '
                          '--output-dir); must not exist unless --force')
    cli.add_argument('-d', '--output-dir', type=pathlib.Path, default=pathlib.Path('.'),
                     help='folder for the outputs named <bag name>_features (default: the '
                          'current folder)')
    cli.add_argument('-m', '--method', choices=METHODS + (ALL,),
                     help='line fit whose covariances are propagated, or all four on their '
                          'own topics (/corners/<method>, ...); default: the method of the '
                          'config file, else wctls')
    cli.add_argument('-c', '--config', type=pathlib.Path,
                     help='feature_node parameter file (YAML, as for --ros-args --params-file; '
                          "default: none, feature_node's defaults)")
    cli.add_argument('-s', '--sensor', choices=tuple(sensor_presets()),
                     help='sensor preset: its noise model, unless the config file sets the '
                          f"sigmas (default: the config file's, else {DEFAULT_SENSOR})")
    cli.add_argument('-t', '--topic', help='LaserScan topic (default: the only one in the bag)')
    cli.add_argument('-f', '--force', action='store_true',
                     help='replace an existing output once the new one is complete; only an '
                          f'output of process_bag (its {MARKER_NAME} file) with no file added')
    cli.add_argument('-j', '--jobs', type=bounded(int, 1), default=usable_cpus(),
                     help='processes that extract features, each taking batches of scans '
                          f'(default: the CPUs this process may use, {usable_cpus()} here)')
    cli.add_argument('--tracks', action='store_true',
                     help='also track the corners and line landmarks: ids on /landmarks '
                          f'(wctls_msgs/LandmarkArray) and {LANDMARKS_CSV}; the sensor still '
                          'unless --poses')
    cli.add_argument('--poses', metavar='FILE',
                     help="with --tracks: the robot's poses (CSV stamp_s,x_m,y_m,yaw_rad) that "
                          'move the tracks from scan to scan (default: none, a still sensor)')
    cli.add_argument('--laser-offset', nargs=3, type=float, default=[0.0, 0.0, 0.0],
                     metavar=('X', 'Y', 'YAW_DEG'),
                     help="with --poses: the laser's pose on the robot (default: 0 0 0)")
    cli.add_argument('--step-sigma', nargs=2, type=float, default=None, metavar=('M', 'DEG'),
                     help='with --tracks: sigma of each step between scans, position (m) and '
                          'heading (deg) (default: 0.02 1 with --poses, 0 0 without)')
    cli.add_argument('--dock', action='store_true',
                     help='also look for the dock the config file describes (its dock_* '
                          'parameters; default: the example dock, a V of two 0.3 m faces at '
                          '120 deg) and write its poses on /detected_dock_pose and '
                          f'/detected_dock_pose_with_covariance and in {DOCK_CSV_NAME}')
    cli.add_argument('--progress', action=argparse.BooleanOptionalAction, default=None,
                     help='show one progress bar for all bags (default: on a terminal, for '
                          'runs over 1 s)')
    cli.add_argument('--odometry', action='store_true',
                     help=f'also the odometry from the features: nav_msgs/Odometry on '
                          f'{ODOMETRY_TOPIC} and {ODOMETRY_CSV} in the output folder (the '
                          "laser's pose, or the robot's with --laser-mount)")
    cli.add_argument('--laser-mount', nargs='+', metavar='X_M Y_M YAW_DEG | FILE',
                     help="with --odometry: the laser's pose on the robot, as three numbers "
                          '(m, m, deg) or a YAML file with x_m, y_m, yaw_rad (such as a '
                          "recording's laser_mount.yaml) (default: none, the laser's odometry)")
    return cli


def _plan(args) -> list:
    """
    Pair every bag with its output and check both before anything is written.

    :param args: the parsed command line
    :return: (bag, output, scans) for each bag
    :raises BagError: with one line per problem found
    """
    if args.output is not None and len(args.bags) > 1:
        raise BagError(f'--output names the output of one bag; {len(args.bags)} bags were '
                       'given: use --output-dir')
    outputs = [args.output or default_output(bag, args.output_dir) for bag in args.bags]
    runs, problems = [], []
    for bag, output in zip(args.bags, outputs):
        try:
            if outputs.count(output) > 1:
                raise BagError(f'{bag}: its output {output} would be written twice: give the '
                               'bags different names')
            info = bag_info(bag)
            scans = info.topics[choose_scan_topic(bag, args.topic, info)][1]
            _refuse_to_replace(pathlib.Path(output), args.bags, args.force)
            runs.append((bag, output, scans))
        except BagError as error:
            problems.append(str(error))
    if problems:
        raise BagError('\n'.join(f'process_bag: error: {problem}' for problem in problems))
    return runs


def _report(summary: Summary) -> str:
    lines = [f'wrote {summary.output}: {summary.scans} scans of {summary.topic} in '
             f'{summary.seconds:.1f} s ({summary.scans / max(summary.seconds, 1e-9):.0f} '
             f'scans/s), with {CSV_NAME} and {JSON_NAME}']
    for method in summary.corners:
        lines.append(f'  {method}: {summary.corners[method]} corners, '
                     f'{summary.segments[method]} segments ({summary.line_landmarks[method]} '
                     'line landmarks)')
    if summary.malformed:
        lines.append(f'  {summary.malformed} malformed scans kept without features')
    if summary.docks is not None:
        lines.append(f'  dock: {summary.docks} poses, in {DOCK_CSV_NAME}')
    return '\n'.join(lines)


def _table(results: list, methods, seconds: float) -> str:
    """Tabulate several runs: (bag, Summary or None when it failed)."""
    rows = [['bag', 'scans', *(f'corners {m}' for m in methods), 'seconds', 'scans/s',
             'output']]
    for bag, summary in results:
        if summary is None:
            rows.append([str(bag), '', *('' for _ in methods), '', '', 'failed (see above)'])
            continue
        rows.append([str(bag), str(summary.scans), *(str(summary.corners[m]) for m in methods),
                     f'{summary.seconds:.1f}', f'{summary.scans / summary.seconds:.0f}',
                     str(summary.output)])
    scans = sum(summary.scans for _, summary in results if summary is not None)
    rows.append(['all', str(scans), *('' for _ in methods), f'{seconds:.1f}',
                 f'{scans / seconds:.0f}', f'{sum(s is not None for _, s in results)} written'])
    widths = [max(len(row[column]) for row in rows) for column in range(len(rows[0]))]
    return '\n'.join('  '.join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip()
                     for row in rows)


def _progress_bar(total: int, wanted):
    """
    Return a tqdm progress bar on standard error, or a silent stand-in without tqdm.

    :param total: scans in all
    :param wanted: --progress: True, False, or None (a bar when standard error is a terminal)
    :return: an object with update(), set_description() and close()
    :raises ImportError: when a bar is asked for (--progress) and tqdm is not installed
    """
    try:
        from tqdm import tqdm
    except ImportError:
        if wanted:
            raise
        return _NoProgress()
    tqdm.monitor_interval = 0       # no thread of its own: worker processes are forked
    return tqdm(total=total, unit='scan', file=sys.stderr,
                disable=None if wanted is None else not wanted, delay=PROGRESS_DELAY_S)


class _NoProgress:
    """What process_bag shows without tqdm: nothing."""

    def update(self, count: int) -> None:
        """Count nothing."""

    def set_description(self, text: str) -> None:
        """Describe nothing."""

    def close(self) -> None:
        """Close nothing."""


@explains_missing_extras('process_bag')
def main(argv=None) -> int:
    """
    Run the command line tool.

    :param argv: arguments (None: sys.argv[1:])
    :return: exit status: 0 done, 2 user error (one line per problem), 128 + the signal number
        when stopped by SIGINT, SIGTERM or SIGHUP (the output being written is not)
    """
    started = time.perf_counter()
    with stop_signals():
        args = parser().parse_args(argv)
        methods = METHODS if args.method == ALL else None
        results = []
        try:
            overrides = {} if args.method in (None, ALL) else {'method': args.method}
            if args.sensor is not None:
                overrides[SENSOR] = args.sensor
            parameters = load_parameters(args.config, overrides=overrides)
            try:
                feature_settings(parameters)
                if args.dock:
                    dock_settings({**parameters, DOCK_ENABLED: True})
            except ValueError as error:
                raise ConfigError(f'process_bag: error: {error}') from error
            runs = _plan(args)
            tracks = (TrackOptions.from_arguments(args.poses, args.laser_offset,
                                                  args.step_sigma) if args.tracks else None)
            odometry = odometry_request(args.odometry, args.laser_mount)
            # Workers are forked from a process that has chosen (and compiled) the core.
            start_core('process_bag', wait=args.jobs > 1,
                       give_up=lambda: stop_requested() is not None)
            check_stop()
            bar = _progress_bar(sum(scans for _, _, scans in runs), args.progress)

            def after_scans(count: int) -> None:
                bar.update(count)
                check_stop()

            with contextlib.closing(bar):
                for bag, output, _ in runs:
                    bar.set_description(pathlib.Path(bag).name)
                    try:
                        results.append((bag, process(bag, output, parameters, methods,
                                                     args.topic, args.force, after_scans,
                                                     args.jobs, tracks, args.dock,
                                                     odometry)))
                    except BagError as error:
                        if len(runs) == 1:
                            raise
                        bar.write(f'process_bag: error: {error}', file=sys.stderr)
                        results.append((bag, None))
        except (BagError, ConfigError) as error:
            text = str(error)
            print(text if text.startswith('process_bag: ') else f'process_bag: error: {text}',
                  file=sys.stderr)
            return USER_ERROR
        except Stopped as stopped:
            interruption = f'interrupted by {stopped}'
            kept = f'; {len(results)} earlier outputs are complete' if results else ''
            print(f'process_bag: {interruption}; the output of {bag} is not written{kept}'
                  if len(runs) > 1 else f'process_bag: {interruption}; nothing written',
                  file=sys.stderr)
            return 128 + stopped.signal_number
    try:
        if len(results) == 1:
            print(_report(results[0][1]), flush=True)
        else:
            print(_table(results, methods or (parameters['method'],),
                         time.perf_counter() - started), flush=True)
    except OSError as error:
        # Python flushes stdout again at exit: give it a file that takes the rest quietly.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        written = [str(summary.output) for _, summary in results if summary is not None]
        print(f'process_bag: error: cannot print the summary ({error.strerror}); '
              + (f'the output {written[0]} is complete' if len(written) == 1 else
                 f'the outputs {", ".join(written)} are complete'), file=sys.stderr)
        return USER_ERROR
    return USER_ERROR if any(summary is None for _, summary in results) else 0


if __name__ == '__main__':
    sys.exit(main())
