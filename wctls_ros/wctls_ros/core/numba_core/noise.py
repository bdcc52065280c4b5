# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The range noise of a scan, estimated from the scan itself.

The derivation: docs/derivation.md#range-noise-from-the-scan.

Compiled (numba); no ROS.
"""

import math

import numpy as np

from ._jit import jit
from ._order import median
from ..rules import CUT_SIGMAS, CUT_VARIANCE, MAD_TO_SIGMA, MIN_TRIPLES, REFINEMENTS
from ..scan import ScanPoints


def scan_range_sigma(points: ScanPoints) -> float:
    """
    Compiled twin of :func:`..numpy_core.noise.scan_range_sigma`.

    :param points: the scan's valid returns
    :return: the estimated sigma, m; 0.0 with fewer than MIN_TRIPLES triples of neighbours
    """
    return range_sigma_of_returns(points.index, points.range_m)


@jit
def range_sigma_of_returns(index, range_m):
    """
    Compiled twin of :func:`..numpy_core.noise.scan_range_sigma` on the returns' arrays.

    Its medians are :func:`._order.median`'s loops.

    :param index: beam index of every return, shape (n,)
    :param range_m: range of every return, shape (n,), m
    :return: the estimated sigma, m; 0.0 with fewer than MIN_TRIPLES triples of neighbours
    """
    second = np.empty(max(index.size - 2, 0))
    triples = 0
    for i in range(1, index.size - 1):
        if index[i] - index[i - 1] == 1 and index[i + 1] - index[i] == 1:
            second[triples] = range_m[i - 1] - 2.0 * range_m[i] + range_m[i + 1]
            triples += 1
    if triples < MIN_TRIPLES:
        return 0.0
    second = second[:triples]
    centre = median(second)
    deviation = np.empty(triples)
    for k in range(triples):
        second[k] -= centre
        deviation[k] = abs(second[k])
    sigma = MAD_TO_SIGMA * median(deviation)
    for _ in range(REFINEMENTS):
        total, kept = 0.0, 0
        for k in range(triples):
            if deviation[k] < CUT_SIGMAS * sigma:
                total += second[k] * second[k]
                kept += 1
        sigma = math.sqrt(total / kept / CUT_VARIANCE) if kept else 0.0
    return sigma / math.sqrt(6.0)
