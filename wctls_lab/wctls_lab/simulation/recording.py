# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Repeated scans of a floor plan from a still (or moving) sensor, as one array (numpy only)."""

from dataclasses import dataclass
from typing import Tuple

import numpy as np

from .floorplan import FloorPlan
from .scanner import full_turn_bearings, NoiseModel, S1_BEAMS_PER_TURN, simulate_scan

SCAN_PERIOD_S = 0.1                 # the RPLIDAR S1's standard 10 Hz


@dataclass(frozen=True)
class Recording:
    """
    Simulated scans with sllidar_ros2's full-turn geometry, and the truth about them.

    :ivar ranges: shape (T, N), m; the model's no-return value where nothing returned
    :ivar angle_min: bearing of beam 0, rad (-pi)
    :ivar angle_increment: bearing step, rad (2 pi / (N - 1))
    :ivar poses: sensor pose of each scan in plan coordinates (x m, y m, yaw rad), (T, 3)
    :ivar corners_m: the plan's true corners in each scan's sensor frame, shape (T, M, 2), m
    :ivar corner_kinds: 'inside' or 'outside' for each true corner, length M
    :ivar visible: which true corners each scan sees well enough to extract, shape (T, M)
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    poses: np.ndarray
    corners_m: np.ndarray
    corner_kinds: Tuple[str, ...]
    visible: np.ndarray


def simulate_recording(plan: FloorPlan, noise: NoiseModel, count: int, seed: int = 0,
                       pose=None, velocity=(0.0, 0.0, 0.0),
                       beams: int = S1_BEAMS_PER_TURN) -> Recording:
    """
    Simulate ``count`` consecutive scans at 10 Hz, seeded.

    Walkers move between scans; what each scan sees of the true corners is worked out from
    that scan's scene (a still sensor in a scene without walkers sees the same in every scan).

    :param plan: the floor plan
    :param noise: the sensor model (per-scan common offset drawn anew each scan)
    :param count: number of scans
    :param seed: random seed
    :param pose: the (first) sensor pose (x m, y m, yaw rad); the plan's if None
    :param velocity: sensor motion in plan coordinates (m/s, m/s, rad/s); zero for a still
        sensor
    :param beams: beams per turn
    :return: the scans
    """
    rng = np.random.default_rng(seed)
    angle_min, increment, bearings = full_turn_bearings(beams)
    start = np.asarray(plan.sensor_pose if pose is None else pose, dtype=float)
    times = SCAN_PERIOD_S * np.arange(count)
    poses = start + times[:, None] * np.asarray(velocity, dtype=float)
    ranges = np.empty((count, beams))
    corners = np.empty((count, len(plan.corners_m), 2))
    visible = np.zeros((count, len(plan.corners_m)), dtype=bool)
    changing = bool(plan.walkers) or np.any(np.asarray(velocity) != 0.0)
    for t in range(count):
        scene = plan.scene(tuple(poses[t]), times[t])
        ranges[t] = simulate_scan(scene, bearings, noise, rng)
        corners[t] = plan.to_sensor_frame(plan.corners_m, tuple(poses[t]))
        visible[t] = scene.visible(corners[t], bearings) if changing or t == 0 else visible[0]
    return Recording(ranges, angle_min, increment, poses, corners, plan.corner_kinds, visible)
