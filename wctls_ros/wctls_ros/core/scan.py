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
from statistics import NormalDist
import sys
import threading
from typing import NamedTuple

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


# The beam spacing the pipeline's rules were tuned at: 1080 beams per turn (the RPLIDAR S1's
# published scans), rad. At a finer spacing the rules that count returns keep what they mean in
# degrees (:func:`beam_density`).
TUNED_STEP_RAD = 2.0 * math.pi / 1080
# At the tuned spacing the breakpoint rule allows 3 sigma of a return's position noise between
# neighbours (whose difference has sqrt(2) sigma).
_BREAKPOINT_SIGMAS_AT_TUNED = 3.0
# At the tuned spacing: the most returns each end trim examines, and the most returns between
# two walls that meet at a corner (the ones both trims leave out, the IEPF split return, and
# pieces of a wall too short to be segments, cut off by something in front of it: a leg).
_END_WINDOW_AT_TUNED = 8
_CORNER_WINDOW_AT_TUNED = 40
# The smallest tail probability a threshold is computed for (about 37 sigma): below it, the
# normal quantile function has no answer in floats.
_SMALLEST_TAIL = 1e-300


class BeamDensity(NamedTuple):
    """
    What the pipeline's rules that count returns become at a scan's beam spacing.

    :ivar finer: returns per tuned step, >= 1 (1 at 1080 beams per turn and coarser)
    :ivar breakpoint_sigmas: the breakpoint rule's allowance, in sigmas of a return's noise
    :ivar end_window: the most returns each end trim examines
    :ivar corner_window: the most returns between two walls that meet at a corner
    """

    finer: float
    breakpoint_sigmas: float
    end_window: int
    corner_window: int

    def rarer(self, sigmas: float, spread: float = 1.0) -> float:
        """
        Return a noise threshold that noise exceeds as often per degree as at the tuned spacing.

        A threshold of ``sigmas`` (in sigmas of a return's noise) on a normal quantity of
        ``spread`` sigmas is exceeded by noise with probability p = 2 (1 - Phi(sigmas /
        spread)) per return. With f = ``finer`` times the returns per degree the threshold is
        raised until p / f^2: then noise exceeds it f times less often per degree than at the
        tuned spacing, where the geometric terms of the rules cover most pairs; at a finer
        spacing those terms vanish and noise alone decides (measured: with p / f, a 100 000-beam
        room scan breaks its walls 18 more times than at 1080 beams; with p / f^2, none).

        :param sigmas: the threshold at the tuned spacing
        :param spread: the tested quantity's std, in sigmas of a return (sqrt(2) for the
            difference of two returns)
        :return: the threshold at this spacing, >= sigmas
        """
        if self.finer == 1.0 or sigmas <= 0.0:
            return sigmas
        exceeded = NormalDist().cdf(-sigmas / spread) / self.finer ** 2
        return -spread * NormalDist().inv_cdf(max(exceeded, _SMALLEST_TAIL))


def beam_density(angle_increment_rad: float, beam_count: int) -> BeamDensity:
    """
    Return the rules that count returns at a scan's beam spacing (docs/derivation.md#density).

    Finer than the tuned spacing by a factor f, a wall has f times the returns: the windows
    grow by f so that they span the same angle, and the breakpoint allowance grows so that noise
    separates f^2 times fewer pairs of neighbours, the same number per turn where noise decides
    every pair (:meth:`BeamDensity.rarer`). Coarser scans keep the tuned rules. A scan of n
    beams counts as at most n times finer: no window need exceed its returns.

    :param angle_increment_rad: the scan's bearing step, rad (its sign is ignored)
    :param beam_count: the scan's beams, valid or not
    :return: the rules
    """
    step = abs(angle_increment_rad)
    finer = min(max(1.0, TUNED_STEP_RAD / step), max(beam_count, 1)) if step > 0.0 else 1.0
    tuned = BeamDensity(finer, _BREAKPOINT_SIGMAS_AT_TUNED,
                        math.ceil(_END_WINDOW_AT_TUNED * finer),
                        math.ceil(_CORNER_WINDOW_AT_TUNED * finer))
    return tuned._replace(breakpoint_sigmas=tuned.rarer(_BREAKPOINT_SIGMAS_AT_TUNED,
                                                        math.sqrt(2.0)))


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

    A sensor's scans share one geometry: the one found last is found again without the lock
    and the reordering (about half a microsecond per scan less), as long as it is kept.
    """

    def __init__(self, max_bytes: int):
        self.max_bytes = max_bytes
        self.bytes = 0
        self._entries: OrderedDict = OrderedDict()
        self._lock = threading.Lock()          # user scripts may extract from several threads
        # (key, (cos, sin)) of the latest geometry found or kept, replaced whole.
        self._latest: tuple = (None, None)

    def directions(self, angle_min_rad: float, angle_increment_rad: float, beam_count: int):
        """
        Return cos and sin of every beam's bearing.

        :return: (cos, sin), each shape (beam_count,), read-only
        """
        key = (angle_min_rad, angle_increment_rad, beam_count)
        latest = self._latest
        if latest[0] == key:       # the most recently used already
            return latest[1]
        with self._lock:
            if key in self._entries:
                self._entries.move_to_end(key)
                self._latest = key, self._entries[key]
                return self._latest[1]
        bearing = angle_min_rad + np.arange(beam_count) * angle_increment_rad
        cos, sin = np.cos(bearing), np.sin(bearing)
        cos.flags.writeable = sin.flags.writeable = False
        size = cos.nbytes + sin.nbytes
        with self._lock:
            if size <= self.max_bytes and key not in self._entries:
                self._entries[key] = cos, sin
                self._latest = key, (cos, sin)
                self.bytes += size
                while self.bytes > self.max_bytes:      # never the latest: it fits alone
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
    :return: (the ranges as a contiguous, writable float64 array (N,): ``ranges_m`` itself when
        it is one, else a copy; whether the beams cover a full turn; cos and sin of every
        beam's bearing (N,) each, read-only)
    :raises ScanError: on ranges that are not one-dimensional, a non-finite or zero increment,
        or more than a full turn of beams
    """
    # Of one numba type whatever the caller's array (the compiled pipeline is compiled for it),
    # copied only when it is not of it already: the copy of a 4320-beam scan took 3 us.
    ranges = np.asarray(ranges_m, dtype=np.float64)
    flags = ranges.flags
    if not (flags.c_contiguous and flags.writeable and flags.aligned):
        ranges = ranges.copy()
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
