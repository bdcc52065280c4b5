# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``simulated_rplidar``: the driver's RPLIDAR emulator seeing a simulated floor plan.

:mod:`wctls_rplidar.emulator.cli` with the scene of :mod:`.simulation` instead of the driver's
built-in room: any bundled plan or YAML floor plan (walkers included), seen from a pose, with the
simulator's sensor models. Every other option, the control lines on standard input and the exit
statuses are ``rplidar_emulator``'s.
"""

import argparse
from dataclasses import replace
import math
import sys
import time

import numpy as np
from wctls_rplidar.emulator import cli
import yaml

from .simulation import (BUNDLED_PLANS, FloorPlan, load_floor_plan, NOISELESS, NoiseModel,
                         SENSOR_MODELS, simulate_scan)

PROG = 'simulated_rplidar'


class SimulatedScene:
    """
    Ranges of a floor plan seen from a pose, with the simulator's sensor model.

    Walkers in the plan move in real time from the moment the scene is made.

    :param plan: the floor plan
    :param pose: sensor pose in the plan (x m, y m, yaw rad); None: the plan's own
    :param noise: the sensor model
    :param rng: random generator
    """

    def __init__(self, plan: FloorPlan, pose, noise: NoiseModel, rng: np.random.Generator):
        self._plan = plan
        self._pose = pose
        self._noise = noise
        self._rng = rng
        self._draws = rng.bit_generator.state       # the state before the last call's draws
        self._start_s = time.monotonic()
        # Without walkers the scene never changes: build it once.
        self._still = None if plan.walkers else plan.scene(pose)

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
        scene = (self._plan.scene(self._pose, time.monotonic() - self._start_s)
                 if self._still is None else self._still)
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
    return SimulatedScene(plan, pose, noise, np.random.default_rng(args.seed)), plan.name


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
