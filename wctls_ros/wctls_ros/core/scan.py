# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
LaserScan geometry to Cartesian points, with REP-117 filtering of invalid returns.

Shared by both implementations of the pipeline: the geometry checks and the beam directions
(:func:`scan_geometry`) and the valid returns as points (:func:`scan_to_points`, numpy; the
compiled pipeline has its own loop, ``numba_core.scan.valid_returns``).
"""

from collections import OrderedDict
from dataclasses import dataclass
import math
import sys
import threading

import numpy as np

# A scan whose last beam is at most this many increments short of a full turn after its first
# is a full turn: its last beam neighbours its first across the +-pi seam. (A driver that
# publishes every sample of a turn, like sllidar_ros2 without angle_compensate, gives 926 or 927
# beams for 925.9 samples per turn: the seam gap varies between 0 and 2 increments.)
_FULL_TURN_GAP_INCREMENTS = 2.5
# More than a full turn between the first and last beam (beyond float32 rounding of the
# LaserScan's angle_increment) would revisit bearings: refused.
_OVER_TURN_TOLERANCE = 1e-4
# The largest float: a range_max of inf still refuses nothing finite.
_LARGEST_RANGE = sys.float_info.max


class ScanError(ValueError):
    """A scan that cannot be interpreted (bad geometry, mismatched arrays)."""


@dataclass(frozen=True)
class ScanPoints:
    """
    The valid returns of one scan, in beam order.

    :ivar index: beam index of each return in the original ranges array, shape (n,)
    :ivar range_m: measured range, shape (n,), m
    :ivar bearing_rad: beam bearing, shape (n,), rad (angle_min + index * angle_increment)
    :ivar x_m: Cartesian x in the scan frame, shape (n,), m
    :ivar y_m: Cartesian y in the scan frame, shape (n,), m
    :ivar full_turn: True when the beams cover a full turn (the first and last are neighbours,
        at most 2.5 increments apart across the seam)
    :ivar beam_count: number of beams of the scan, valid or not
    :ivar angle_increment_rad: bearing step between beams, rad
    """

    index: np.ndarray
    range_m: np.ndarray
    bearing_rad: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    full_turn: bool
    beam_count: int
    angle_increment_rad: float

    def __len__(self):
        return len(self.index)


class _DirectionCache:
    """
    cos and sin of the beams of the latest scan geometries, bounded by bytes, not entries.

    A sensor's geometry rarely changes, so the bearings' trigonometry is worth keeping; but a
    geometry of a million beams holds 16 MB, and a publisher that changes the geometry every
    scan must not grow the node's memory. The least recently used geometries go first; one too
    large for the whole budget is computed and not kept.
    """

    def __init__(self, max_bytes: int):
        self.max_bytes = max_bytes
        self.bytes = 0
        self._entries: OrderedDict = OrderedDict()
        self._lock = threading.Lock()          # user scripts may extract from several threads

    def directions(self, angle_min_rad: float, angle_increment_rad: float, beam_count: int):
        """
        Return cos and sin of every beam's bearing.

        :return: (cos, sin), each shape (beam_count,), read-only
        """
        key = (angle_min_rad, angle_increment_rad, beam_count)
        with self._lock:
            if key in self._entries:
                self._entries.move_to_end(key)
                return self._entries[key]
        bearing = angle_min_rad + np.arange(beam_count) * angle_increment_rad
        cos, sin = np.cos(bearing), np.sin(bearing)
        cos.flags.writeable = sin.flags.writeable = False
        size = cos.nbytes + sin.nbytes
        with self._lock:
            if size <= self.max_bytes and key not in self._entries:
                self._entries[key] = cos, sin
                self.bytes += size
                while self.bytes > self.max_bytes:
                    old_cos, old_sin = self._entries.popitem(last=False)[1]
                    self.bytes -= old_cos.nbytes + old_sin.nbytes
        return cos, sin


# 8 MB: hundreds of geometries of a few thousand beams, or the latest few of 100 000.
_BEAM_DIRECTIONS = _DirectionCache(8 * 2 ** 20)


def scan_geometry(ranges_m, angle_min_rad: float, angle_increment_rad: float):
    """
    Check a LaserScan's geometry and return what the compiled pipeline needs of it.

    :param ranges_m: ranges, shape (N,), m
    :param angle_min_rad: bearing of the first beam, rad
    :param angle_increment_rad: bearing step between beams, rad (non-zero, either sign)
    :return: (the ranges as a new float64 array (N,), whether the beams cover a full turn,
        cos and sin of every beam's bearing (N,) each, read-only)
    :raises ScanError: on ranges that are not one-dimensional, a non-finite or zero increment,
        or more than a full turn of beams
    """
    ranges = np.array(ranges_m, dtype=np.float64)       # a copy: contiguous and writable
    if ranges.ndim != 1:
        raise ScanError(f'ranges must be one-dimensional, got shape {ranges.shape}')
    if not (math.isfinite(angle_min_rad) and math.isfinite(angle_increment_rad)):
        raise ScanError('angle_min and angle_increment must be finite')
    if angle_increment_rad == 0.0 and ranges.size > 1:
        raise ScanError('angle_increment is 0: the beams have no distinct bearings')
    beam_count = ranges.size
    span = abs(angle_increment_rad) * max(beam_count - 1, 0)
    if span > 2.0 * math.pi * (1.0 + _OVER_TURN_TOLERANCE):
        raise ScanError(f'{beam_count} beams of {angle_increment_rad:g} rad span {span:.4f} rad, '
                        'more than a full turn')
    full_turn = (beam_count > 1 and 2.0 * math.pi - span
                 <= _FULL_TURN_GAP_INCREMENTS * abs(angle_increment_rad))
    cos, sin = _BEAM_DIRECTIONS.directions(float(angle_min_rad), float(angle_increment_rad),
                                           beam_count)
    return ranges, bool(full_turn), cos, sin


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
    ranges, full_turn, cos, sin = scan_geometry(ranges_m, angle_min_rad, angle_increment_rad)
    beam_count = ranges.size
    # NaN fails every comparison, +-inf one of the two; a zero range is a point at the sensor
    # itself, never a wall return.
    lower = (ranges >= range_min_m) if range_min_m > 0.0 else (ranges > 0.0)
    index = (lower & (ranges <= min(range_max_m, _LARGEST_RANGE))).nonzero()[0]
    range_m = ranges[index]
    return ScanPoints(index, range_m, angle_min_rad + index * angle_increment_rad,
                      range_m * cos[index], range_m * sin[index], bool(full_turn), beam_count,
                      float(angle_increment_rad))
