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
(the extraction left out). Per still recording: the drift at its end and its largest. Both
references, scan to keyframe (the default) and scan to scan, side by side in one run.
Usage: python bench_odometry.py [recording ...]
"""

import math
import pathlib
import sys

import numpy as np

from wctls_lab.evaluation.poses import load_poses, poses_at
from wctls_lab.evaluation.scans import load_scans
from wctls_lab.evaluation.score_cli import node_config
from wctls_lab.evaluation.trajectory import drift, run_odometry, trajectory_errors
from wctls_ros.frontend.odometry import OdometryConfig
from wctls_ros.plain_yaml import load_without_aliases

DATA = pathlib.Path(__file__).resolve().parents[2] / 'data'
# Recording -> (sensor preset, the reference's per-pose jitter m, deg).
MOVING = {'rplidar_barc_moving': ('rplidar_a2', 0.005, 0.5),
          'mrpt_malaga_moving': (None, 0.01, 0.5),
          'tuw_gh25_moving': (None, 0.01, 0.5)}
STILL = ('sick_lms111_static', 'sick_lms1xx_static', 'sick_lms511_static',
         'sick_tim781s_static')
REFERENCES = {'keyframe': OdometryConfig(),
              'scan to scan': OdometryConfig(keyframe_m=0.0, keyframe_rad=0.0)}


def moving(name: str, reference: str) -> str:
    """Return one table row of a moving recording."""
    folder = DATA / name
    sensor, sigma_m, sigma_deg = MOVING[name]
    scans = load_scans(folder)
    run = run_odometry(scans, node_config(None, sensor), REFERENCES[reference])
    mount = load_without_aliases((folder / 'laser_mount.yaml').read_text())
    poses = poses_at(load_poses(folder / 'poses.csv'), run.stamps_s,
                     (mount['x_m'], mount['y_m'], mount['yaw_rad']))
    known = np.isfinite(poses).all(axis=1)
    errors = trajectory_errors(run.poses[known], run.steps[known],
                               run.step_covariances[known], poses[known], sigma_m,
                               math.radians(sigma_deg))
    statuses = ', '.join(f'{s} {run.statuses.count(s)}' for s in sorted(set(run.statuses)))
    return (f'| {name} | {reference} | {errors.rpe_percent_per_m:.2f} | '
            f'{errors.rpe_deg_per_m:.2f} | {errors.ate_m:.3f} | {100 * errors.steps_within:.1f} '
            f'| {errors.nees_mean:.2f} | {100 * errors.nees_in_gate:.1f} | {statuses} | '
            f'{1e3 * run.odometry_s:.1f} |')


def still(name: str, reference: str) -> str:
    """Return one table row of a still recording."""
    scans = load_scans(DATA / name)
    run = run_odometry(scans, node_config(None, None), REFERENCES[reference])
    distance = drift(run.poses)
    return (f'| {name} | {reference} | {len(scans)} | {1e3 * distance[-1]:.1f} | '
            f'{1e3 * distance.max():.1f} | {1e3 * run.odometry_s:.1f} |')


def main(names) -> None:
    """Print the tables."""
    names = names or list(MOVING) + list(STILL)
    print('| recording | reference | RPE %/m | RPE deg/m | ATE m | steps within 10 cm, 2 deg % '
          '| step NEES mean (3) | inside 95 % gate % | statuses | odometry ms/scan |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for name in (n for n in names if n in MOVING):
        for reference in REFERENCES:
            print(moving(name, reference), flush=True)
    print('\n| still recording | reference | scans | drift at the end mm | largest drift mm | '
          'odometry ms/scan |')
    print('|---|---|---|---|---|---|')
    for name in (n for n in names if n in STILL):
        for reference in REFERENCES:
            print(still(name, reference), flush=True)


if __name__ == '__main__':
    main(sys.argv[1:])
