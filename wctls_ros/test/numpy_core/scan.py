# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""LaserScan geometry to Cartesian points, with REP-117 filtering of invalid returns (numpy)."""

import math
import sys

from wctls_ros.core.scan import scan_geometry, ScanError, ScanPoints  # noqa: F401


def scan_to_points(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                   range_min_m: float = 0.0, range_max_m: float = math.inf) -> ScanPoints:
    """
    Convert the ranges of a LaserScan to Cartesian points, keeping only valid returns.

    Invalid per REP-117: NaN, +-inf, ranges outside [range_min_m, range_max_m], and 0. Any beam
    count, either sign of angle_increment, any field of view up to a full turn.

    :param ranges_m: ranges, shape (N,), m
    :param angle_min_rad: bearing of the first beam, rad
    :param angle_increment_rad: bearing step between beams, rad (non-zero, either sign)
    :param range_min_m: closest valid range, m
    :param range_max_m: farthest valid range, m
    :return: the valid returns
    :raises ScanError: on a non-finite or zero increment, or more than a full turn of beams
    """
    # The geometry checks are the core's; the filtering and the points are this reference's.
    ranges, full_turn, cos, sin = scan_geometry(ranges_m, angle_min_rad, angle_increment_rad)
    beam_count = ranges.size
    # NaN fails every comparison, +-inf one of the two; a zero range is a point at the sensor
    # itself, never a wall return.
    lower = (ranges >= range_min_m) if range_min_m > 0.0 else (ranges > 0.0)
    index = (lower & (ranges <= min(range_max_m, sys.float_info.max))).nonzero()[0]
    range_m = ranges[index]
    return ScanPoints(index, range_m, angle_min_rad + index * angle_increment_rad,
                      range_m * cos[index], range_m * sin[index], bool(full_turn), beam_count,
                      float(angle_increment_rad))
