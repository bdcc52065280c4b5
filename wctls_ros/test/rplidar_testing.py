# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Helpers shared by the RPLIDAR tests: the emulator and its scene's true ranges."""

import numpy as np
from wctls_ros.rplidar.emulator import EmulatorProcess
from wctls_ros.simulation import cast_rays, load_floor_plan

# The emulator's default scene: the bundled plan seen from its own sensor pose.
WALLS, _ = load_floor_plan('environment_a').in_sensor_frame()


def true_ranges(bearings_rad):
    """
    Return the noiseless ranges of the emulator's scene along laser-frame bearings.

    :param bearings_rad: bearings, rad, counter-clockwise (REP-103)
    :return: ranges, m
    """
    return cast_rays(WALLS, np.zeros(2), np.asarray(bearings_rad, dtype=float))


def range_band(low_rad, high_rad, steps=17):
    """
    Return the scene's smallest and largest range over bearing intervals.

    :param low_rad: interval starts, rad
    :param high_rad: interval ends, rad
    :param steps: bearings sampled per interval
    :return: (lowest, highest) range per interval, m
    """
    fractions = np.linspace(0.0, 1.0, steps)
    bearings = np.asarray(low_rad)[:, None] + np.outer(np.asarray(high_rad) - low_rad, fractions)
    ranges = true_ranges(bearings.ravel()).reshape(bearings.shape)
    return ranges.min(axis=1), ranges.max(axis=1)


def start_emulator(directory, *options):
    """
    Start a noiseless emulator whose terminal is linked at ``directory/ttyS1``.

    :param directory: a pathlib.Path for the link
    :param options: more emulator options
    :return: the running :class:`EmulatorProcess` (a context manager)
    """
    return EmulatorProcess(['--noiseless', '--link', str(directory / 'ttyS1'), *options])
