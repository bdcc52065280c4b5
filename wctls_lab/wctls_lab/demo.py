# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
demo: the whole system live on this machine, no sensor needed.

Starts an RPLIDAR emulator (the S1 unless ``--model`` says another) on a pseudo-terminal
(streaming a simulated floor plan), rplidar_node reading it, and feature_node extracting
corners, each as its own process like ``ros2 run`` would; records ``scan``, ``corners``,
``lines`` and ``markers`` into an mcap bag; then prints a table (corners per scan, their sigmas,
their error against the simulated truth, latency) and draws one scan. With ``--dock``, the
example dock stands 1 m in front of the sensor and feature_node looks for it: its poses are
recorded too, and the table and the figure show them against the truth. With ``--moving``, the
emulated sensor drives round a circle, odometry_node follows it from the scans, and the table
compares its trajectory and covariance with the emulator's true poses.

Sealed: its processes talk on a ROS domain of their own, discovered on this machine only,
whatever ROS_DOMAIN_ID and the DDS settings of the environment say, so that its emulated scans
never reach a live system. Every process it started is stopped at the end, also on Ctrl-C,
SIGTERM or a closed terminal (SIGHUP); should the demo itself be killed (SIGKILL), the kernel
ends them (``PR_SET_PDEATHSIG``). It writes only into a folder of its own
(:mod:`wctls_ros.output_folders`).

Exit status: 0 done; 1 the live run failed (a process did not start or no features came; one
line, the logs say why); 2 a user error (one line ``demo: error: ...``); 128 + N stopped by
signal N (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP), with one line and no traceback.
"""

import argparse
from dataclasses import dataclass, field
import functools
import math
import os
import pathlib
import random
import signal
import subprocess
import sys
import textwrap
import threading
import time
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
from wctls_ros.bags import BagWriter
from wctls_ros.cli import bounded, Parser, USER_ERROR, UserError
from wctls_ros.core import METHODS, nees
from wctls_ros.extras import explains_missing_extras, require
from wctls_ros.frontend.dock import DockShape, wrap_angle
from wctls_ros.output_folders import claim, mark, remove_entries
from wctls_ros.outputs import (CORNERS, DOCK_POSE_WITH_COVARIANCE, FEATURES, LANDMARK_OUTPUTS,
                               message_class, ODOMETRY, SCAN)
from wctls_ros.params import feature_settings, load_parameters
from wctls_ros.process import check_stop, die_with_parent, stop_requested, stop_signals, Stopped
from wctls_rplidar.emulator.device import EMULATED_MODELS
import yaml

from .simulation import full_turn_bearings, load_floor_plan, S1_BEAMS_PER_TURN
from .simulation.visibility import visible_corners

# The driver and feature_node run with their shipped files and nothing else (feature_node with
# the default sensor preset, generic: docs/sensors.md); the emulator simulates the S1 as we
# expect a real one to look (its s1_like default).
# A found corner is the true one when it is this close, m.
MATCH_RADIUS_M = 0.1
STOP_TIMEOUT_S = 10.0
# What the demo writes into its output folder.
OUTPUTS = ('bag', 'logs', 'scan.png', 'summary.md', 'ttyS1', 'dock_plan.yaml', 'truth.csv')
# With --dock: the example dock's apex this far in front of the sensor, m, and its body's depth
# behind the apex, m.
DOCK_DISTANCE_M = 1.0
DOCK_DEPTH_M = 0.1
# With --moving: the sensor drives round a circle of this radius, m, at this speed, m/s, starting
# at the plan's pose turned this far left, deg (in environment_a the circle then passes between
# the columns and the cabinet). A turn then sweeps 1.6 deg: the scans are distorted by the
# motion, as a real robot's are.
MOVING_RADIUS_M = 0.35
MOVING_SPEED_M_S = 0.1
MOVING_TURN_DEG = 90.0
# Half a turn of the emulated S1 at 10 Hz, s: a scan's features come from its whole turn, and its
# stamp is its first beam's, so it is compared with the true pose this long after its stamp.
HALF_TURN_S = 0.05
# Its ROS domain is drawn from these (ROS 2's usable ids on Linux), never the environment's.
DOMAIN_IDS = range(1, 102)
# Settings that could take the demo's traffic off this machine or into a live system:
# static peers, a discovery server, a DDS profile of the user's, the deprecated switch that the
# discovery range replaces.
FOREIGN_SETTINGS = ('ROS_STATIC_PEERS', 'ROS_DISCOVERY_SERVER', 'ROS_LOCALHOST_ONLY',
                    'FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                    'CYCLONEDDS_URI')


@dataclass
class Recording:
    """What the recorder saw, kept for the summary (times in ns)."""

    scans: Dict[int, tuple] = field(default_factory=dict)    # stamp -> (receive time, msg)
    corners: List[tuple] = field(default_factory=list)       # (receive time, CornerArray)
    docks: List[tuple] = field(default_factory=list)   # (receive time, PoseWithCovarianceStamped)
    odometry: List[tuple] = field(default_factory=list)     # (receive time, nav_msgs/Odometry)
    stopped_by: int = 0                 # the signal that ended the recording early, if any


def _executable(package: str, name: str) -> str:
    """Return an installed executable (what `ros2 run PACKAGE NAME` would start)."""
    from ament_index_python.packages import get_package_prefix
    return str(pathlib.Path(get_package_prefix(package)) / 'lib' / package / name)


def _config_file(package: str) -> pathlib.Path:
    """Return the folder of a package's installed configuration files."""
    from ament_index_python.packages import get_package_share_directory
    return pathlib.Path(get_package_share_directory(package)) / 'config'


