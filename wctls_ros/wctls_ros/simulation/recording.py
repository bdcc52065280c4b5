# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Repeated scans of a floor plan from a still (or moving) sensor, as one array (numpy only)."""

from dataclasses import dataclass

import numpy as np

from .floorplan import FloorPlan
from .scanner import full_turn_bearings, NoiseModel, S1_BEAMS_PER_TURN, simulate_ranges

SCAN_PERIOD_S = 0.1                 # the RPLIDAR S1's standard 10 Hz


@dataclass(frozen=True)
class Recording:
    """
    Simulated scans with sllidar_ros2's full-turn geometry.

    :ivar ranges: shape (T, N), m; +inf for no return
    :ivar angle_min: bearing of beam 0, rad (-pi)
    :ivar angle_increment: bearing step, rad (2 pi / (N - 1))
    :ivar poses: sensor pose of each scan in plan coordinates (x m, y m, yaw rad), (T, 3)
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    poses: np.ndarray


def simulate_recording(plan: FloorPlan, noise: NoiseModel, count: int, seed: int = 0,
                       pose=None, velocity=(0.0, 0.0, 0.0),
                       beams: int = S1_BEAMS_PER_TURN) -> Recording:
    """
    Simulate ``count`` consecutive scans at 10 Hz, seeded.

    :param plan: the floor plan
    :param noise: the noise model (per-scan common offset drawn anew each scan)
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
    for t in range(count):
        walls, _ = plan.in_sensor_frame(tuple(poses[t]))
        ranges[t] = simulate_ranges(walls, bearings, noise, rng)
    return Recording(ranges, angle_min, increment, poses)
