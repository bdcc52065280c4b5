# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A turn in sllidar_ros2's layout, and as a fixed-count scan: LaserScan fields (pure).

- Published angle = offset - raw clockwise angle, counter-clockwise (REP-103) in both
  orientations: offset pi in the ``sllidar`` orientation (x toward the raw 180 deg side, as
  sllidar_ros2), 0 in the ``rep103`` one (x toward the device's front, raw 0 deg). The arrays
  ascend in published angle (``inverted`` mirrors the array order, as sllidar does for a sensor
  mounted upside down).
- ``angle_compensate``: the turn is binned into N = ``360 * k`` bins as sllidar_ros2 bins it
  (bin j holds raw angles [j / k, (j + 1) / k) deg; beam i is bin N - 1 - i, or bin i when
  ``inverted``), each beam published at its bin's centre: increment w = 2 pi / N, angle_min =
  offset - 2 pi + w / 2, angle_max = angle_min + (N - 1) w. A bin holds the one sample nearest
  its centre: +inf when that sample had no return, NaN (no measurement, REP-117) when no sample
  fell in it, as in the fixed-count scan. sllidar_ros2 publishes the same bins from offset - 2 pi
  to offset, increment 2 pi / (N - 1), so its bearings drift by up to a bin along the turn and
  jump back by one across the seam; it also copies each sample into the next k - 1 bins (a
  quarter of an A2's beams hold a copy 0.5-2.4 bins off its sample's bearing) and leaves the
  bins left empty +inf.
- Otherwise the beams lie on the turn's own angle grid, from its first to its last sample with
  a return (so the beam count and angle_min/max change from turn to turn): increment = the
  turn's angle step (the median advance between consecutive samples), each beam holding the
  sample nearest its bearing, so that every sample is published within half a step of its own
  bearing; a grid angle no sample fell near is NaN (no measurement, REP-117). On a device that
  samples a uniform grid (dense and standard nodes) that is one beam per sample, each at its
  sample's bearing; express and ultra capsules' corrected angles (up to 8 degrees) and lost
  frames no longer spread the samples evenly between the first and the last, as sllidar_ros2
  does (1.9-2.6 degrees off on clean A-series streams, up to 54 after a lost capsule).
- No return -> +inf; intensities = the 6-bit quality (sllidar's ``quality >> 2``).
- :func:`fixed_scan`: N bins of 2 pi / N from -pi, each holding the sample nearest its centre
  (+inf for a sample without a return); a bin no sample fell in is NaN (no measurement,
  REP-117). The same N every turn, angles in [-pi, pi) whatever the orientation.

Time order: the sensor sweeps clockwise, so published angles fall as time goes on and the
arrays, ascending in angle, run backwards in time. header.stamp is the measurement time of the
turn's first sample (raw angle ~0: the last beam of the per-sample and binned scans, published
angle offset, or offset - w / 2); beam i of an N-beam scan was measured about
``(N - 1 - i) * time_increment`` after it. In the fixed-count scan the turn starts and ends at
the bin holding raw angle 0 (published angle offset: the array's ends for ``sllidar``, its
middle for ``rep103``).

The timing fields are this driver's own, honest ones: scan_time is the measured rotation period
and time_increment the time the sensor takes to sweep one angle_increment.
"""

from dataclasses import dataclass, replace
import math

import numpy as np

from .turns import Turn

RANGE_MIN_M = 0.05
# Published angle = offset - raw angle, per laser frame orientation, rad.
ORIENTATION_OFFSETS_RAD = {'sllidar': math.pi, 'rep103': 0.0}


@dataclass(frozen=True)
class ScanArrays:
    """
    The fields of a sensor_msgs/LaserScan computed from one turn.

    :ivar angle_min: rad
    :ivar angle_max: rad
    :ivar angle_increment: rad
    :ivar time_increment: s between adjacent beams
    :ivar scan_time: s per turn
    :ivar ranges: float32, m, +inf for no return
    :ivar intensities: float32, 6-bit quality
    """

    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float
    scan_time: float
    ranges: np.ndarray
    intensities: np.ndarray


def compensation_multiple(us_per_sample: float, scan_frequency_hz: float) -> int:
    """
    Return sllidar's bins per degree: ``floor(samples_per_turn / 360 + 1)``, at least 1.

    :param us_per_sample: the scan mode's sample period, microseconds
    :param scan_frequency_hz: the rotation frequency, Hz
    :return: k (3 for DenseBoost at 10 Hz: 1080 bins)
    """
    samples_per_turn = int(1e6 / us_per_sample / scan_frequency_hz)
    return max(int(samples_per_turn / 360.0 + 1), 1)


def _binned(turn: Turn, position: np.ndarray, bins: int) -> tuple:
    """
    Return (ranges m, intensities) of ``bins`` bins, each holding the sample nearest its centre.

    The nearest sample has the smallest bearing error whatever the sample density; a sample is
    never repeated into another bin (sllidar_ros2 copies each into the next k - 1 bins, where
    it is up to a bin or more off its bearing).

    :param turn: the assembled turn
    :param position: each sample's place in bin widths from the first bin's start (bin i spans
        [i, i + 1); places at or past ``bins`` go to the last bin)
    :param bins: the number of bins
    :return: float32 arrays in bin order: +inf where the sample had no return, NaN (no
        measurement, REP-117; intensity 0) where no sample fell in the bin
    """
    index = np.minimum(position.astype(np.int64), bins - 1)
    off_centre = np.abs(position - index - 0.5)
    order = np.lexsort((off_centre, index))
    owners, first = np.unique(index[order], return_index=True)
    nearest = order[first]
    ranges = np.full(bins, np.nan, np.float32)
    intensities = np.zeros(bins, np.float32)
    distance_mm = turn.distance_mm[nearest]
    ranges[owners] = np.where(distance_mm > 0, distance_mm / 1000.0, np.inf)
    intensities[owners] = turn.quality[nearest]
    return ranges, intensities


def orientation_offset_rad(orientation: str) -> float:
    """
    Return the published angle of raw angle 0 in a laser frame orientation.

    :param orientation: ``'sllidar'`` or ``'rep103'``
    :return: rad
    :raises ValueError: on another orientation
    """
    if orientation not in ORIENTATION_OFFSETS_RAD:
        raise ValueError(f'orientation must be one of {tuple(ORIENTATION_OFFSETS_RAD)}, got '
                         f'{orientation!r}')
    return ORIENTATION_OFFSETS_RAD[orientation]


def turn_to_scan(turn: Turn, angle_compensate: bool, inverted: bool, multiple: int,
                 orientation: str = 'sllidar') -> ScanArrays:
    """
    Lay one turn out as sllidar_ros2 does, with every beam at its samples' bearing.

    :param turn: the assembled turn
    :param angle_compensate: bin into ``360 * multiple`` fixed beams
    :param inverted: the sensor is mounted upside down (mirror the array order)
    :param multiple: bins per degree for ``angle_compensate`` (see :func:`compensation_multiple`)
    :param orientation: the laser frame, ``'sllidar'`` or ``'rep103'``
    :return: the LaserScan fields
    :raises ValueError: on an unknown orientation
    """
    offset = orientation_offset_rad(orientation)
    if angle_compensate:
        return _compensated_scan(turn, inverted, multiple, offset)
    return _grid_scan(turn, inverted, offset)


def _grid_scan(turn: Turn, inverted: bool, offset_rad: float) -> ScanArrays:
    """
    Lay one turn out on its own angle grid, from its first to its last return (see the module).

    Beam k (in raw order) is at raw angle a0 + k s, s the turn's step: the sample nearest it,
    at most s / 2 away, fills it.

    :param turn: the assembled turn
    :param inverted: the sensor is mounted upside down (mirror the array order)
    :param offset_rad: the published angle of raw angle 0
    :return: the LaserScan fields, increment s (0 for a single beam)
    """
    angle = turn.angle_deg
    advances = np.diff(angle)
    advances = advances[advances > 0.0]
    step_deg = float(np.median(advances)) if advances.size else 1.0
    returns = turn.distance_mm > 0
    ends = angle[returns] if returns.any() else angle
    first_deg, last_deg = float(ends.min()), float(ends.max())
    count = int(round((last_deg - first_deg) / step_deg)) + 1
    position = (angle - first_deg) / step_deg + 0.5
    near = (position >= 0.0) & (position < count)
    ranges, intensities = _binned(replace(turn, angle_deg=angle[near],
                                          distance_mm=turn.distance_mm[near],
                                          quality=turn.quality[near]), position[near], count)
    step_rad = math.radians(step_deg)
    raw_max = math.radians(first_deg) + (count - 1) * step_rad
    if not inverted:
        ranges, intensities = ranges[::-1], intensities[::-1]
    return ScanArrays(angle_min=offset_rad - raw_max, angle_max=offset_rad - math.radians(
                          first_deg), angle_increment=step_rad if count > 1 else 0.0,
                      time_increment=step_rad / (2.0 * math.pi) * turn.period_s,
                      scan_time=turn.period_s, ranges=np.ascontiguousarray(ranges),
                      intensities=np.ascontiguousarray(intensities))


def _compensated_scan(turn: Turn, inverted: bool, multiple: int, offset_rad: float) -> ScanArrays:
    """
    Lay one turn out in ``360 * multiple`` bins of raw angle, each published at its centre.

    Bin j holds raw angles [j / k, (j + 1) / k) deg, k = ``multiple``, as in sllidar_ros2;
    their published angles offset - raw lie in (offset - (j + 1) w, offset - j w], w = 2 pi / N,
    so bin j's centre is offset - (j + 1/2) w. Upright, the array ascends in published angle (beam
    i holds bin N - 1 - i, sllidar's order): angle_min = offset - 2 pi + w / 2. Inverted, beam i
    holds bin i, whose mirrored angle raw - offset is the same offset - 2 pi + (i + 1/2) w modulo
    2 pi (offset 0 or pi): the same fields, the array reversed.

    :param turn: the assembled turn
    :param inverted: the sensor is mounted upside down (mirror the array order)
    :param multiple: bins per degree
    :param offset_rad: the published angle of raw angle 0
    :return: the LaserScan fields, increment 2 pi / N
    """
    bins = 360 * multiple
    width = 2.0 * math.pi / bins
    ranges, intensities = _binned(turn, turn.angle_deg * multiple, bins)
    if not inverted:
        ranges, intensities = ranges[::-1], intensities[::-1]
    return ScanArrays(angle_min=offset_rad - 2.0 * math.pi + 0.5 * width,
                      angle_max=offset_rad - 0.5 * width, angle_increment=width,
                      time_increment=turn.period_s / bins, scan_time=turn.period_s,
                      ranges=np.ascontiguousarray(ranges),
                      intensities=np.ascontiguousarray(intensities))


def fixed_scan(turn: Turn, beams: int, inverted: bool, orientation: str) -> ScanArrays:
    """
    Lay one turn out as ``beams`` fixed angular bins: the same beams every turn.

    Bin i spans published angles [-pi + i w, -pi + (i + 1) w), w = 2 pi / beams, and holds the
    range of the sample nearest its centre; +inf where that sample had no return, NaN where no
    sample fell in the bin.

    :param turn: the assembled turn
    :param beams: the number of bins, at least 1
    :param inverted: the sensor is mounted upside down (mirror the angles)
    :param orientation: the laser frame, ``'sllidar'`` or ``'rep103'``
    :return: the LaserScan fields, angle_min = -pi + w / 2, increment w
    :raises ValueError: on an unknown orientation or no bins
    """
    if beams < 1:
        raise ValueError(f'a fixed-count scan needs at least 1 beam, got {beams}')
    offset = orientation_offset_rad(orientation)
    width = 2.0 * math.pi / beams
    angle = offset - np.radians(turn.angle_deg)
    if inverted:
        angle = -angle
    ranges, intensities = _binned(turn, np.mod(angle + math.pi, 2.0 * math.pi) / width, beams)
    return ScanArrays(angle_min=-math.pi + 0.5 * width, angle_max=math.pi - 0.5 * width,
                      angle_increment=width, time_increment=turn.period_s / beams,
                      scan_time=turn.period_s, ranges=ranges, intensities=intensities)
