# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The emulator's built-in room: a furnished room of 4.5 x 2.5 m, seen with Gaussian range noise.

The room is the lab's ``environment_a`` floor plan (wctls_lab.simulation), held here as plain
walls so that the driver's emulator stands alone: the outline with three pilasters, a window
niche and two chamfered corners, a cabinet and two free-standing columns, each a square turned
45 deg. A sample at raw (clockwise) angle theta is the range along the laser-frame bearing
pi - theta, so a driver publishing sllidar_ros2's angle = pi - theta sees the room in REP-103
orientation.
"""

import math
from typing import Optional, Tuple

import numpy as np

from .raycast import cast_rays

# The outline, m, in the room's frame (x along the long walls).
_OUTLINE_M = ((0.0, 0.0), (0.7, 0.0), (0.7, 0.3), (1.1, 0.3), (1.1, 0.0), (2.6, 0.0),
              (2.6, -0.3), (3.4, -0.3), (3.4, 0.0), (3.7, 0.0), (3.7, 0.25), (3.95, 0.25),
              (3.95, 0.0), (4.0, 0.0), (4.5, 0.5), (4.5, 2.0), (4.0, 2.5), (3.35, 2.5),
              (3.35, 2.25), (3.0, 2.25), (3.0, 2.5), (1.4, 2.5), (1.4, 1.9), (0.3, 1.9),
              (0.3, 2.5), (0.0, 2.5))
# Square pieces of furniture: centre (m), side (m), yaw (deg).
_SQUARES = (((2.2, 1.9), 0.3, 45.0), ((2.1, 0.7), 0.25, 45.0), ((0.9, 1.25), 0.4, 45.0))
# Where the emulated sensor stands, (x m, y m, yaw rad), unless told otherwise.
SENSOR_POSE = (2.2, 1.25, 0.0)


def _closed(points: np.ndarray) -> np.ndarray:
    """Return the walls (K, 4) of a closed polygon's points (K, 2)."""
    return np.hstack([points, np.roll(points, -1, axis=0)])


def room_walls_m() -> np.ndarray:
    """
    Return the room's walls in its own frame.

    :return: shape (K, 4): x0, y0, x1, y1, m
    """
    walls = [_closed(np.array(_OUTLINE_M))]
    for (x, y), side, yaw_deg in _SQUARES:
        angles = math.radians(yaw_deg) + np.radians([45.0, 135.0, 225.0, 315.0])
        half_diagonal = side / math.sqrt(2.0)
        walls.append(_closed(np.column_stack([x + half_diagonal * np.cos(angles),
                                              y + half_diagonal * np.sin(angles)])))
    return np.vstack(walls)


def walls_in_sensor_frame(pose: Tuple[float, float, float] = SENSOR_POSE) -> np.ndarray:
    """
    Return the room's walls as a sensor at a pose sees them (its REP-103 frame).

    :param pose: the sensor's (x m, y m, yaw rad) in the room
    :return: shape (K, 4), m
    """
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    # room -> sensor: R(yaw)^T (p - t); as row vectors p' = (p - t) R.
    points = (room_walls_m().reshape(-1, 2) - np.array([x, y])) @ np.array([[c, -s], [s, c]])
    return points.reshape(-1, 4)


class RoomScene:
    """
    The room's ranges at the emulator's raw angles, through a sensor model.

    For a sample at bearing theta the range is the room's along ``theta + d_theta`` plus
    ``d_r + offset``, with ``d_theta ~ N(0, bearing_sigma_rad^2)`` and
    ``d_r ~ N(0, range_sigma_m^2)`` independent per sample, ``offset ~ N(0,
    common_range_sigma_m^2)`` one draw per call; a sample returns nothing with probability
    ``dropout_probability``. The draws come in the order of the lab simulator's sensor model
    (wctls_lab.simulation.scanner), so one seed gives the same stream with either scene.

    :param pose: the sensor's (x m, y m, yaw rad) in the room
    :param range_sigma_m: the range noise std, m (0: exact ranges)
    :param rng: random generator (default: seeded with 0); the device's faults may share it
    :param bearing_sigma_rad: the bearing noise std, rad
    :param common_range_sigma_m: the std of a range offset shared by a call's samples, m
    :param dropout_probability: the chance that a sample returns nothing
    """

    def __init__(self, pose: Tuple[float, float, float] = SENSOR_POSE,
                 range_sigma_m: float = 0.0, rng: Optional[np.random.Generator] = None,
                 bearing_sigma_rad: float = 0.0, common_range_sigma_m: float = 0.0,
                 dropout_probability: float = 0.0):
        self._walls = walls_in_sensor_frame(pose)
        self._range_sigma_m = range_sigma_m
        self._bearing_sigma_rad = bearing_sigma_rad
        self._common_range_sigma_m = common_range_sigma_m
        self._dropout_probability = dropout_probability
        self._rng = rng or np.random.default_rng(0)
        self._draws = self._rng.bit_generator.state    # the state before the last call's draws

    def distances_mm(self, raw_angle_deg: np.ndarray, fresh_noise: bool = True) -> np.ndarray:
        """
        Return the measured distance at each raw clockwise angle.

        :param raw_angle_deg: device angles, degrees clockwise from the front, shape (N,)
        :param fresh_noise: False: the same noise draws as the previous call (as many angles)
        :return: distances, mm (float), shape (N,); 0 where nothing returns
        """
        if fresh_noise:
            self._draws = self._rng.bit_generator.state
        else:
            self._rng.bit_generator.state = self._draws
        bearings = math.pi - np.radians(np.asarray(raw_angle_deg, dtype=float))
        rng = self._rng
        ranges = cast_rays(self._walls, np.zeros(2),
                           bearings + rng.normal(0.0, self._bearing_sigma_rad, bearings.shape))
        offset = rng.normal(0.0, self._common_range_sigma_m)
        ranges = ranges + rng.normal(0.0, 1.0, bearings.shape) * self._range_sigma_m + offset
        returned = (rng.random(bearings.shape) >= self._dropout_probability) & (ranges > 0.0)
        return np.where(returned & np.isfinite(ranges), ranges * 1000.0, 0.0)
