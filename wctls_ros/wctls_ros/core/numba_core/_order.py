# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Order for the compiled kernels: a stable order and a median as plain loops, circular positions.

numba's own np.argsort(kind='mergesort') and np.median compile a generic implementation per
argument type that costs seconds on a machine that has never run the core; these few loops
cost a fraction of that and are all the pipeline needs.
"""

import numpy as np

from ._jit import jit


@jit
def wrapped(position, n):
    """
    Return a position taken modulo n (a segment across the seam of a full turn runs past n).

    For a position >= 0 that is at most a turn or two past n, as in the loops over a segment's
    or a window's returns: a subtraction where ``%`` divides (tens of cycles), once per return.
    """
    while position >= n:
        position -= n
    return position


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


# Runs this short are sorted by insertion before merging (fewer passes over the data).
_RUN = 16


@jit
def sorted_copy(values):
    """
    Return the values sorted ascending: insertion-sorted runs of 16, then bottom-up merges.

    O(n log n) on any input (no pivot an adversarial scan could defeat). No NaN.

    :param values: shape (n,)
    :return: a sorted copy, shape (n,)
    """
    n = values.size
    ordered = values.copy()
    for low in range(0, n, _RUN):
        for i in range(low + 1, min(low + _RUN, n)):
            value, j = ordered[i], i - 1
            while j >= low and ordered[j] > value:
                ordered[j + 1] = ordered[j]
                j -= 1
            ordered[j + 1] = value
    spare = np.empty(n)
    width = _RUN
    while width < n:
        for low in range(0, n, 2 * width):
            middle, high = min(low + width, n), min(low + 2 * width, n)
            left, right = low, middle
            for out in range(low, high):
                if right >= high or (left < middle and ordered[left] <= ordered[right]):
                    spare[out] = ordered[left]
                    left += 1
                else:
                    spare[out] = ordered[right]
                    right += 1
        ordered, spare = spare, ordered
        width *= 2
    return ordered


@jit
def median(values):
    """
    Return the median of ``values`` (the mean of the two middle ones for an even count).

    :param values: shape (n,), n >= 1, no NaN
    :return: the median
    """
    ordered = sorted_copy(values)
    middle = values.size // 2
    if values.size % 2:
        return ordered[middle]
    return 0.5 * (ordered[middle - 1] + ordered[middle])
