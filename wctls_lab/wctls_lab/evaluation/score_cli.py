# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``score``: precision, recall and NEES against truth, recurrence on static recordings, per method.

Examples::

    score out/env_a_cluttered                             # truth.yaml from simulate, inside
    score data/sick_lms111_static --labels data/labels/sick_lms111_static.yaml --out out/lms111
    score data/urg04lx_office --labels data/labels/urg04lx_office.yaml    # scans 0-24 (labels)
    score data/lms111_building --labels data/labels/lms111_building.yaml  # 6 JSON scans
    score out/env_b --config my_feature_node.yaml --methods wtls --scans 0-49

    score data/urg04lx_office --still no                  # carried: the pose-free test only
    score robot_bag --poses poses.csv --pose-sigma-m 0.02 --pose-sigma-deg 0.5

Every run also tests the re-observations of corners and lines in consecutive scans
(:mod:`.reobservation`), with poses in the world frame. Offline: reads the bag with rosbags
and never starts ROS. Exit status 0, or 2 with one line ``score: error: ...`` on a bad path,
bag, label file, pose file, configuration or option, or a moving sensor without truth, poses
or --still no.
"""

import argparse
import math
import pathlib
import shlex
import sys
import time
from typing import Dict, Optional

import numpy as np
from wctls_ros.cli import bounded, Parser, start_core, USER_ERROR, UserError
from wctls_ros.core import FeatureConfig, METHODS
from wctls_ros.extras import explains_missing_extras, require
from wctls_ros.frontend.tracking import Motion
from wctls_ros.output_folders import claim, owned_folder
from wctls_ros.params import feature_settings, load_parameters, SENSOR
from wctls_ros.process import check_stop, ending_at_once, stop_signals, Stopped
from wctls_ros.sensors import DEFAULT_SENSOR, sensor_presets

from .poses import load_poses, poses_at, poses_from_bag
from .rules import check_still, corners_per_scan_figure
from .scans import load_json_scans, load_scans, StaticScans
from .score import (markdown_table, RECURRING_PRESENCE, REOBSERVATION_COLUMNS, score_scans,
                    write_score)
from .tracks import run_tracker, track_figures, track_lines
from .trajectory import run_odometry, score_trajectory
from .truth import load_truth, Truth, TRUTH_FILE


def parser() -> argparse.ArgumentParser:
    """
    Return the command-line parser.

    :return: the parser
    """
    p = Parser(
        prog='score',
        description='Score the corners of every method on a recording: precision, recall and '
        "NEES against true corners (a simulation's truth.yaml beside the bag, or hand labels), "
        'and on a static recording the recurrence of corners and their NEES against their '
        'mean. Prints a Markdown table; with --out also writes table.md, table.csv, '
        'corners.csv and score.png. Semantics: wctls_lab.evaluation.score.')
    p.add_argument('bag', help='ROS 2 (mcap/sqlite3) or ROS 1 bag, a JSON scan '
                   '{ranges, bearings}, or a folder of JSON scans')
    p.add_argument('--labels', default=None,
                   help=f'true corners (YAML, wctls_lab.evaluation.truth); default: '
                   f'{TRUTH_FILE} inside the bag folder when there is one')
    p.add_argument('--methods', default=','.join(METHODS),
                   help='comma-separated methods among ' + ', '.join(METHODS)
                   + ' (default: %(default)s)')
    p.add_argument('--config', default=None,
                   help='feature_node parameter YAML (as for --params-file); default: the '
                   "node's defaults")
    p.add_argument('--sensor', default=None, choices=tuple(sensor_presets()),
                   help='sensor preset whose noise model the covariances use, over the '
                   f"config file's (default: the file's, else {DEFAULT_SENSOR})")
    p.add_argument('--range-sigma', type=float, default=None,
                   help='range noise std of the covariances, m (default: that of --config)')
    p.add_argument('--bearing-sigma-deg', type=float, default=None,
                   help='bearing noise std of the covariances, deg (default: that of --config)')
    p.add_argument('--common-range-sigma', type=float, default=None,
                   help='per-scan common range offset std, m (default: that of --config)')
    p.add_argument('--scans', default=None, metavar='FIRST-LAST',
                   help='score only these scans (0-based, inclusive); default: all, or the '
                   'ones the labels cover')
    p.add_argument('--topic', default=None, help="LaserScan topic (default: the bag's only one)")
    p.add_argument('--still', choices=('auto', 'yes', 'no'), default='auto',
                   help='measure recurrence: when the stillness check passes (auto), or treat '
                   'the scans as still or not whatever it says, e.g. for a hand-held sensor '
                   'that drifts by a centimetre; auto refuses a moving sensor without truth '
                   'or poses, no scores its re-observations (default: %(default)s)')
    p.add_argument('--min-presence', type=float, default=RECURRING_PRESENCE,
                   help='a corner recurs when found in at least this share of the scans '
                   '(default: %(default)s)')
    p.add_argument('--poses', default=None, metavar='FILE',
                   help='poses of the sensor (CSV with the header stamp_s,x_m,y_m,yaw_rad), '
                   "interpolated to each scan's stamp: corners and lines are tracked in the "
                   'world frame and their re-observations tested (default: none; the pose-free '
                   'test runs in any case)')
    p.add_argument('--poses-topic', default=None, metavar='TOPIC',
                   help='like --poses, from a nav_msgs/msg/Odometry or tf2_msgs/msg/TFMessage '
                   'topic of the bag (default: none)')
    p.add_argument('--tf-frames', nargs=2, default=('odom', 'base_link'),
                   metavar=('PARENT', 'CHILD'),
                   help='with a TF --poses-topic: the transform that gives the robot pose '
                   '(default: odom base_link)')
    p.add_argument('--laser-offset', type=float, nargs=3, default=(0.0, 0.0, 0.0),
                   metavar=('X_M', 'Y_M', 'YAW_DEG'),
                   help="the sensor's pose in the frame of the poses (default: 0 0 0)")
    p.add_argument('--pose-sigma-m', type=bounded(float, 0.0), default=0.0,
                   help='position sigma of the poses, each axis, m (default: %(default)s)')
    p.add_argument('--pose-sigma-deg', type=bounded(float, 0.0), default=0.0,
                   help='heading sigma of the poses, deg (default: %(default)s)')
    p.add_argument('--tracks', action='store_true',
                   help='also run the landmark tracker (the first method) and print its '
                   'figures: confirmed tracks, their lengths, id switches and duplicates per '
                   '100 scans, the gate share, and with labels confirmed-landmark precision and '
                   'recall (wctls_lab.evaluation.tracks)')
    p.add_argument('--step-sigma', type=bounded(float, 0.0), nargs=2, default=None,
                   metavar=('M', 'DEG'),
                   help='with --tracks: sigma of each step between scans (default: with poses '
                   'sqrt(2) times the pose sigmas, the difference of two independent pose '
                   'errors; without, 0 0: a still sensor)')
    p.add_argument('--odometry', action='store_true',
                   help='with poses: also run the odometry from the features (the first '
                   "method's) and compare its trajectory with the poses: RPE per metre, ATE "
                   "after SE(2) alignment, step NEES with the poses' sigmas as their jitter; "
                   "with --tracks, the tracks again with the odometry's steps as the motion")
    p.add_argument('--out', default=None, help='folder for table.md, table.csv, corners.csv, '
                   'score.png: a new or empty folder, or an earlier output of score, which is '
                   'replaced (default: print only)')
    p.add_argument('--title', default=None, help='report title (default: the bag name)')
    return p


def node_config(path=None, sensor: Optional[str] = None) -> FeatureConfig:
    """
    Return the pipeline settings feature_node would run with, checked as the node does.

    :param path: a feature_node parameter file (None: the node's defaults)
    :param sensor: a sensor preset, over the file's (None: the file's, else the default)
    :return: the configuration
    :raises ValueError: when the node would refuse the file or the sensor
    """
    overrides = {} if sensor is None else {SENSOR: sensor}
    return feature_settings(load_parameters(path, overrides=overrides)).config


def configs(args, methods) -> Dict[str, FeatureConfig]:
    """
    Return the configuration of every method: the file's (or defaults) with the sigmas given.

    :param args: the parsed arguments
    :param methods: the methods
    :return: method -> configuration
    :raises ValueError: on values the pipeline refuses
    """
    base = node_config(args.config, args.sensor)
    given = {'range_sigma_m': args.range_sigma,
             'bearing_sigma_rad': (None if args.bearing_sigma_deg is None
                                   else math.radians(args.bearing_sigma_deg)),
             'common_range_sigma_m': args.common_range_sigma}
    base = base.replace(**{k: v for k, v in given.items() if v is not None})
    return {method: base.replace(method=method) for method in methods}


def _scan_range(text: Optional[str], truth: Optional[Truth]):
    """Return (first, last or None) of the scans to score."""
    if text is None:
        return (truth.first_scan, truth.last_scan) if truth is not None else (0, None)
    first, dash, last = text.partition('-')
    if not (first.isdigit() and dash and last.isdigit() and int(first) <= int(last)):
        raise UserError(f'--scans wants FIRST-LAST, e.g. 0-24; got {text!r}')
    return int(first), int(last)


def load_recording(path, topic: Optional[str]) -> StaticScans:
    """
    Read the scans of a bag, a JSON scan or a folder of JSON scans.

    :param path: the recording
    :param topic: the LaserScan topic of a bag (None: its only one)
    :return: the scans
    """
    path = pathlib.Path(path)
    if not path.exists():
        raise UserError(f'{path}: no such bag or scan file')
    if path.suffix == '.json' or (path.is_dir() and any(path.glob('*.json'))
                                  and not any(path.glob('metadata.yaml'))):
        return load_json_scans(path)
    return load_scans(path, topic)


def _truth(args) -> Optional[Truth]:
    """Return the labels given, or the truth inside the bag folder, or None."""
    if args.labels is not None:
        return load_truth(args.labels)
    inside = pathlib.Path(args.bag) / TRUTH_FILE
    return load_truth(inside) if inside.is_file() else None


def _poses(args, scans: StaticScans):
    """Return the sensor pose of each scan (NaN rows where the poses do not reach), or None."""
    if args.poses is not None and args.poses_topic is not None:
        raise UserError('give --poses or --poses-topic, not both')
    if args.poses is None and args.poses_topic is None:
        return None
    source = (load_poses(args.poses) if args.poses is not None else
              poses_from_bag(args.bag, args.poses_topic, tuple(args.tf_frames)))
    x, y, yaw_deg = args.laser_offset
    poses = poses_at(source, scans.stamps_ns * 1e-9, (x, y, math.radians(yaw_deg)))
    covered = int(np.isfinite(poses).all(axis=1).sum())
    if covered < 2:
        raise UserError(f'{args.poses or args.poses_topic}: the poses cover {covered} of the '
                        f'{len(scans)} scans '
                        f'(stamps {scans.stamps_ns[0] * 1e-9:.3f}-'
                        f'{scans.stamps_ns[-1] * 1e-9:.3f} s); at least 2 are needed')
    return poses


def _track_lines(args, scans: StaticScans, config: FeatureConfig, truth: Optional[Truth],
                 poses: Optional[np.ndarray]) -> list:
    """Run the landmark tracker over the scans with known poses; return its figures' lines."""
    pose_sigma_rad = math.radians(args.pose_sigma_deg)
    step_m, step_rad = ((math.sqrt(2.0) * args.pose_sigma_m, math.sqrt(2.0) * pose_sigma_rad)
                        if args.step_sigma is None and poses is not None else
                        (0.0, 0.0) if args.step_sigma is None else
                        (args.step_sigma[0], math.radians(args.step_sigma[1])))
    if poses is not None:
        known = np.isfinite(poses).all(axis=1)
        if truth is not None and not known.all():
            raise UserError('--tracks with labels needs a pose for every scan')
        scans = StaticScans(scans.ranges[known], scans.angle_min, scans.angle_increment,
                            scans.range_min, scans.range_max, scans.stamps_ns[known],
                            scans.source)
        poses = poses[known]
    runs = [(f'steps of sigma {1e3 * step_m:g} mm and {math.degrees(step_rad):g} deg',
             run_tracker(scans, config, poses, step_m, step_rad))]
    if args.odometry:
        # As a robot without a reference runs it: the odometry's own steps and covariances.
        odometry = run_odometry(scans, config)
        motions = [Motion(step, covariance) for step, covariance
                   in zip(odometry.steps, odometry.step_covariances)]
        runs.append(('steps and covariances of the odometry from the features',
                     run_tracker(scans, config, poses, motions=motions)))
    lines = []
    for steps, run in runs:
        lines.append(f'{len(scans)} scans, {steps}; tracker {1e3 * run.seconds_per_scan:.2f} ms '
                     'per scan')
        lines += track_lines([track_figures(run, kind, truth, max(args.pose_sigma_m, 1e-3),
                                            max(pose_sigma_rad, 1e-3))
                              for kind in ('corner', 'line')])
    return lines


