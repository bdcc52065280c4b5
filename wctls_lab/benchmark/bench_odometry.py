#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark the odometry from the features on every recording of data/ with poses, and the still.

Per moving recording (its poses.csv and laser_mount.yaml): RPE per metre (pairs of >= 1 m of
reference path, chosen on the reference), ATE after SE(2) alignment, the share of steps within
10 cm and 2 deg, the step NEES with the reference's jitter (per pose: the tracking system of
the RPLIDAR car 5 mm and 0.5 deg, the SLAM-corrected keyframes of Malaga and gh25 1 cm and
0.5 deg) and its share inside the 95 % gate, the statuses, and the odometry's time per scan
(the extraction left out; the compiled core is loaded, or compiled, before the first scan, so
that where numba is at hand every scan is timed with the compiled core serving, none with the
numpy steps that serve while it loads in the background). Per still recording: the drift at
its end and its largest. Every reference side by side in one run: scan to keyframe (the
default), scan to scan, and scan to a local map of the landmarks of the last 3 and 10 scans
(docs/odometry.md#local-map).

With ``--wheel``: the moving recordings with and without a wheel odometry as the prior, side
by side. No recording of data/ holds one, so it is synthetic: the reference's robot step
between two scans plus noise drawn (seeded) from the wheel model's covariance at its
defaults (5 % of the distance + 2 mm, 5 % of the turn + 0.2 deg), that covariance stated to
the odometry; then the same steps with the reference's own jitter (as in the step NEES) added
to the stated covariance. A wheel this good relative to the reference, tuned on nothing.

With ``--kiss PYTHON``: KISS-ICP too, in the interpreter PYTHON of a virtual environment that
has it (``pip install kiss-icp``; not a dependency of ours): the scans as z = 0 clouds of their
finite returns within range, deskew off, voxel 0.1 m, scored by the same code with its fixed
0.1 covariance, its time per scan its ``register_frame``'s.
With ``--rf2o BINARY``: rf2o_laser_odometry too, its ``CLaserOdometry2D`` built stand-alone
(never committed; the interface in :func:`rf2o`), scored with the covariance it computes.
With ``--twins``: the odometry's time per scan by its numpy steps and by their compiled twin
(docs/odometry.md#time-per-scan), side by side on the same landmarks (extracted once),
alternating in one process, best of three passes, the slowest scan and the median too; and
whether both give the same statuses and counts on every scan, and how far their poses lie
apart, m.
Usage: python bench_odometry.py [--wheel | --twins] [--kiss PYTHON] [--rf2o BINARY] [recording ...]
"""

import math
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

from wctls_lab.evaluation.poses import load_poses, poses_at
from wctls_lab.evaluation.scans import load_scans
from wctls_lab.evaluation.score_cli import node_config
from wctls_lab.evaluation.trajectory import (drift, reference_step_covariance, run_odometry,
                                             trajectory_errors)
from wctls_ros.core import extract_features, runtime
from wctls_ros.frontend.frames import landmarks_from_features
from wctls_ros.frontend.odometry import compose, inverse, Odometry, OdometryConfig
from wctls_ros.frontend.wheel import laser_prior, WheelModel
from wctls_ros.plain_yaml import load_without_aliases

DATA = pathlib.Path(__file__).resolve().parents[2] / 'data'
# Recording -> (sensor preset, the reference's per-pose jitter m, deg).
MOVING = {'rplidar_barc_moving': ('rplidar_a2', 0.005, 0.5),
          'mrpt_malaga_moving': (None, 0.01, 0.5),
          'tuw_gh25_moving': (None, 0.01, 0.5)}
STILL = ('sick_lms111_static', 'sick_lms1xx_static', 'sick_lms511_static',
         'sick_tim781s_static')
REFERENCES = {'keyframe': OdometryConfig(),
              'scan to scan': OdometryConfig(keyframe_m=0.0, keyframe_rad=0.0),
              'local map, 3 scans': OdometryConfig(map_memory_scans=3),
              'local map, 10 scans': OdometryConfig(map_memory_scans=10)}


def synthetic_wheel(robot: np.ndarray, mount: np.ndarray, seed: int = 0,
                    jitter=None) -> list:
    """
    Return a wheel prior per scan: the reference robot's step plus noise from the model.

    :param robot: the robot's reference pose at each scan, shape (T, 3); NaN where unknown
    :param mount: the laser's pose on the robot
    :param seed: the noise's seed
    :param jitter: (m, rad) the reference's per-pose jitter, whose step covariance the stated
        covariance adds; None: the model's alone
    :return: per scan a Prior, or None (the first scan, unknown poses)
    """
    rng = np.random.default_rng(seed)
    model = WheelModel()
    priors = [None]
    for k, (before, after) in enumerate(zip(robot[:-1], robot[1:]), start=1):
        if not (np.isfinite(before).all() and np.isfinite(after).all()):
            priors.append(None)
            continue
        step = compose(inverse(before), after)
        covariance = model.covariance(step)
        stated = covariance if jitter is None else covariance + reference_step_covariance(
            robot, k, *jitter)
        priors.append(laser_prior(step + rng.multivariate_normal(np.zeros(3), covariance),
                                  stated, mount))
    return priors


def moving(name: str, reference: str, wheel: str = '') -> str:
    """Return one table row of a moving recording (wheel: '', 'model' or 'with jitter')."""
    folder = DATA / name
    sensor, sigma_m, sigma_deg = MOVING[name]
    scans = load_scans(folder)
    mount = load_without_aliases((folder / 'laser_mount.yaml').read_text())
    mount = np.array([mount['x_m'], mount['y_m'], mount['yaw_rad']])
    reference_poses = load_poses(folder / 'poses.csv')
    jitter = (sigma_m, math.radians(sigma_deg)) if wheel == 'with jitter' else None
    priors = (synthetic_wheel(poses_at(reference_poses, scans.stamps_ns * 1e-9), mount,
                              jitter=jitter) if wheel else None)
    run = run_odometry(scans, node_config(None, sensor), REFERENCES[reference], priors)
    poses = poses_at(reference_poses, run.stamps_s, tuple(mount))
    known = np.isfinite(poses).all(axis=1)
    errors = trajectory_errors(run.poses[known], run.steps[known],
                               run.step_covariances[known], poses[known], sigma_m,
                               math.radians(sigma_deg))
    statuses = ', '.join(f'{s} {run.statuses.count(s)}' for s in sorted(set(run.statuses)))
    row = (f'| {name} | {reference} | {errors.rpe_percent_per_m:.2f} | '
           f'{errors.rpe_deg_per_m:.2f} | {errors.ate_m:.3f} | {100 * errors.steps_within:.1f} '
           f'| {errors.nees_mean:.2f} | {100 * errors.nees_in_gate:.1f} | {statuses} | ')
    if wheel:
        used = sum(source == 'wheel' and not rejected
                   for source, rejected in zip(run.prior_sources, run.prior_rejected))
        row += f'{used} / {sum(run.prior_rejected)} | '
    return row + f'{1e3 * run.odometry_s:.1f} |'


# Run in KISS-ICP's interpreter: the clouds of argv[1] (npz) in, its poses and time out.
KISS_ICP = """
import math, sys, time
import numpy as np
from kiss_icp.config import KISSConfig
from kiss_icp.kiss_icp import KissICP
clouds = np.load(sys.argv[1])
config = KISSConfig()
config.data.deskew = False
config.data.max_range = float(clouds['max_range'])
config.mapping.voxel_size = 0.1
odometry, poses, spent = KissICP(config), [], 0.0
for k in range(int(clouds['count'])):
    points = clouds[f'c{k}']
    start = time.perf_counter()
    odometry.register_frame(points, np.zeros(len(points)))
    spent += time.perf_counter() - start
    pose = odometry.last_pose
    poses.append([pose[0, 3], pose[1, 3], math.atan2(pose[1, 0], pose[0, 0])])
np.savez(sys.argv[2], poses=np.array(poses), seconds=spent / max(len(poses), 1))
"""


def kiss_icp(name: str, python: str) -> str:
    """Return one table row of KISS-ICP on a moving recording, run by another interpreter."""
    scans = load_scans(DATA / name)
    angles = scans.angle_min + scans.angle_increment * np.arange(scans.ranges.shape[1])
    clouds = {'max_range': np.array(scans.range_max), 'count': np.array(len(scans.ranges))}
    for k, ranges in enumerate(scans.ranges):
        kept = np.isfinite(ranges) & (ranges >= scans.range_min) & (ranges <= scans.range_max)
        clouds[f'c{k}'] = np.column_stack([ranges[kept] * np.cos(angles[kept]),
                                           ranges[kept] * np.sin(angles[kept]),
                                           np.zeros(kept.sum())]).astype(float)
    with tempfile.TemporaryDirectory() as folder_out:
        inputs, outputs = pathlib.Path(folder_out, 'in.npz'), pathlib.Path(folder_out, 'out.npz')
        np.savez(inputs, **clouds)
        subprocess.run([python, '-c', KISS_ICP, str(inputs), str(outputs)], check=True)
        result = np.load(outputs)
        laser, seconds = result['poses'], float(result['seconds'])
    # Its published covariance: a fixed 0.1.
    covariances = np.repeat(0.1 * np.eye(3)[None], len(laser), axis=0)
    return external_row(name, 'KISS-ICP', scans, laser, covariances, seconds)


def rf2o(name: str, binary: str) -> str:
    """
    Return one table row of rf2o_laser_odometry on a moving recording, run by a local build.

    BINARY reads a text file, a line ``count width angle_min angle_max angle_increment`` then
    per scan ``stamp_s`` and its ``width`` ranges (0 where invalid), runs rf2o's
    ``CLaserOdometry2D`` as its node does (``init`` on the first scan, ``odometryCalculation``
    on each next, the laser at the robot's origin) and prints per scan the laser's pose, the
    upper triangle of ``cov_odo`` and the milliseconds of the call:
    ``x y yaw c00 c01 c02 c11 c12 c22 ms``. rf2o publishes no covariance (all zero); ``cov_odo``
    is the one it computes, of the finest level's step in the laser frame, scored here.
    """
    scans = load_scans(DATA / name)
    ranges = np.where(np.isfinite(scans.ranges) & (scans.ranges >= scans.range_min)
                      & (scans.ranges <= scans.range_max), scans.ranges, 0.0)
    width = ranges.shape[1]
    angle_max = scans.angle_min + scans.angle_increment * (width - 1)
    with tempfile.TemporaryDirectory() as folder_out:
        inputs = pathlib.Path(folder_out, 'scans.txt')
        with inputs.open('w') as out:
            out.write(f'{len(ranges)} {width} {float(scans.angle_min)!r} {float(angle_max)!r} '
                      f'{float(scans.angle_increment)!r}\n')
            for stamp_ns, row in zip(scans.stamps_ns, ranges):
                out.write(f'{float(stamp_ns) * 1e-9!r} ' + ' '.join(map('{:.6g}'.format, row))
                          + '\n')
        printed = subprocess.run([binary, str(inputs)], check=True, capture_output=True,
                                 text=True).stdout
    rows = np.array([line.split() for line in printed.splitlines()], dtype=float)
    laser, upper = rows[:, :3], rows[:, 3:9]
    covariances = upper[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3)
    return external_row(name, 'rf2o', scans, laser, covariances, rows[1:, 9].mean() * 1e-3)


def external_row(name: str, label: str, scans, laser: np.ndarray, covariances: np.ndarray,
                 seconds: float) -> str:
    """
    Return the table row of another odometry's laser poses, scored as ours.

    :param laser: its laser poses in its own odom frame, one per scan, shape (T, 3)
    :param covariances: its step covariances in the laser frame, shape (T, 3, 3)
    :param seconds: its time per scan, s
    """
    folder = DATA / name
    _, sigma_m, sigma_deg = MOVING[name]
    mount = load_without_aliases((folder / 'laser_mount.yaml').read_text())
    mount = np.array([mount['x_m'], mount['y_m'], mount['yaw_rad']])
    # The laser's poses, started at the mount as ours: odom is the robot's first pose.
    poses = np.array([compose(mount, pose) for pose in laser])
    steps = np.zeros_like(poses)
    steps[1:] = [compose(inverse(a), b) for a, b in zip(poses[:-1], poses[1:])]
    reference = poses_at(load_poses(folder / 'poses.csv'), scans.stamps_ns * 1e-9, tuple(mount))
    known = np.isfinite(reference).all(axis=1)
    errors = trajectory_errors(poses[known], steps[known], covariances[known],
                               reference[known], sigma_m, math.radians(sigma_deg))
    return (f'| {name} | {label} | {errors.rpe_percent_per_m:.2f} | '
            f'{errors.rpe_deg_per_m:.2f} | {errors.ate_m:.3f} | {100 * errors.steps_within:.1f} '
            f'| {errors.nees_mean:.3g} | {100 * errors.nees_in_gate:.1f} | - | '
            f'{1e3 * seconds:.2f} |')


def still(name: str, reference: str) -> str:
    """Return one table row of a still recording."""
    scans = load_scans(DATA / name)
    run = run_odometry(scans, node_config(None, None), REFERENCES[reference])
    distance = drift(run.poses)
    return (f'| {name} | {reference} | {len(scans)} | {1e3 * distance[-1]:.1f} | '
            f'{1e3 * distance.max():.1f} | {1e3 * run.odometry_s:.1f} |')


def twins(name: str) -> str:
    """Return one table row of the odometry's numpy steps against its compiled twin."""
    scans = load_scans(DATA / name)
    config = node_config(None, MOVING[name][0] if name in MOVING else None)
    landmarks = [landmarks_from_features(extract_features(
        ranges, scans.angle_min, scans.angle_increment, config, scans.range_min,
        scans.range_max), config.max_landmark_angle_sigma_rad) for ranges in scans.ranges]
    stamps = scans.stamps_ns * 1e-9
    best = {False: math.inf, True: math.inf}
    slowest, median, updates = dict(best), {}, {}
    for _ in range(3):
        for compiled in (False, True):
            odometry, spent, taken = Odometry(compiled=compiled), [], []
            for stamp, scan in zip(stamps, landmarks):
                start = time.perf_counter()
                taken.append(odometry.update(stamp, scan))
                spent.append(time.perf_counter() - start)
            slowest[compiled] = min(slowest[compiled], max(spent))
            if np.mean(spent) < best[compiled]:
                best[compiled], median[compiled] = float(np.mean(spent)), np.median(spent)
            updates[compiled] = taken
    same = sum((a.status, a.corners, a.lines) == (b.status, b.corners, b.lines)
               for a, b in zip(updates[False], updates[True]))
    apart = max(float(np.abs(a.pose - b.pose).max())
                for a, b in zip(updates[False], updates[True]))
    return (f'| {name} | {1e3 * best[False]:.2f} | {1e3 * best[True]:.3f} | '
            f'{best[False] / best[True]:.1f} | {1e3 * slowest[False]:.1f} | '
            f'{1e3 * slowest[True]:.2f} | {1e3 * median[False]:.2f} | {1e3 * median[True]:.3f} '
            f'| {same} / {len(landmarks)} | {apart:.1e} |')


def main(names) -> None:
    """Print the tables."""
    runtime.start(wait=True)            # every scan timed with the compiled core serving
    peers = {}
    for option in ('--kiss', '--rf2o'):
        if option in names:
            at = names.index(option)
            peers[option], names = names[at + 1], names[:at] + names[at + 2:]
    if names and names[0] == '--twins':
        print('| recording | numpy ms/scan | compiled ms/scan | ratio | numpy slowest ms | '
              'compiled slowest ms | numpy median ms | compiled median ms | same statuses and '
              'counts | poses apart m |')
        print('|---|---|---|---|---|---|---|---|---|---|')
        for name in names[1:] or list(MOVING) + list(STILL):
            print(twins(name), flush=True)
        return
    if names and names[0] == '--wheel':
        print('| recording | prior | RPE %/m | RPE deg/m | ATE m | steps within 10 cm, 2 deg % '
              '| step NEES mean (3) | inside 95 % gate % | statuses | wheel steps taken / '
              'rejected | odometry ms/scan |')
        print('|---|---|---|---|---|---|---|---|---|---|---|')
        for name in [n for n in names[1:] if n in MOVING] or list(MOVING):
            for wheel in ('', 'model', 'with jitter'):
                row = moving(name, 'keyframe', wheel)
                cells = row.split(' | ')
                cells[1] = {'': 'constant velocity', 'model': 'synthetic wheel',
                            'with jitter': "synthetic wheel, the reference's jitter stated"}[
                    wheel]
                if not wheel:
                    cells.insert(-1, '-')
                print(' | '.join(cells), flush=True)
        return
    names = names or list(MOVING) + list(STILL)
    print('| recording | reference | RPE %/m | RPE deg/m | ATE m | steps within 10 cm, 2 deg % '
          '| step NEES mean (3) | inside 95 % gate % | statuses | odometry ms/scan |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for name in (n for n in names if n in MOVING):
        for reference in REFERENCES:
            print(moving(name, reference), flush=True)
        if '--kiss' in peers:
            print(kiss_icp(name, peers['--kiss']), flush=True)
        if '--rf2o' in peers:
            print(rf2o(name, peers['--rf2o']), flush=True)
    print('\n| still recording | reference | scans | drift at the end mm | largest drift mm | '
          'odometry ms/scan |')
    print('|---|---|---|---|---|---|')
    for name in (n for n in names if n in STILL):
        for reference in REFERENCES:
            print(still(name, reference), flush=True)


if __name__ == '__main__':
    main(sys.argv[1:])
