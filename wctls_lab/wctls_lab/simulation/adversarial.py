# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Scans crafted to find the worst case of the feature pipeline (numpy only).

No sensor produces these; anything that can publish on a LaserScan topic (or write a bag) can.
The tests and ``bench_core.py`` use them to show that one such scan costs about as much as a
room scan of the same beam count.
"""

import math

import numpy as np


def peeling_wall(beams: int, wall_m: float = 2.0, behind_m=(0.045, 0.12),
                 field_of_view_rad: float = math.pi / 2):
    """
    Return a scan of a straight wall whose every other return lies behind it, by a growing gap.

    The gap grows from ``behind_m[0]`` at the first beam to ``behind_m[1]`` at the last: the
    return farthest from the chord of any run then sits next to the run's end, so an
    Iterative End Point Fit that splits at the farthest return peels two returns per level and
    needs beams / 2 levels. The default gaps stay within the breakpoint rule's allowance of a
    5 cm range noise, so the whole scan is one chain, and exceed the paper's fixed 4 cm split
    distance; a split distance of 4 sigma of that noise sees them as noise.

    :param beams: number of beams, >= 2
    :param wall_m: distance of the wall from the sensor, m
    :param behind_m: gap behind the wall at the first and at the last beam, m
    :param field_of_view_rad: angle the beams span, centred on the wall's normal, rad
    :return: (ranges (beams,) m, angle_min rad, angle_increment rad)
    """
    increment = field_of_view_rad / (beams - 1)
    angle_min = -field_of_view_rad / 2.0
    bearing = angle_min + increment * np.arange(beams)
    along = 1.0 / np.cos(bearing)
    ranges = wall_m * along
    ranges[1::2] += np.linspace(*behind_m, beams)[1::2] * along[1::2]
    return ranges, angle_min, increment
