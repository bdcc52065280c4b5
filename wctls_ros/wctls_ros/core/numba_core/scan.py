# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The valid returns of a scan as points, one compiled loop (see ``wctls_ros.core.scan``)."""

import numpy as np

from ._jit import jit
from ..records import Returns
from ..scan import _LARGEST_RANGE


@jit
def valid_returns(ranges_m, cos, sin, angle_min_rad, angle_increment_rad, range_min_m,
                  range_max_m):
    """
    Compiled twin of :func:`..scan.scan_to_points`, on :func:`..scan.scan_geometry`'s beams.

    :param ranges_m: ranges, shape (N,), m
    :param cos: cos of every beam's bearing, shape (N,)
    :param sin: sin of every beam's bearing, shape (N,)
    :param angle_min_rad: bearing of the first beam, rad
    :param angle_increment_rad: bearing step, rad
    :param range_min_m: closest valid range, m
    :param range_max_m: farthest valid range, m
    :return: the returns (:class:`~.records.Returns`)
    """
    farthest = min(range_max_m, _LARGEST_RANGE)
    index = np.empty(ranges_m.size, np.intp)
    count = 0
    for i in range(ranges_m.size):
        r = ranges_m[i]
        # NaN fails every comparison, +-inf one of the two.
        if (r >= range_min_m if range_min_m > 0.0 else r > 0.0) and r <= farthest:
            index[count] = i
            count += 1
    index = index[:count]
    range_m = np.empty(count)
    bearing, x, y = np.empty(count), np.empty(count), np.empty(count)
    for k in range(count):
        i = index[k]
        range_m[k] = ranges_m[i]
        bearing[k] = angle_min_rad + i * angle_increment_rad
        x[k], y[k] = range_m[k] * cos[i], range_m[k] * sin[i]
    return Returns(index, range_m, bearing, x, y)
