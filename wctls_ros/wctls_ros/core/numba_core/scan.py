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
    # One pass, each return written where the count of valid ones has got to (a second pass
    # through the indices of the valid ones took 12 against 8.4 us at 4320 beams).
    beams = ranges_m.size
    index = np.empty(beams, np.intp)
    range_m, bearing, x, y = np.empty(beams), np.empty(beams), np.empty(beams), np.empty(beams)
    count = 0
    for i in range(beams):
        r = ranges_m[i]
        # NaN fails every comparison, +-inf one of the two.
        if (r >= range_min_m if range_min_m > 0.0 else r > 0.0) and r <= farthest:
            index[count], range_m[count] = i, r
            bearing[count] = angle_min_rad + i * angle_increment_rad
            x[count], y[count] = r * cos[i], r * sin[i]
            count += 1
    return Returns(index[:count], range_m[:count], bearing[:count], x[:count], y[:count])
