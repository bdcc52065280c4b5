# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Wheel odometry as the odometry's prior: its poses by time, the step between two scans.

A robot with wheel encoders publishes its pose in its own odom frame at its own rate
(nav_msgs/Odometry, or the TF odom -> base_link). :class:`WheelPoses` keeps the recent poses
and gives the robot's step between two scans' stamps, each pose interpolated (linearly in x, y
and the shorter way in yaw) or, for a stamp after the newest pose, extrapolated along the last
motion for at most the timeout; what it cannot give (no pose yet, poses too old or too far
apart, time that ran backwards) it names. :class:`WheelModel` is the step's covariance grown
with the distance and the turn (docs/odometry.md#wheel-odometry-as-the-prior);
:func:`laser_prior` moves the robot's step onto the laser by the mount, as
:class:`.odometry.Odometry` takes it. Pure numpy, no ROS.
"""

from bisect import bisect_right
from collections import deque
from dataclasses import dataclass
import math
from typing import Deque, Optional, Tuple

import numpy as np

from .frames import wrap_angle
from .odometry import change_frame, compose, inverse, Prior

# Why a step has no wheel prior (the odometry then takes the constant velocity).
WHEEL_MISSING = ('none yet', 'stale', 'backwards')
# What WheelPoses.add did with a pose.
WHEEL_ADDED = ('kept', 'not finite', 'backwards')


@dataclass(frozen=True)
class WheelModel:
    """
    The covariance of a wheel step, where the wheel odometry states none.

    Per step, in the robot's frame: sigma_xy = sigma_per_m * |d| + floor_m on each axis and
    sigma_yaw = sigma_per_rad * |dyaw| + floor_rad, d the step's translation and dyaw its turn;
    no correlation between the axes, nor between steps.

    :ivar sigma_per_m: the translation's std per metre travelled, each axis (m per m)
    :ivar floor_m: the translation's std of any step, m (> 0)
    :ivar sigma_per_rad: the turn's std per radian turned (rad per rad)
    :ivar floor_rad: the turn's std of any step, rad (> 0)
    :raises ValueError: on a negative growth or a floor that is not positive
    """

    sigma_per_m: float = 0.05
    floor_m: float = 0.002
    sigma_per_rad: float = 0.05
    floor_rad: float = math.radians(0.2)

    def __post_init__(self):
        for name in ('sigma_per_m', 'sigma_per_rad'):
            if not 0.0 <= getattr(self, name) < math.inf:
                raise ValueError(f'{name} must be >= 0 and finite, got {getattr(self, name)}')
        for name in ('floor_m', 'floor_rad'):
            if not 0.0 < getattr(self, name) < math.inf:
                raise ValueError(f'{name} must be > 0 and finite, got {getattr(self, name)}')

    def covariance(self, step: np.ndarray) -> np.ndarray:
        """
        Return the covariance of a robot's step.

        :param step: (dx m, dy m, dyaw rad)
        :return: shape (3, 3)
        """
        sigma_m = self.sigma_per_m * math.hypot(step[0], step[1]) + self.floor_m
        sigma_rad = self.sigma_per_rad * abs(float(wrap_angle(step[2]))) + self.floor_rad
        return np.diag([sigma_m ** 2, sigma_m ** 2, sigma_rad ** 2])


def laser_prior(step: np.ndarray, covariance: np.ndarray, mount: np.ndarray) -> Prior:
    """
    Return a robot's step as the prior of the laser it carries.

    The laser's step is M^-1 (+) s (+) M for its mount M (the laser's pose on the robot), the
    covariance through the Jacobian (:func:`.odometry.change_frame` with M^-1).

    :param step: the robot's step (dx m, dy m, dyaw rad)
    :param covariance: its covariance, shape (3, 3)
    :param mount: the laser's pose in the robot frame (x m, y m, yaw rad)
    :return: the laser's step and covariance
    :raises ValueError: when they are not finite or the covariance is not positive definite
    """
    laser, laser_covariance = change_frame(np.asarray(step, dtype=float),
                                           np.asarray(covariance, dtype=float),
                                           inverse(np.asarray(mount, dtype=float)))
    return Prior(laser, laser_covariance)


def _between(a: np.ndarray, b: np.ndarray, fraction: float) -> np.ndarray:
    """Return the pose a fraction of the way from a to b: x, y linear, yaw the shorter way."""
    return np.array([a[0] + fraction * (b[0] - a[0]), a[1] + fraction * (b[1] - a[1]),
                     float(wrap_angle(a[2] + fraction * float(wrap_angle(b[2] - a[2]))))])


class WheelPoses:
    """
    The recent poses of a robot's wheel odometry, and its steps between stamps.

    Poses come in by stamp; one older than the newest means the source's time ran backwards (a
    bag replayed from its start, a simulation reset): the poses are dropped and the steps that
    would span the jump are refused as 'backwards'. Poses older than ``keep_s`` before the
    newest are dropped.
    """

    def __init__(self, timeout_s: float, keep_s: float = 10.0, max_poses: int = 10000):
        """
        Keep no poses yet.

        :param timeout_s: a stamp after the newest pose by more than this, or between two poses
            further apart, has no wheel pose ('stale'), s
        :param keep_s: drop the poses this much older than the newest, s
        :param max_poses: keep at most this many poses
        """
        self.timeout_s = float(timeout_s)
        self.keep_s = float(keep_s)
        self._stamps: Deque[float] = deque(maxlen=max_poses)
        self._poses: Deque[np.ndarray] = deque(maxlen=max_poses)
        self._rates: Deque[Optional[np.ndarray]] = deque(maxlen=max_poses)
        self._jumped = False
        self._dropped_s = -math.inf

    def add(self, stamp_s: float, pose, rate_covariance: Optional[np.ndarray] = None) -> str:
        """
        Take one pose of the wheel odometry.

        :param stamp_s: its stamp, s
        :param pose: the robot's pose in the wheel odometry's frame (x m, y m, yaw rad)
        :param rate_covariance: the covariance of its velocity (vx, vy, vyaw) in the robot's
            frame, shape (3, 3), or None where the source states none
        :return: one of WHEEL_ADDED: 'kept'; 'not finite' (left out); 'backwards' (older than
            the newest pose: the poses before are dropped and this one kept)
        """
        pose = np.asarray(pose, dtype=float).reshape(-1)
        if not (math.isfinite(stamp_s) and pose.shape == (3,) and np.isfinite(pose).all()):
            return WHEEL_ADDED[1]
        outcome = WHEEL_ADDED[0]
        if self._stamps and stamp_s < self._stamps[-1]:
            self._stamps.clear()
            self._poses.clear()
            self._rates.clear()
            self._jumped, self._dropped_s = True, -math.inf
            outcome = WHEEL_ADDED[2]
        elif self._stamps and stamp_s == self._stamps[-1]:
            # The same stamp again: the later message stands.
            self._stamps.pop()
            self._poses.pop()
            self._rates.pop()
        if len(self._stamps) == self._stamps.maxlen:
            self._dropped_s = self._stamps[0]
        self._stamps.append(float(stamp_s))
        self._poses.append(pose)
        self._rates.append(None if rate_covariance is None
                           else np.asarray(rate_covariance, dtype=float))
        while self._stamps and self._stamps[0] < stamp_s - self.keep_s:
            self._dropped_s = self._stamps.popleft()
            self._poses.popleft()
            self._rates.popleft()
        return outcome

    def _missing_before(self) -> str:
        """Return why a stamp before the oldest pose has none."""
        if self._jumped:
            return WHEEL_MISSING[2]
        return WHEEL_MISSING[1] if math.isfinite(self._dropped_s) else WHEEL_MISSING[0]

    def pose_at(self, stamp_s: float) -> Tuple[Optional[np.ndarray], str]:
        """
        Return the robot's wheel pose at a stamp, or why there is none.

        :param stamp_s: the stamp, s
        :return: (the pose (x m, y m, yaw rad) or None, 'ok' or one of WHEEL_MISSING)
        """
        stamps, poses = self._stamps, self._poses
        if not stamps or stamp_s < stamps[0]:
            return None, self._missing_before()
        newest = stamps[-1]
        if stamp_s >= newest:
            if stamp_s - newest > self.timeout_s:
                return None, WHEEL_MISSING[1]
            if stamp_s == newest or len(stamps) < 2 or not (
                    0.0 < newest - stamps[-2] <= self.timeout_s):
                return poses[-1].copy(), 'ok'
            # Along the last motion, at its rate.
            fraction = (stamp_s - newest) / (newest - stamps[-2])
            motion = compose(inverse(poses[-2]), poses[-1])
            return compose(poses[-1], fraction * motion), 'ok'
        after = bisect_right(stamps, stamp_s)
        if stamps[after - 1] == stamp_s:
            return poses[after - 1].copy(), 'ok'
        before_s, after_s = stamps[after - 1], stamps[after]
        if after_s - before_s > self.timeout_s:
            return None, WHEEL_MISSING[1]
        return _between(poses[after - 1], poses[after],
                        (stamp_s - before_s) / (after_s - before_s)), 'ok'

    def step(self, from_s: float,
             to_s: float) -> Tuple[Optional[np.ndarray], Optional[np.ndarray], str]:
        """
        Return the robot's step between two stamps, in the robot's frame at the first.

        Until a step is given again after the source's time ran back, a step it cannot give is
        refused as 'backwards', whatever else it lacks.

        :param from_s: the previous scan's stamp, s
        :param to_s: the current scan's stamp, s
        :return: (the step (dx m, dy m, dyaw rad) or None; the covariance the source states
            for it, its velocity covariance at to_s times (to_s - from_s)^2, or None; 'ok' or
            one of WHEEL_MISSING)
        """
        if not (math.isfinite(from_s) and math.isfinite(to_s)) or to_s < from_s:
            return None, None, WHEEL_MISSING[2]
        first, why = self.pose_at(from_s)
        second, why = (None, why) if first is None else self.pose_at(to_s)
        if first is None or second is None:
            # Since the source's time ran back, whatever is missing is missing for that.
            return None, None, WHEEL_MISSING[2] if self._jumped else why
        self._jumped = False
        rate = self._rates[max(0, bisect_right(self._stamps, to_s) - 1)]
        stated = None if rate is None else rate * (to_s - from_s) ** 2
        return compose(inverse(first), second), stated, 'ok'
