#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark the landmark tracker's time per scan, numpy and numba side by side.

A synthetic scene of L landmarks (default 10, 20 and 40; half corners, half line landmarks) is
seen from a sensor that steps 5 cm and 1 deg a scan, each landmark observed with 1 cm of noise,
the step given 1 cm and 0.5 deg of sigma; and real recordings of data/ as ``score --tracks``
tracks them (default the gh25 robot and the RPLIDAR car, their poses' steps given 71 mm and
1.4 deg). Extraction is not timed: only :meth:`~wctls_ros.frontend.tracking.Tracker.update`,
the numpy steps (``compiled=False``) and the compiled twin (``compiled=True``) on the same
detections, scan by scan in turn (the order rotating), so that the machine's load falls on
both alike; with ``--baseline COMMIT`` the tracker of that commit too (taken out of git into a
cache folder and imported under a name of its own). Prints, per scene, the median and p90 time
per scan over the scans after the first 20 (the synthetic tracks are confirmed by then) and,
for the synthetic scenes, the share of the scans' detections that kept their first id.

Usage: python bench_tracker.py [--landmarks L ...] [--scans N] [--recordings NAME ...]
[--baseline COMMIT]
"""

import argparse
import importlib
import math
import os
import pathlib
import time

from earlier import earlier_package
import numpy as np
from wctls_lab.evaluation import load_scans
from wctls_lab.evaluation.analysis import features_per_scan
from wctls_ros.core import FeatureConfig, warm_up
from wctls_ros.frontend.frames import rotation
from wctls_ros.frontend.poses import load_poses, poses_at
from wctls_ros.frontend.tracking import (Detections, detections_of, Motion, steps_from_poses,
                                         Tracker, View)

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
NOISE_M = 0.01
STEP = np.array([0.05, 0.0, math.radians(1.0)])
STEP_COV = np.diag([0.01 ** 2, 0.01 ** 2, math.radians(0.5) ** 2])
WARM_UP_SCANS = 20
# The moving recordings and their laser's offset on the robot (each laser_mount.yaml).
MOUNTS = {'tuw_gh25_moving': 0.12, 'mrpt_malaga_moving': 0.78, 'rplidar_barc_moving': -0.12}
POSE_SIGMA_M, POSE_SIGMA_RAD = 0.05, math.radians(1.0)


def scene(landmarks: int, rng: np.random.Generator):
    """Return world corners (C, 3) and lines (L, 2) around the origin."""
    corners = landmarks // 2
    lines = landmarks - corners
    corner_xy = rng.uniform(-6.0, 6.0, size=(corners, 2))
    corner = np.column_stack([corner_xy, rng.uniform(-math.pi, math.pi, corners)])
    line = np.column_stack([np.linspace(-math.pi, math.pi, lines, endpoint=False),
                            rng.uniform(3.0, 8.0, lines)])
    return corner, line


def observe(corner, line, pose, rng: np.random.Generator) -> Detections:
    """Return the scene seen from a pose, with noise."""
    turn = rotation(pose[2])
    xy = (corner[:, :2] - pose[:2]) @ turn
    yaw = corner[:, 2] - pose[2]
    cov = np.tile(np.diag([NOISE_M ** 2, NOISE_M ** 2, 0.02 ** 2]), (len(xy), 1, 1))
    noisy = np.column_stack([xy, yaw]) + rng.normal(0.0, 1.0, (len(xy), 3)) * [
        NOISE_M, NOISE_M, 0.02]
    angle = line[:, 0] - pose[2]
    radius = line[:, 1] - pose[0] * np.cos(line[:, 0]) - pose[1] * np.sin(line[:, 0])
    line_cov = np.tile(np.diag([0.005 ** 2, NOISE_M ** 2]), (len(line), 1, 1))
    sensed = np.column_stack([angle, radius]) + rng.normal(0.0, 1.0, (len(line), 2)) * [
        0.005, NOISE_M]
    normal = np.column_stack([np.cos(sensed[:, 0]), np.sin(sensed[:, 0])])
    along = np.column_stack([-normal[:, 1], normal[:, 0]])
    foot = normal * sensed[:, 1:2]
    ends = np.stack([foot - along, foot + along], axis=1)
    return Detections(noisy, cov, sensed, line_cov, ends)


def synthetic(landmarks: int, scans: int, seed: int = 1):
    """Return the (detections, motion, view) of each scan of a synthetic scene."""
    rng = np.random.default_rng(seed)
    corner, line = scene(landmarks, rng)
    pose, out = np.zeros(3), []
    for t in range(scans):
        if t:
            pose = pose + np.concatenate([rotation(pose[2]) @ STEP[:2], STEP[2:]])
        out.append((observe(corner, line, pose, rng),
                    Motion(STEP, STEP_COV) if t else Motion.still(), None))
    return out


def recorded(name: str):
    """Return the (detections, motion, view) of each scan of a moving recording of data/."""
    recording = load_scans(REPOSITORY / 'data' / name)
    poses = poses_at(load_poses(REPOSITORY / 'data' / name / 'poses.csv'),
                     recording.stamps_ns * 1e-9, (MOUNTS[name], 0.0, 0.0))
    known = np.isfinite(poses).all(axis=1)
    motions = steps_from_poses(poses[known], math.sqrt(2.0) * POSE_SIGMA_M,
                               math.sqrt(2.0) * POSE_SIGMA_RAD)
    config = FeatureConfig()
    detections = [detections_of(features, config.max_landmark_angle_sigma_rad)
                  for (features, _), seen in zip(features_per_scan(recording, config), known)
                  if seen]
    views = [View(recording.angle_min, recording.angle_increment, ranges, recording.range_max)
             for ranges in recording.ranges[known]]
    return list(zip(detections, motions, views))


def earlier_tracker(commit: str):
    """Return the Tracker class of an earlier commit (:func:`earlier.earlier_package`)."""
    name = earlier_package(commit, 'bench_tracker')
    return importlib.import_module(f'{name}.frontend.tracking').Tracker


def run(scans, contenders):
    """
    Track the same scans with every contender, scan by scan in turn.

    :param scans: (detections, motion, view) of each scan
    :param contenders: name -> a new tracker
    :return: (name -> per-scan seconds after the warm-up, share of detections that kept their
        first id with the first contender)
    """
    trackers = {name: make() for name, make in contenders.items()}
    times = {name: [] for name in trackers}
    names = list(trackers)
    kept, total, first_ids = 0, 0, None
    for t, (detections, motion, view) in enumerate(scans):
        turn = names[t % len(names):] + names[:t % len(names)]
        for name in turn:
            start = time.perf_counter()
            tracked = trackers[name].update(detections, motion, view)
            spent = time.perf_counter() - start
            if t >= WARM_UP_SCANS:
                times[name].append(spent)
            if name == names[0]:
                ids = np.concatenate([tracked.corners.ids, tracked.lines.ids])
                first_ids = ids if t == 0 else first_ids
                if t >= WARM_UP_SCANS and len(ids) == len(first_ids):
                    kept += int(np.sum(ids == first_ids))
                    total += len(ids)
    return times, kept / total if total else math.nan


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[1])
    parser.add_argument('--landmarks', type=int, nargs='+', default=[10, 20, 40])
    parser.add_argument('--scans', type=int, default=220)
    parser.add_argument('--recordings', nargs='*', default=['tuw_gh25_moving',
                                                            'rplidar_barc_moving'],
                        choices=sorted(MOUNTS))
    parser.add_argument('--baseline', default=None,
                        help='time the tracker of this commit too (e.g. main)')
    args = parser.parse_args()
    print(f'compiled core ready in {warm_up():.1f} s; load {os.getloadavg()[0]:.2f}')
    contenders = {'numpy': lambda: Tracker(compiled=False),
                  'numba': lambda: Tracker(compiled=True)}
    if args.baseline:
        earlier = earlier_tracker(args.baseline)
        contenders[args.baseline] = earlier
    header = ' | '.join(f'{name} median, p90 ms' for name in contenders)
    print(f'| scene | {header} | numpy / numba | ids kept |')
    print('|---' * (len(contenders) + 3) + '|')
    scenes = [(f'{count} landmarks', lambda count=count: synthetic(count, args.scans))
              for count in args.landmarks]
    scenes += [(name, lambda name=name: recorded(name)) for name in args.recordings]
    for title, scans in scenes:
        times, kept = run(scans(), contenders)
        cells = ' | '.join(f'{1e3 * np.median(times[name]):.3f}, '
                           f'{1e3 * np.percentile(times[name], 90):.3f}' for name in contenders)
        ratio = np.median(times['numpy']) / np.median(times['numba'])
        share = '-' if title in args.recordings else f'{kept:.3f}'
        print(f'| {title} | {cells} | {ratio:.1f} | {share} |')
    print(f'load {os.getloadavg()[0]:.2f}')


if __name__ == '__main__':
    main()
