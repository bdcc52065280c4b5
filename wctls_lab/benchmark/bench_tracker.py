#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark the landmark tracker's time per scan against the number of landmarks in view.

A synthetic scene of L landmarks (default 10, 20 and 40; half corners, half line landmarks) is
seen from a sensor that steps 5 cm and 1 deg a scan, each landmark observed with 1 cm of noise,
the step given 1 cm and 0.5 deg of sigma. Extraction is not timed: only
:meth:`~wctls_ros.frontend.tracking.Tracker.update`. Prints, per L and tracker (the numpy
steps, and their compiled twin when numba can give it), the median and p90 time per scan over
the scans after the first 20 (the tracks are confirmed by then) and the share of the scans'
detections that kept their track's id.

Usage: python bench_tracker.py [--landmarks L ...] [--scans N]
"""

import argparse
import math
import time

import numpy as np
from wctls_ros.core import CoreUnavailable
from wctls_ros.frontend.frames import rotation
from wctls_ros.frontend.tracking import Detections, Motion, Tracker

NOISE_M = 0.01
STEP = np.array([0.05, 0.0, math.radians(1.0)])
STEP_COV = np.diag([0.01 ** 2, 0.01 ** 2, math.radians(0.5) ** 2])
WARM_UP_SCANS = 20


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


def run(landmarks: int, scans: int, compiled: bool, seed: int = 1):
    """Return (median s, p90 s, share of detections that kept their id) of one scene."""
    rng = np.random.default_rng(seed)
    corner, line = scene(landmarks, rng)
    tracker = Tracker(compiled=compiled)
    pose = np.zeros(3)
    times, kept, total = [], 0, 0
    first_ids = None
    for t in range(scans):
        if t:
            pose = pose + np.concatenate([rotation(pose[2]) @ STEP[:2], STEP[2:]])
        found = observe(corner, line, pose, rng)
        start = time.perf_counter()
        tracked = tracker.update(found, Motion(STEP, STEP_COV) if t else Motion.still())
        spent = time.perf_counter() - start
        ids = np.concatenate([tracked.corners.ids, tracked.lines.ids])
        if t == 0:
            first_ids = ids
        if t >= WARM_UP_SCANS:
            times.append(spent)
            kept += int(np.sum(ids == first_ids))
            total += len(ids)
    return float(np.median(times)), float(np.percentile(times, 90)), kept / max(total, 1)


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[1])
    parser.add_argument('--landmarks', type=int, nargs='+', default=[10, 20, 40])
    parser.add_argument('--scans', type=int, default=220)
    args = parser.parse_args()
    print('| landmarks in view | tracker | median ms / scan | p90 ms / scan | ids kept |')
    print('|---|---|---|---|---|')
    for count in args.landmarks:
        for name, compiled in (('numpy', False), ('numba', True)):
            try:
                median, p90, kept = run(count, args.scans, compiled)
            except CoreUnavailable as error:
                print(f'| {count} | {name} | - | - | {error} |')
                continue
            print(f'| {count} | {name} | {1e3 * median:.3f} | {1e3 * p90:.3f} | {kept:.3f} |')


if __name__ == '__main__':
    main()
