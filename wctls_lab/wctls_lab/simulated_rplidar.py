# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``simulated_rplidar``: the driver's RPLIDAR emulator seeing a simulated floor plan.

:mod:`wctls_rplidar.emulator.cli` with the scene of :mod:`.simulation` instead of the driver's
built-in room: any bundled plan or YAML floor plan (walkers included), seen from a pose, with the
simulator's sensor models. With ``--circle`` the sensor drives round a circle from that pose at a
steady speed (a robot for the odometry to follow), and ``--truth`` logs its true pose. Every
other option, the control lines on standard input and the exit statuses are
``rplidar_emulator``'s.
"""

import argparse
from dataclasses import dataclass, replace
import math
import sys
import time
from typing import Optional, TextIO

import numpy as np
from wctls_rplidar.emulator import cli
import yaml

from .simulation import (BUNDLED_PLANS, FloorPlan, load_floor_plan, NOISELESS, NoiseModel,
                         SENSOR_MODELS, simulate_scan)

PROG = 'simulated_rplidar'
# The columns of the --truth file: the wall-clock time of the samples (the clock rplidar_node
# stamps its scans on) and the sensor's pose in the plan then.
TRUTH_COLUMNS = ('time_s', 'x_m', 'y_m', 'yaw_rad')


@dataclass(frozen=True)
class Circle:
    """
    A sensor driving round a circle at a steady speed, turning left, from its start pose.

    :ivar radius_m: the circle's radius, m
    :ivar speed_m_s: the speed along it, m/s
    """

    radius_m: float
    speed_m_s: float

    def pose(self, start: np.ndarray, elapsed_s: float) -> np.ndarray:
        """
        Return the pose after ``elapsed_s`` seconds; the heading is the circle's tangent.

        :param start: the start pose (x m, y m, yaw rad), heading along the circle
        :param elapsed_s: time since the start, s
        :return: the pose (x m, y m, yaw rad)
        """
        x, y, yaw = start
        centre_x, centre_y = x - self.radius_m * math.sin(yaw), y + self.radius_m * math.cos(yaw)
        heading = yaw + self.speed_m_s * elapsed_s / self.radius_m
        return np.array([centre_x + self.radius_m * math.sin(heading),
                         centre_y - self.radius_m * math.cos(heading), heading])


class SimulatedScene:
    """
    Ranges of a floor plan seen from a pose, with the simulator's sensor model.

    Walkers in the plan, and the sensor on a ``circle``, move in real time from the moment the
    scene is made.

    :param plan: the floor plan
    :param pose: sensor pose in the plan (x m, y m, yaw rad); None: the plan's own
    :param noise: the sensor model
    :param rng: random generator
    :param circle: the sensor drives round it from ``pose``; None: it stands still
    :param truth: a text file that gets a CSV row of :data:`TRUTH_COLUMNS` per sample batch
    """

    def __init__(self, plan: FloorPlan, pose, noise: NoiseModel, rng: np.random.Generator,
                 circle: Optional[Circle] = None, truth: Optional[TextIO] = None):
        self._plan = plan
        self._pose = np.array(plan.sensor_pose if pose is None else pose, dtype=float)
        self._noise = noise
        self._rng = rng
        self._circle = circle
        self._truth = truth
        if truth is not None:
            truth.write(','.join(TRUTH_COLUMNS) + '\n')
        self._draws = rng.bit_generator.state       # the state before the last call's draws
        self._start_s = time.monotonic()
        # Without walkers or motion the scene never changes: build it once.
        self._still = (None if plan.walkers or circle is not None
                       else plan.scene(tuple(self._pose)))

    def distances_mm(self, raw_angle_deg: np.ndarray, fresh_noise: bool = True) -> np.ndarray:
        """
        Return the measured distance at each raw clockwise angle.

        :param raw_angle_deg: device angles, degrees clockwise from the front
        :param fresh_noise: False: the same noise draws as the previous call (as many angles)
        :return: distances, mm (float); 0 where nothing returns
        """
        if fresh_noise:
            self._draws = self._rng.bit_generator.state
        else:
            self._rng.bit_generator.state = self._draws
        bearings = math.pi - np.radians(raw_angle_deg)
        elapsed_s = time.monotonic() - self._start_s
        pose = (self._pose if self._circle is None
                else self._circle.pose(self._pose, elapsed_s))
        if self._truth is not None and fresh_noise:
            self._truth.write(f'{time.time():.6f},{pose[0]:.6f},{pose[1]:.6f},{pose[2]:.6f}\n')
        scene = self._plan.scene(tuple(pose), elapsed_s) if self._still is None else self._still
        ranges = simulate_scan(scene, bearings, self._noise, self._rng)
        return np.where(np.isfinite(ranges), ranges * 1000.0, 0.0)


def plan_options(p: argparse.ArgumentParser) -> None:
    """
    Add the floor plan's options to the emulator's parser.

    :param p: the parser
    """
    p.add_argument('--floor-plan', default='environment_a',
                   help=f'bundled plan name ({", ".join(BUNDLED_PLANS)}) or a YAML path '
                        '(default: %(default)s)')
    p.add_argument('--pose', type=float, nargs=3, metavar=('X', 'Y', 'YAW_DEG'),
                   help="sensor pose in the plan, m and degrees (default: the plan's own)")
    p.add_argument('--sensor', choices=tuple(SENSOR_MODELS), default='s1_like',
                   help="the sensor's measurement model (simulate --sensor; the driver bins "
                        'the samples itself, so no bins here) (default: %(default)s)')
    p.add_argument('--range-sigma', type=cli.bounded(float, 0.0),
                   help="range noise std, m (default: the sensor model's)")
    p.add_argument('--bearing-sigma-deg', type=cli.bounded(float, 0.0),
                   help="bearing noise std, degrees (default: the sensor model's)")
    p.add_argument('--circle', type=float, nargs=2, metavar=('RADIUS_M', 'SPEED_M_S'),
                   help='drive the sensor round a circle from its pose, turning left, at a '
                        'steady speed (default: it stands still)')
    p.add_argument('--truth', type=argparse.FileType('w', bufsize=1), metavar='FILE',
                   help="log the sensor's true pose: a CSV row (" + ', '.join(TRUTH_COLUMNS)
                        + ') per batch of samples, time on the wall clock (default: none)')


def plan_scene(args) -> tuple:
    """
    Build the simulated scene from the parsed options.

    :param args: the parsed options
    :return: the scene and the plan's name
    :raises UserError: on a floor plan that cannot be read
    """
    try:
        plan = load_floor_plan(args.floor_plan)
    except OSError as error:
        raise cli.UserError(f'--floor-plan: {error.strerror or error}'
                            + (f': {error.filename}' if error.filename else '')) from None
    except (yaml.YAMLError, ValueError, KeyError, TypeError, IndexError) as error:
        raise cli.UserError(f'--floor-plan {args.floor_plan}: not a valid floor plan '
                            f'({type(error).__name__}: {" ".join(str(error).split())})') from None
    pose = None if args.pose is None else (args.pose[0], args.pose[1], math.radians(args.pose[2]))
    noise = replace(SENSOR_MODELS[args.sensor], bearing_quantum_rad=0.0)
    if args.range_sigma is not None:
        noise = replace(noise, range_sigma_m=args.range_sigma)
    if args.bearing_sigma_deg is not None:
        noise = replace(noise, bearing_sigma_rad=math.radians(args.bearing_sigma_deg))
    noise = NOISELESS if args.noiseless else noise
    circle = None
    if args.circle is not None:
        radius_m, speed_m_s = args.circle
        if not (radius_m > 0.0 and speed_m_s >= 0.0):
            raise cli.UserError(f'--circle: the radius must be above 0 and the speed 0 or more, '
                                f'got {radius_m:g} m and {speed_m_s:g} m/s')
        circle = Circle(radius_m, speed_m_s)
    return SimulatedScene(plan, pose, noise, np.random.default_rng(args.seed), circle,
                          args.truth), plan.name


def parser() -> argparse.ArgumentParser:
    """
    Return the command-line parser: the emulator's, with the floor plan's options.

    :return: the parser
    """
    return cli.parser(PROG, plan_options)


def main(argv=None) -> int:
    """
    Run the emulator on a floor plan until ``quit`` on standard input, SIGTERM or Ctrl-C.

    :param argv: command-line arguments (default: ``sys.argv[1:]``)
    :return: exit status: 0 after quit or SIGTERM, 2 on a user error, 130 on Ctrl-C
    """
    return cli.main(argv, PROG, plan_options, plan_scene)


if __name__ == '__main__':
    sys.exit(main())
