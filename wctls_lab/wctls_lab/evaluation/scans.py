# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Repeated scans of one sensor: loading them from a bag or from JSON scans.

Pure numpy: the bag is read through :mod:`wctls_ros.bags`, and the scans are held as one
(T, N) array of ranges with a common beam geometry. Whether they come from a still sensor is
decided by :func:`.rules.check_still`.
"""

from dataclasses import dataclass
import json
import math
import pathlib
import re
from typing import Optional

import numpy as np


@dataclass(frozen=True)
class StaticScans:
    """
    Repeated scans with one beam geometry.

    :ivar ranges: ranges, shape (T, N), m; +inf (or NaN) for no return
    :ivar angle_min: bearing of the first beam, rad
    :ivar angle_increment: bearing step, rad
    :ivar range_min: the scans' range_min, m
    :ivar range_max: the scans' range_max, m
    :ivar stamps_ns: header stamp of each scan, shape (T,), ns
    :ivar source: where the scans came from (a bag path or a description)
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    stamps_ns: np.ndarray
    source: str = ''

    def __len__(self):
        return len(self.ranges)

    @property
    def bearings(self) -> np.ndarray:
        """
        Return the beam bearings.

        :return: shape (N,), rad
        """
        return self.angle_min + self.angle_increment * np.arange(self.ranges.shape[1])

    def part(self, first: int, stop: int) -> 'StaticScans':
        """
        Return the scans first to stop - 1.

        :param first: index of the first scan kept
        :param stop: index after the last scan kept
        :return: the scans, with the same geometry and source
        """
        return StaticScans(self.ranges[first:stop], self.angle_min, self.angle_increment,
                           self.range_min, self.range_max, self.stamps_ns[first:stop],
                           self.source)

    def valid(self) -> np.ndarray:
        """
        Return which ranges are usable returns (finite, within the scans' limits, not 0).

        :return: boolean, shape (T, N)
        """
        with np.errstate(invalid='ignore'):
            return (np.isfinite(self.ranges) & (self.ranges >= self.range_min)
                    & (self.ranges <= self.range_max) & (self.ranges > 0.0))


def load_scans(path, topic: Optional[str] = None, limit: Optional[int] = None) -> StaticScans:
    """
    Read the LaserScans of a bag into one array.

    :param path: a ROS 2 bag (mcap or sqlite3) or a ROS 1 bag
    :param topic: the LaserScan topic, or None for the bag's only one
    :param limit: read at most this many scans (None: all)
    :return: the scans
    :raises wctls_ros.bags.BagError: on an unreadable bag
    :raises ValueError: when the bag holds no scans or scans of different beam layouts
    """
    from wctls_ros.bags import read_scans
    ranges, stamps, geometry = [], [], None
    for record in read_scans(path, topic):
        scan = record.scan
        this = (len(scan.ranges), round(float(scan.angle_min), 9),
                round(float(scan.angle_increment), 12))
        if geometry is None:
            geometry = this + (float(scan.range_min), float(scan.range_max))
        elif this != geometry[:3]:
            raise ValueError(f'{path}: the beam layout changes between scans ({geometry[:3]} '
                             f'then {this}); repeated scans of one sensor are needed')
        ranges.append(np.asarray(scan.ranges, dtype=float))
        stamps.append(int(scan.header.stamp.sec) * 10 ** 9 + int(scan.header.stamp.nanosec))
        if limit is not None and len(ranges) >= limit:
            break
    if not ranges:
        raise ValueError(f'{path} holds no scans')
    return StaticScans(np.array(ranges), geometry[1], geometry[2], geometry[3], geometry[4],
                       np.array(stamps, dtype=np.int64), str(path))


def load_json_scans(path) -> StaticScans:
    """
    Read single scans saved as JSON ``{"ranges": [...], "bearings": [...]}`` (m, rad).

    That is how laser_line_extraction's test scans (``data/lms111_building``) are stored. A
    folder gives all its ``*.json`` files in natural name order (scan_2 before scan_10), one scan
    each; they must share one beam layout with evenly spaced bearings.

    :param path: a JSON file or a folder of them
    :return: the scans (range limits 0 and +inf: a 0 range is no return)
    :raises ValueError: on an unreadable file, a malformed scan or different beam layouts
    """
    path = pathlib.Path(path)
    files = (sorted(path.glob('*.json'), key=lambda p: [int(part) if part.isdigit() else part
                                                        for part in re.split(r'(\d+)', p.name)])
             if path.is_dir() else [path])
    if not files:
        raise ValueError(f'{path} holds no JSON scans')
    ranges, layout = [], None
    for file in files:
        try:
            document = json.loads(file.read_text())
            scan_ranges = np.asarray(document['ranges'], dtype=float).reshape(-1)
            bearings = np.asarray(document['bearings'], dtype=float).reshape(-1)
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as error:
            raise ValueError(f'{file}: not a JSON scan with ranges and bearings ({error})') \
                from error
        steps = np.diff(bearings)
        if (len(bearings) != len(scan_ranges) or len(bearings) < 2 or not np.all(
                np.isfinite(bearings)) or np.ptp(steps) > 1e-6 * abs(steps[0]) or steps[0] == 0):
            raise ValueError(f'{file}: ranges and bearings must match, with evenly spaced '
                             'bearings')
        this = (len(bearings), round(float(bearings[0]), 9), round(float(steps.mean()), 12))
        if layout is not None and this != layout:
            raise ValueError(f'{file}: its beam layout {this} differs from {layout}')
        layout = this
        ranges.append(scan_ranges)
    return StaticScans(np.array(ranges), layout[1], layout[2], 0.0, math.inf,
                       np.arange(len(ranges), dtype=np.int64), str(path))
