# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Sorting for the compiled kernels: a stable order and a median, as plain loops.

numba's own np.argsort(kind='mergesort') and np.median compile a generic implementation per
argument type that costs seconds on a machine that has never run the core; these few loops
cost a fraction of that and are all the pipeline needs.
"""

import numpy as np

from ._jit import jit


@jit
def stable_order(values):
    """
    Return the indices that sort ``values`` ascending, equal values in their original order.

    A bottom-up merge sort, O(n log n) on any input. NaN compares False both ways, so a NaN
    stays where the merge meets it; the callers never sort NaN.

    :param values: shape (n,)
    :return: shape (n,), int
    """
    n = values.size
    order = np.arange(n)
    spare = np.empty(n, np.intp)
    width = 1
    while width < n:
        for low in range(0, n, 2 * width):
            middle, high = min(low + width, n), min(low + 2 * width, n)
            left, right, out = low, middle, low
            while left < middle and right < high:
                # Take from the right only when strictly smaller: equal values keep their order.
                if values[order[right]] < values[order[left]]:
                    spare[out] = order[right]
                    right += 1
                else:
                    spare[out] = order[left]
                    left += 1
                out += 1
            while left < middle:
                spare[out] = order[left]
                left += 1
                out += 1
            while right < high:
                spare[out] = order[right]
                right += 1
                out += 1
        order, spare = spare, order
        width *= 2
    return order


@jit
def median(values):
    """
    Return the median of ``values`` (the mean of the two middle ones for an even count).

    :param values: shape (n,), n >= 1, no NaN
    :return: the median
    """
    order = stable_order(values)
    middle = values.size // 2
    if values.size % 2:
        return values[order[middle]]
    return 0.5 * (values[order[middle - 1]] + values[order[middle]])
