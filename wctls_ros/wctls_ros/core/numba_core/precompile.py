# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The pipeline compiled before the first scan, or loaded from numba's on-disk cache.

From the cache the compiled pipeline loads in a fraction of a second. Without it (the first run
on a machine, or after an upgrade) numba compiles it: 16-20 s of CPU on a 2-core EPYC VM. Nobody
waits for that: :mod:`..runtime` runs it in a process of its own while the numpy pipeline serves
(helper processes that compiled kernels beside it once saved a third of the wait, when the first
scan waited for it).
"""

import glob
import math
import os
import time

import numpy as np

from ._jit import cache_folder, use_disk_cache
from .pipeline import _features_of_scan, extract_features


def warm_up() -> float:
    """
    Compile the pipeline for this machine, or load it from the on-disk cache.

    The first scan would otherwise pay it: seconds on a machine that has never run it, a
    fraction of one from the cache.

    :return: how long it took, s
    """
    started = time.perf_counter()
    use_disk_cache()
    beams = 360
    angle_min, increment = -math.pi, 2.0 * math.pi / beams
    bearing = angle_min + increment * np.arange(beams)
    square_room = 2.0 / np.maximum(np.abs(np.cos(bearing)), np.abs(np.sin(bearing)))
    extract_features(square_room, angle_min, increment)
    return time.perf_counter() - started


def pipeline_is_cached() -> bool:
    """
    Return whether numba's cache holds the compiled pipeline, or cannot hold anything.

    Either way no compile of its own is needed: the pipeline loads, or nothing would be kept.
    Sets up the cache first (:func:`._jit.use_disk_cache`): stale kernels are not the pipeline.
    """
    use_disk_cache()
    folder = cache_folder()
    function = getattr(_features_of_scan, 'py_func', None)   # None: NUMBA_DISABLE_JIT is set
    if folder is None or function is None:
        return True
    name = f'{function.__module__.rsplit(".", 1)[-1]}.{function.__qualname__}'
    return bool(glob.glob(os.path.join(glob.escape(folder), f'{name}-*.nbi')))