def private_network(environment: dict) -> int:
    """
    Seal a ROS environment: a domain of its own, discovery on this machine only.

    :param environment: the environment to change (e.g. os.environ)
    :return: the domain id chosen (never the one the environment had)
    """
    taken = environment.get('ROS_DOMAIN_ID', '').strip()
    domain = random.choice([d for d in DOMAIN_IDS if str(d) != taken])
    for name in FOREIGN_SETTINGS:
        environment.pop(name, None)
    environment['ROS_DOMAIN_ID'] = str(domain)
    environment['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return domain


class Processes:
    """
    Child processes, each in its own session so that one signal stops all of its threads.

    Each is sent SIGTERM by the kernel if the demo dies without stopping it.
    """

    def __init__(self, log_dir: pathlib.Path):
        self.log_dir = log_dir
        self.running = []

    def start(self, name: str, command: List[str]) -> subprocess.Popen:
        """
        Start a child process with its output in ``<log_dir>/<name>.log``.

        :param name: short name for the log file
        :param command: the command line
        :return: the process
        """
        log = open(self.log_dir / f'{name}.log', 'w')
        process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL, start_new_session=True,
                                   preexec_fn=functools.partial(die_with_parent, os.getpid(),
                                                                signal.SIGTERM))
        log.close()
        self.running.append((name, process))
        return process

    def stop_all(self) -> None:
        """Interrupt every child (as Ctrl-C would), and kill the ones that do not stop."""
        for _, process in self.running:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
        deadline = time.monotonic() + STOP_TIMEOUT_S
        for name, process in self.running:
            try:
                process.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                print(f'demo: {name} did not stop on SIGINT: killing it', file=sys.stderr)
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
        self.running.clear()


def _wait_for(path: pathlib.Path, process: subprocess.Popen, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not path.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f'the emulator did not create {path} (see its log)')
        check_stop()
        time.sleep(0.05)