def run(args, argv) -> int:
    """Load, score, print and write; raise on what the user gave wrong."""
    methods = [m.strip() for m in args.methods.split(',') if m.strip()]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown or not methods:
        raise UserError(f'unknown methods {unknown}; choose among {", ".join(METHODS)}')
    if not 0.0 < args.min_presence <= 1.0:
        raise UserError(f'--min-presence must be in (0, 1], got {args.min_presence}')
    if args.out is not None:        # refused now rather than after the scoring
        claim(args.out, 'score')
    settings = configs(args, methods)
    truth = _truth(args)
    first, last = _scan_range(args.scans, truth)
    with ending_at_once('score'):          # a step of seconds that writes nothing
        recording = load_recording(args.bag, args.topic)
    check_stop()
    last = len(recording) - 1 if last is None else last
    if last >= len(recording):
        raise UserError(f'scans {first}-{last} asked for, {args.bag} has {len(recording)}')
    scans = StaticScans(recording.ranges[first:last + 1], recording.angle_min,
                        recording.angle_increment, recording.range_min, recording.range_max,
                        recording.stamps_ns[first:last + 1], recording.source)
    if truth is not None:
        truth_first, truth_last = truth.covered(len(recording))
        if not truth_first <= first <= last <= truth_last:
            raise UserError(f'the labels cover scans {truth_first}-{truth_last}, not '
                            f'{first}-{last}')
        truth = truth.select(first, len(scans))
    poses = _poses(args, scans)
    with ending_at_once('score'):
        check = check_still(scans)
    still = {'auto': check.still, 'yes': True, 'no': False}[args.still]
    if truth is None and poses is None and args.still == 'auto' and not still:
        raise UserError(f'{args.bag}: refused: the sensor or scene is not still '
                        f'({check.describe()}): recurrence needs a static recording and there '
                        f'is no truth (--labels, or {TRUTH_FILE} beside the scans); for a '
                        'moving sensor say so: --still no tests the re-observations without '
                        'poses, --poses FILE or --poses-topic TOPIC with them')
    if args.odometry and poses is None:
        raise UserError('--odometry compares the odometry with the poses: give --poses or '
                        '--poses-topic')
    started = time.monotonic()
    table = score_scans(scans, settings, truth, still, args.min_presence, poses,
                        args.pose_sigma_m, math.radians(args.pose_sigma_deg))
    check_stop()
    elapsed = time.monotonic() - started
    config = settings[methods[0]]
    notes = [f'scans {first}-{last} of {args.bag} ({len(scans)} scans, '
             f'{scans.ranges.shape[1]} beams)',
             f'covariance model: range {1e3 * config.range_sigma_m:.2f} mm, bearing '
             f'{math.degrees(config.bearing_sigma_rad):.3f} deg, common-mode '
             f'{1e3 * config.common_range_sigma_m:.2f} mm'
             + (f' (from {args.config})' if args.config else ''),
             'truth: ' + ('none' if truth is None else
                          f'{args.labels or pathlib.Path(args.bag) / TRUTH_FILE} '
                          f'({len(truth.ids)} corners)'),
             f'stillness check: {check.describe()} ({"still" if check.still else "moved"}); '
             + ('recurrence measured' if still else 'recurrence refused: it needs a still '
                'sensor')
             + (f' (--still {args.still})' if args.still != 'auto' else ''),
             'poses: ' + ('none' if poses is None else
                          f'{args.poses or args.poses_topic}, '
                          f'{int(np.isfinite(poses).all(axis=1).sum())} of '
                          f'{len(scans)} scans covered, '
                          f'sigma {1e3 * args.pose_sigma_m:g} mm and {args.pose_sigma_deg:g} '
                          'deg'),
             f'scored in {elapsed:.1f} s']
    if args.odometry:
        # In the notes: printed, and in table.md with the command that made them.
        errors = score_trajectory(scans, config, poses, args.pose_sigma_m,
                                  math.radians(args.pose_sigma_deg))
        notes += [f'odometry ({config.method}): {line}' for line in errors.lines()]
    print('\n'.join(f'# {note}' for note in notes))
    print(markdown_table(table))
    print(markdown_table(table, REOBSERVATION_COLUMNS))
    for scored in table.methods:
        print(f'# {scored.method}: corners per scan '
              f'{corners_per_scan_figure(scored.per_scan):.3f}')
        print('\n'.join(f'# {scored.method}: {line}' for line in scored.reobservation.lines()))
    if args.tracks:
        print('\n'.join(f'# {methods[0]} tracks: {line}' for line in _track_lines(
            args, scans, settings[methods[0]], truth, poses)))
    if args.out is not None:
        command = 'score ' + ' '.join(shlex.quote(a) for a in
                                      (sys.argv[1:] if argv is None else argv))
        try:
            with owned_folder(args.out, 'score') as staging:
                # Drawing the figures: a step of a second or two beside a busy machine.
                with ending_at_once('score', removing=staging):
                    written = write_score(table, staging,
                                          args.title or pathlib.Path(args.bag).name, command,
                                          notes)
                check_stop()            # before the files move in: a stop leaves nothing
        except OSError as error:            # a full disk, a file-size limit, no permission
            raise UserError(f'cannot write {args.out}: {error.strerror or error}') from error
        path = pathlib.Path(args.out) / written.name
        print(f'score: wrote {path}')
    return 0


@explains_missing_extras('score')
def main(argv=None) -> int:
    """
    Run ``score``.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status: 0, or 2 on a user error (one line on stderr)
    """
    args = parser().parse_args(argv)
    from wctls_ros.bags import BagError
    try:
        with stop_signals():
            with ending_at_once('score'):
                require('rosbags')     # reads bags: missing, the tool ends before it starts
                start_core('score')
            return run(args, argv)
    except Stopped as stopped:
        print(f'score: stopped by {stopped}', file=sys.stderr)
        return 128 + stopped.signal_number
    except (BagError, OSError, ValueError) as error:
        message = str(error).splitlines()[0] if str(error) else type(error).__name__
        print(f'score: error: {message}', file=sys.stderr)
        return USER_ERROR


if __name__ == '__main__':
    sys.exit(main())