def record(bag_path: pathlib.Path, seconds: float, dock: bool = False,
           odometry: bool = False) -> Recording:
    """
    Record the demo's topics into an mcap bag for ``seconds`` once features flow.

    Features flow once scans and corners arrive and feature_node's pipeline is settled (on
    /diagnostics: no compiled pipeline is still on its way); nothing before that is recorded.

    :param bag_path: the bag folder to write
    :param seconds: how long to record once features flow, s
    :param dock: also record the dock's poses (detected_dock_pose_with_covariance)
    :param odometry: also record odometry_node's odometry (odom)
    :return: what was seen, for the summary (``stopped_by`` set on a stop signal)
    """
    from diagnostic_msgs.msg import DiagnosticArray
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.signals import SignalHandlerOptions

    seen = Recording()
    context = rclpy.context.Context()
    # A stop signal (noted: :func:`main`) ends the recording between two spins.
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('demo_recorder', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        with BagWriter(bag_path) as bag:
            arrived = set()
            recording = threading.Event()

            def keep(topic, message):
                arrived.add(topic)
                if not recording.is_set():
                    return
                now = time.time_ns()
                bag.write(topic, now, message)
                if topic == SCAN.in_bag:
                    seen.scans[_stamp_ns(message)] = (now, message)
                elif topic == CORNERS.in_bag:
                    seen.corners.append((now, message))
                elif topic == DOCK_POSE_WITH_COVARIANCE.in_bag:
                    seen.docks.append((now, message))
                elif topic == ODOMETRY.in_bag:
                    seen.odometry.append((now, message))

            node.create_subscription(message_class(SCAN.type_name), SCAN.name,
                                     lambda m: keep(SCAN.in_bag, m), qos_profile_sensor_data)
            optional = (((DOCK_POSE_WITH_COVARIANCE,) if dock else ())
                        + ((ODOMETRY,) if odometry else ()))
            for topic in FEATURES + LANDMARK_OUTPUTS + optional:
                node.create_subscription(message_class(topic.type_name), topic.name,
                                         lambda m, t=topic: keep(t.in_bag, m), 10)
            settled = threading.Event()

            def on_diagnostics(array):
                for status in array.status:
                    values = {value.key: value.value for value in status.values}
                    if values.get('feature pipeline settled') == 'yes':
                        settled.set()

            node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
            # Discovery can match the recorder to feature_node before the driver (or the other
            # way round) on a busy machine: start the clock once both scans and corners arrive,
            # and feature_node's pipeline is settled: the table measures the compiled pipeline
            # (when numba is there), not the numpy one serving while it loads.
            start_deadline = time.monotonic() + 60.0
            while not ({SCAN.in_bag, CORNERS.in_bag} <= arrived and settled.is_set()
                       or stop_requested()):
                if time.monotonic() > start_deadline:
                    raise RuntimeError('no scans and corners from a settled feature pipeline '
                                       'within 60 s (see the logs)')
                executor.spin_once(timeout_sec=0.1)
            if not stop_requested():
                print(f'demo: features flowing; recording {seconds:g} s ...', flush=True)
            recording.set()
            end = time.monotonic() + seconds
            while time.monotonic() < end and not stop_requested():
                executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    seen.stopped_by = stop_requested() or 0
    return seen


def dock_plan(floor_plan: str, path: pathlib.Path, shape: DockShape = DockShape()) -> np.ndarray:
    """
    Write a floor plan with the example dock standing in front of the plan's sensor.

    :param floor_plan: the plan's name or YAML path (its base)
    :param path: the plan file to write
    :param shape: the dock
    :return: the dock's true pose in the laser frame (x m, y m, yaw rad), shape (3,)
    """
    base = (str(pathlib.Path(floor_plan).resolve()) if pathlib.Path(floor_plan).is_file()
            else floor_plan)
    x, y, yaw = load_floor_plan(floor_plan).sensor_pose
    half = 0.5 * shape.opening_angle_rad
    # The dock frame: x along the sensor's heading (away from it), y to its left.
    outline = [(-shape.right_face_m * math.cos(half), -shape.right_face_m * math.sin(half)),
               (0.0, 0.0),
               (-shape.left_face_m * math.cos(half), shape.left_face_m * math.sin(half)),
               (DOCK_DEPTH_M, shape.left_face_m * math.sin(half)),
               (DOCK_DEPTH_M, -shape.right_face_m * math.sin(half))]
    c, s = math.cos(yaw), math.sin(yaw)
    apex = (x + DOCK_DISTANCE_M * c, y + DOCK_DISTANCE_M * s)
    points = [[apex[0] + c * u - s * v, apex[1] + s * u + c * v] for u, v in outline]
    spec = {'name': 'demo_dock', 'base': base,
            'polylines': [{'closed': True, 'points': points}]}
    path.write_text(yaml.safe_dump(spec))
    return np.array([DOCK_DISTANCE_M, 0.0, 0.0])


def dock_rows(seen: Recording, truth: np.ndarray) -> list:
    """
    Return the table's rows of the dock: poses published, their error and NEES.

    :param seen: the recording
    :param truth: the dock's true pose in the laser frame (x m, y m, yaw rad)
    :return: rows (measure, value)
    """
    errors, yaw_errors, values = [], [], []
    for _, message in seen.docks:
        pose, q = message.pose.pose.position, message.pose.pose.orientation
        error = np.array([pose.x - truth[0], pose.y - truth[1],
                          float(wrap_angle(2.0 * math.atan2(q.z, q.w) - truth[2]))])
        rows = np.ix_([0, 1, 5], [0, 1, 5])
        covariance = np.array(message.pose.covariance).reshape(6, 6)[rows]
        errors.append(1e3 * math.hypot(*error[:2]))
        yaw_errors.append(math.degrees(abs(error[2])))
        values.append(float(nees(error, covariance)))
    share = 100.0 * len(seen.docks) / max(len(seen.corners), 1)
    return [
        ('dock poses published (per CornerArray)', f'{len(seen.docks)} ({share:.0f} %)'),
        ('dock error against the truth (median mm, deg)',
         f'{np.median(errors):.1f}, {np.median(yaw_errors):.2f}' if errors else '-'),
        ('dock NEES against the truth (mean; 3 = calibrated)',
         f'{np.mean(values):.2f}' if values else '-'),
    ]


def corners_seen_from(plan, pose: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the plan's corners a full S1 turn sees from a pose, and the others, in its frame.

    :param plan: the floor plan
    :param pose: the sensor's pose in the plan (x m, y m, yaw rad); None: the plan's own
    :return: (corners in view (M, 2), the other corners (H, 2)), laser frame, m
    """
    walls, corners = plan.in_sensor_frame(pose)
    _, _, bearings = full_turn_bearings(S1_BEAMS_PER_TURN)
    in_view = visible_corners(walls, corners, bearings)
    return corners[in_view], corners[~in_view]


def truth_poses(path: pathlib.Path) -> Callable[[float], np.ndarray]:
    """
    Read the emulator's true poses (simulated_rplidar --truth) and interpolate them in time.

    :param path: the CSV file (time_s, x_m, y_m, yaw_rad; yaw unwrapped)
    :return: wall-clock time (s) -> the sensor's pose in the plan (x m, y m, yaw rad)
    :raises RuntimeError: when the file holds fewer than two poses
    """
    rows = np.loadtxt(path, delimiter=',', skiprows=1, ndmin=2)
    if len(rows) < 2:
        raise RuntimeError(f'the emulator logged {len(rows)} true poses in {path}')
    return lambda time_s: np.array([np.interp(time_s, rows[:, 0], rows[:, k]) for k in (1, 2, 3)])


def _stamp_ns(message) -> int:
    return message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec


def odometry_rows(seen: Recording, pose_at: Callable[[float], np.ndarray]) -> list:
    """
    Return the table's rows of the odometry against the emulator's truth.

    Each Odometry is compared with the true pose half a turn after its scan's stamp
    (:data:`HALF_TURN_S`). The step into each pose and its
    covariance are the twist's times the time since the previous one, as the message defines
    them (:mod:`wctls_ros.odometry_messages`).

    :param seen: the recording
    :param pose_at: wall-clock time (s) -> the sensor's true pose in the plan
    :return: rows (measure, value)
    """
    from .evaluation.trajectory import trajectory_errors
    messages = [message for _, message in seen.odometry]
    if len(messages) < 2:
        return [('odometry poses recorded', f'{len(messages)}')]
    stamps = 1e-9 * np.array([_stamp_ns(message) for message in messages], dtype=float)
    planar = np.ix_([0, 1, 5], [0, 1, 5])
    estimate = np.array([[m.pose.pose.position.x, m.pose.pose.position.y,
                          2.0 * math.atan2(m.pose.pose.orientation.z, m.pose.pose.orientation.w)]
                         for m in messages])
    rates = np.array([[m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z]
                      for m in messages])
    rate_covariances = np.array([np.array(m.twist.covariance).reshape(6, 6)[planar]
                                 for m in messages])
    dt = np.concatenate([[0.0], np.diff(stamps)])
    steps = rates * dt[:, None]
    step_covariances = rate_covariances * (dt ** 2)[:, None, None]
    step_covariances[0] = np.eye(3)                  # row 0: no step into the first pose
    reference = np.array([pose_at(stamp + HALF_TURN_S) for stamp in stamps])
    errors = trajectory_errors(estimate, steps, step_covariances, reference, 0.0, 0.0)
    return [
        ('odometry poses, true path (m)', f'{len(messages)}, {errors.path_m:.2f}'),
        ('odometry RPE over >= 1 m of path (%/m, deg/m)',
         f'{errors.rpe_percent_per_m:.2f}, {errors.rpe_deg_per_m:.2f}'
         if errors.rpe_pairs else '-'),
        ('odometry ATE, SE(2) aligned (m)', f'{errors.ate_m:.3f}'),
        ('odometry steps within 10 cm and 2 deg of the truth',
         f'{100 * errors.steps_within:.1f} %'),
        ('odometry step NEES (mean; 3 = honest), inside the 95 % gate',
         f'{errors.nees_mean:.2f}, {100 * errors.nees_in_gate:.1f} %'),
    ]


def summarise(seen: Recording, truth_at: Callable[[int], Tuple[np.ndarray, np.ndarray]]) -> tuple:
    """
    Compute the demo's table from what was recorded, and the notes that explain its counts.

    :param seen: the recording
    :param truth_at: a scan's stamp (ns) -> (the corners the sensor can see then, the plan's
        other corners (the visibility rule says not seen)), laser frame, shapes (M, 2), (H, 2),
        m (:func:`corners_seen_from`)
    :return: (rows (measure, value), notes: sentences)
    """
    counts, sigmas, errors, latency, age, in_view = [], [], [], [], [], []
    near_hidden = 0
    for received, message in seen.corners:
        stamp = _stamp_ns(message)
        truth_xy, hidden_xy = truth_at(stamp)
        in_view.append(len(truth_xy))
        counts.append(len(message.corners))
        if stamp in seen.scans:
            latency.append((received - seen.scans[stamp][0]) * 1e-6)
        age.append((received - stamp) * 1e-6)
        for corner in message.corners:
            covariance = np.array(corner.pose.covariance).reshape(6, 6)[:2, :2]
            sigmas.append(np.sqrt(np.diag(covariance)))
            xy = np.array([corner.pose.pose.position.x, corner.pose.pose.position.y])
            distance = np.hypot(*(truth_xy - xy).T) if len(truth_xy) else np.array([np.inf])
            if distance.min() < MATCH_RADIUS_M:
                errors.append(float(nees(xy - truth_xy[distance.argmin()], covariance)))
            elif len(hidden_xy) and np.hypot(*(hidden_xy - xy).T).min() < MATCH_RADIUS_M:
                near_hidden += 1
    sigmas = np.array(sigmas).reshape(-1, 2)
    counts = np.array(counts)
    rows = [
        ('scans recorded', f'{len(seen.scans)}'),
        ('CornerArrays recorded', f'{len(seen.corners)}'),
        ('corners per scan (mean, min-max)',
         f'{counts.mean():.1f} ({counts.min()}-{counts.max()})' if counts.size else '-'),
        ('true corners in view (mean)', f'{np.mean(in_view):.1f}' if in_view else '-'),
        (f'corners within {MATCH_RADIUS_M * 100:.0f} cm of a true one',
         f'{len(errors)} of {counts.sum()} ({100 * len(errors) / counts.sum():.1f} %)'
         if counts.sum() else '-'),
        ('mean corner sigma x, y (mm)',
         f'{1e3 * sigmas[:, 0].mean():.1f}, {1e3 * sigmas[:, 1].mean():.1f}'
         if sigmas.size else '-'),
        ('NEES against the truth (mean; 2 = calibrated)',
         f'{np.mean(errors):.2f} over {len(errors)} corners' if errors else '-'),
        ('feature_node latency, scan in -> corners in (median, p99 ms)',
         f'{np.median(latency):.1f}, {np.percentile(latency, 99):.1f}' if latency else '-'),
        ('age of the corners since the first beam (median ms)',
         f'{np.median(age):.0f}' if age else '-'),
    ]
    return rows, _notes(seen, counts, max(in_view, default=0), len(errors), near_hidden)


def _notes(seen: Recording, counts: np.ndarray, in_view: int, matched: int,
           near_hidden: int) -> List[str]:
    """
    Explain the counts a reader of the table would ask about.

    :param seen: the recording
    :param counts: corners in each CornerArray, shape (A,)
    :param in_view: true corners in view (the most of any scan)
    :param matched: corners within the match radius of one in view
    :param near_hidden: other corners within it of a true corner not in view
    :return: sentences
    """
    notes = []
    answered = {_stamp_ns(message) for _, message in seen.corners}
    unanswered = sorted(set(seen.scans) - answered)
    if unanswered and answered:
        before = sum(stamp < min(answered) for stamp in unanswered)
        after = sum(stamp > max(answered) for stamp in unanswered)
        skipped = len(unanswered) - before - after
        notes.append(
            f"{len(unanswered)} recorded scans have no CornerArray (before feature_node's "
            f'first answer: {before}; at the end, their corners after the recording stopped: '
            f'{after}; skipped while feature_node was behind: {skipped}, as its one-scan queue '
            'keeps the newest and /diagnostics counts them).')
    if counts.size and counts.max() > in_view:
        notes.append(
            f'Some scans have more corners ({counts.max()}) than the {in_view} true corners '
            f'in view. Of the {counts.sum() - matched} corners not within '
            f'{MATCH_RADIUS_M * 100:.0f} cm of one in view: at a true corner the visibility '
            'rule counts as not in view (a wall seen by fewer than 8 returns or over less than '
            f'15 cm, thin evidence): {near_hidden}; '
            f'false: {counts.sum() - matched - near_hidden}.')
    return notes


def draw(seen: Recording, config, truth_at: Callable[[int], Tuple[np.ndarray, np.ndarray]],
         path: pathlib.Path, dock_truth: Optional[np.ndarray] = None) -> None:
    """
    Draw the scan with the median number of corners: segments, corners, ellipses x10, truth.

    :param seen: the recording
    :param config: the FeatureConfig feature_node ran with (to redraw the same features)
    :param truth_at: a scan's stamp (ns) -> its true corners in view and the others
        (:func:`summarise`)
    :param path: PNG to write
    :param dock_truth: with --dock, the dock's true pose (x, y, yaw): it and the last
        published dock pose are drawn as arrows
    """
    from wctls_ros.conversions import scan_features
    from .plotting import draw_scan_features, pyplot
    received = [message for _, message in seen.corners]
    median = sorted(received, key=lambda m: len(m.corners))[len(received) // 2]
    stamp = _stamp_ns(median)
    scan = seen.scans.get(stamp, next(iter(seen.scans.values())))[1]
    truth_xy = truth_at(_stamp_ns(scan))[0]
    features, _ = scan_features(scan, config)
    ranges = np.asarray(scan.ranges, dtype=float)
    bearings = scan.angle_min + np.arange(len(ranges)) * scan.angle_increment
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8.0, 5.5), dpi=90)
    draw_scan_features(ax, ranges, bearings, features)
    ax.plot(truth_xy[:, 0], truth_xy[:, 1], 'x', color='tab:green', ms=6, label='true corners')
    if dock_truth is not None:
        arrows = [(dock_truth, 'tab:green', 'true dock')]
        if seen.docks:
            pose = seen.docks[-1][1].pose.pose
            arrows.append((np.array([pose.position.x, pose.position.y, 2.0 * math.atan2(
                pose.orientation.z, pose.orientation.w)]), 'tab:purple', 'dock seen'))
        for (x, y, yaw), color, label in arrows:
            ax.arrow(x, y, 0.3 * math.cos(yaw), 0.3 * math.sin(yaw), width=0.01, color=color,
                     label=label)
    ax.set_title(f'make demo: one emulated S1 scan, {len(features.corners)} corners '
                 f'({config.method}), 1-sigma ellipses x10', fontsize=9)
    ax.legend(fontsize=7, loc='best')
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def parser() -> argparse.ArgumentParser:
    """
    Return the command-line parser.

    :return: the parser
    """
    p = Parser(prog='demo', description=__doc__.strip().splitlines()[0])
    p.add_argument('--seconds', type=bounded(float, 1.0), default=20.0,
                   help='how long to record once features flow, s (default: %(default)s)')
    p.add_argument('--out', default='out/demo', help='output folder (default: %(default)s)')
    p.add_argument('--floor-plan', default='environment_a',
                   help='emulated scene: environment_a, environment_b or a YAML file '
                   '(default: %(default)s)')
    p.add_argument('--method', default='wctls', choices=METHODS,
                   help="feature_node's line fit (default: %(default)s)")
    p.add_argument('--model', default='s1', choices=tuple(EMULATED_MODELS),
                   help='the emulated RPLIDAR: its modes, serial rate and motor control, which '
                   'rplidar_node finds as it would on a real one (default: %(default)s)')
    p.add_argument('--dock', action='store_true',
                   help=f'stand the example dock (docs/docking.md) {DOCK_DISTANCE_M:g} m in '
                   'front of the sensor; feature_node looks for it, and its poses are '
                   'recorded and summarised')
    p.add_argument('--moving', action='store_true',
                   help=f'drive the emulated sensor round a circle ({MOVING_RADIUS_M:g} m, '
                   f'{MOVING_SPEED_M_S:g} m/s); odometry_node follows it from the scans, and its '
                   "odometry is recorded and summarised against the emulator's true poses")
    return p


@explains_missing_extras('demo')
def main(argv=None) -> int:
    """
    Run the demo.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status
    """
    args = parser().parse_args(argv)
    try:
        with stop_signals():
            return _run(args)
    except Stopped as stopped:
        print(f'demo: stopped by {stopped}', file=sys.stderr)
        return 128 + stopped.signal_number


def _prepare(out: pathlib.Path) -> None:
    """
    Make the output folder the demo's own: refuse anyone else's, clear an earlier demo's.

    :param out: the output folder
    :raises UserError: when the folder is not the demo's to write
    :raises OSError: when it cannot be written
    """
    earlier = claim(out, 'demo')
    remove_entries(out, earlier)
    (out / 'logs').mkdir(parents=True)
    mark(out, 'demo', OUTPUTS)


def _run(args) -> int:
    """Check the floor plan and the output folder, then run the demo; the exit status."""
    require('rosbags')          # the recording needs it: missing, nothing is started
    if args.dock and args.moving:
        print('demo: error: --dock and --moving: the dock stands in front of a still sensor',
              file=sys.stderr)
        return USER_ERROR
    try:
        plan = load_floor_plan(args.floor_plan)
    except (OSError, ValueError) as error:
        print(f'demo: error: --floor-plan: {" ".join(str(error).split())}', file=sys.stderr)
        return USER_ERROR
    out = pathlib.Path(args.out)
    try:
        _prepare(out)
    except UserError as error:
        print(f'demo: error: --out: {error}', file=sys.stderr)
        return USER_ERROR
    except OSError as error:
        print(f'demo: error: --out: cannot write {out}: {error.strerror or error}',
              file=sys.stderr)
        return USER_ERROR
    try:
        return _live(args, plan, out)
    finally:
        mark(out, 'demo', OUTPUTS)        # what it wrote, as written: the next run replaces it


def _live(args, plan, out: pathlib.Path) -> int:
    """Start, record, stop and summarise into an output folder of the demo's; the status."""
    domain = private_network(os.environ)
    tty = out.resolve() / 'ttyS1'
    # The landmark tracks too: their ids on landmarks and, as labels, on landmark_markers.
    parameters: dict = {'method': args.method, 'publish_landmarks': True}
    floor_plan, dock_truth = args.floor_plan, None
    if args.dock:
        floor_plan = str(out.resolve() / 'dock_plan.yaml')
        dock_truth = dock_plan(args.floor_plan, pathlib.Path(floor_plan))
        plan = load_floor_plan(floor_plan)
        parameters['dock_enabled'] = True
    emulator_options, truth_file = [], out / 'truth.csv'
    if args.moving:
        x_m, y_m, yaw_rad = plan.sensor_pose
        emulator_options = ['--pose', str(x_m), str(y_m),
                            str(math.degrees(yaw_rad) + MOVING_TURN_DEG),
                            '--circle', str(MOVING_RADIUS_M), str(MOVING_SPEED_M_S),
                            '--truth', str(truth_file)]
    processes = Processes(out / 'logs')
    seen = Recording()
    try:
        _start_nodes(processes, args, tty, floor_plan, parameters, emulator_options)
        nodes = 'feature_node and odometry_node' if args.moving else 'feature_node'
        print(f'demo: {args.model.upper()} emulator on {tty} -> rplidar_node -> {nodes} '
              f'(ROS_DOMAIN_ID {domain}, logs in {out / "logs"})', flush=True)
        check_stop()
        seen = record(out / 'bag', args.seconds, dock=args.dock, odometry=args.moving)
    except Stopped as stopped:
        seen.stopped_by = stopped.signal_number
    except RuntimeError as error:
        print(f'demo: {error}', file=sys.stderr)
        return 1
    finally:
        # Stopping takes up to STOP_TIMEOUT_S: a signal meanwhile is only noted, and honoured
        # once every process has stopped.
        if seen.stopped_by:
            print('demo: interrupted; stopping everything', file=sys.stderr)
        processes.stop_all()
    stopped_by = stop_requested()
    if stopped_by and not seen.stopped_by:
        print('demo: interrupted; every process stopped', file=sys.stderr)
    if stopped_by:
        return 128 + stopped_by
    if not seen.corners:
        print(f'demo: no corners recorded (see {out / "logs"})', file=sys.stderr)
        return 1
    config = feature_settings(
        load_parameters(_config_file('wctls_ros') / 'feature_node.yaml', overrides=parameters))[0]
    _summarise_into(out, seen, plan, config, dock_truth,
                    truth_poses(truth_file) if args.moving else None)
    return 0


def _start_nodes(processes: Processes, args, tty: pathlib.Path, floor_plan: str,
                 parameters: dict, emulator_options: List[str]) -> None:
    """Start the emulator, then rplidar_node reading it, feature_node and odometry_node."""
    emulator = processes.start('simulated_rplidar', [
        _executable('wctls_lab', 'simulated_rplidar'), '--link', str(tty), '--floor-plan',
        floor_plan, '--model', args.model, *emulator_options])
    _wait_for(tty, emulator, 20.0)
    processes.start('rplidar_node', [
        _executable('wctls_rplidar', 'rplidar_node'), '--ros-args', '--params-file',
        str(_config_file('wctls_rplidar') / 'rplidar_s1.yaml'), '-p', f'serial_port:={tty}'])
    processes.start('feature_node', [
        _executable('wctls_ros', 'feature_node'), '--ros-args', '--params-file',
        str(_config_file('wctls_ros') / 'feature_node.yaml')]
        + [arg for k, v in parameters.items() for arg in ('-p', f'{k}:={v}')])
    if args.moving:
        processes.start('odometry_node', [
            _executable('wctls_ros', 'odometry_node'), '--ros-args', '--params-file',
            str(_config_file('wctls_ros') / 'odometry_node.yaml'), '-p',
            f'method:={args.method}'])


def _summarise_into(out: pathlib.Path, seen: Recording, plan, config,
                    dock_truth: Optional[np.ndarray],
                    pose_at: Optional[Callable[[float], np.ndarray]]) -> None:
    """
    Print the table and write it, and the figure, into the output folder.

    :param out: the output folder
    :param seen: the recording
    :param plan: the floor plan the emulator saw
    :param config: feature_node's FeatureConfig
    :param dock_truth: with --dock, the dock's true pose in the laser frame
    :param pose_at: with --moving, the emulator's true poses (:func:`truth_poses`)
    """
    if pose_at is None:
        still = corners_seen_from(plan)

        def truth_at(stamp_ns: int) -> Tuple[np.ndarray, np.ndarray]:
            return still
    else:
        def truth_at(stamp_ns: int) -> Tuple[np.ndarray, np.ndarray]:
            return corners_seen_from(plan, pose_at(1e-9 * stamp_ns + HALF_TURN_S))
    rows, notes = summarise(seen, truth_at)
    if dock_truth is not None:
        rows += dock_rows(seen, dock_truth)
    if pose_at is not None:
        rows += odometry_rows(seen, pose_at)
    width = max(len(name) for name, _ in rows)
    table = '\n'.join(f'{name:<{width}}  {value}' for name, value in rows)
    draw(seen, config, truth_at, out / 'scan.png', dock_truth)
    (out / 'summary.md').write_text(
        '| measure | value |\n|---|---|\n'
        + '\n'.join(f'| {name} | {value} |' for name, value in rows) + '\n'
        + ''.join(f'\n- {note}' for note in notes) + ('\n' if notes else ''))
    print(f'\n{table}\n' + ''.join(f'\n{textwrap.fill(note, 99)}\n' for note in notes))
    print(f'demo: wrote {out / "bag"} (mcap: open it in Foxglove), {out / "scan.png"} and '
          f'{out / "summary.md"}')


if __name__ == '__main__':
    sys.exit(main())
