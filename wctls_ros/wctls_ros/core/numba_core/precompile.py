# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The pipeline's, tracker's, dock's and odometry's kernels compiled before the first scan, or loaded.

From the cache the compiled pipeline loads in a fraction of a second. Without it (the first run
on a machine, or after an upgrade) numba compiles it: 16-22 s of CPU on a 2-core EPYC VM, and
the tracker's kernels 8 s more (21.6 s against 29.7 s measured one after the other), the
dock's about 10 s more (at load 8), the odometry's about 15 s more (at load 2.5). Nobody waits
for that: :mod:`..runtime` runs it in a process of its own while the numpy pipeline serves
(helper processes that compiled kernels beside it once saved a third of the wait, when the
first scan waited for it).
"""

import glob
import math
import os
import time

import numpy as np

from . import dock, odometry, tracking
from ._jit import cache_folder, use_disk_cache
from .pipeline import _features_of_scan, extract_features
from ..records import TrackRules

# The compiled functions that Python calls, each compiled once for the types it is called with.
_ENTRY_POINTS = (_features_of_scan, tracking.update_tracks, dock.fit_returns,
                 dock.corner_starts, dock.segment_pair_starts, dock.segment_starts,
                 odometry.hypotheses, odometry.search, odometry.fit)


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
    _track_once(square_room, angle_min, increment)
    _dock_once(square_room, angle_min, increment)
    _odometry_once()
    return time.perf_counter() - started


def _track_once(ranges_m: np.ndarray, angle_min_rad: float, angle_increment_rad: float) -> None:
    """
    Compile the tracker's kernels: one scan of a corner and a line against a track of each.

    With the argument types :class:`wctls_ros.frontend.tracking.Tracker` calls them with
    (corners and lines share them: one compile).
    """
    rules = TrackRules(0.95, 3, 1, 3, 50, 200, 0.2)
    gates = np.array([math.nan, 9.21, 13.28])
    for dims, value in ((3, np.array([[1.0, 1.0, 0.5]])), (2, np.array([[0.5, 2.0]]))):
        cov = np.tile(1e-4 * np.eye(dims), (1, 1, 1))
        ends = np.array([[[1.0, 1.0], [1.0, 1.0]]]) if dims == 3 else np.array(
            [[[2.0, -1.0], [2.0, 1.0]]])
        tracking.update_tracks(
            dims == 2, value, cov, ends, value.copy(), cov.copy(), np.zeros_like(cov),
            ends.copy(), np.zeros(1, np.int8), np.ones(1, np.int64), np.zeros(1, np.int64),
            np.zeros(1, np.int64), np.zeros(3), 1e-6 * np.eye(3), gates, rules, 1, True,
            ranges_m, angle_min_rad, angle_increment_rad, 10.0)


def _dock_once(ranges_m: np.ndarray, angle_min_rad: float, angle_increment_rad: float) -> None:
    """
    Compile the dock's kernels: the starts of a corner, two segments and one, the fit.

    With the argument types :func:`wctls_ros.frontend.dock.find_docks` calls them with.
    """
    shape = (0.3, 0.3, 2.1, 0.03, 0.17)
    segments = (np.array([0.5, -0.5]), np.array([1.5, 1.5]), np.tile(1e-4 * np.eye(2), (2, 1, 1)),
                np.array([[1.8, 0.0, 1.7, 0.2], [1.8, 0.0, 1.7, -0.2]]), np.zeros(1, np.int64),
                np.ones(1, np.int64))
    dock.corner_starts(*segments, np.array([2.1]), np.array([[1.8, 0.0]]), np.array([0.0]),
                       shape)
    dock.segment_pair_starts(*segments, shape, True)
    dock.segment_starts(segments[3], np.array([40, 40]), ranges_m, angle_min_rad,
                        angle_increment_rad, True, (0.0, math.inf), (0.01, 0.001, 0.0, 0.0, 0.0),
                        shape)
    dock.fit_returns(ranges_m, angle_min_rad, angle_increment_rad, True, (0.0, math.inf),
                     (0.01, 0.001, 0.0, 0.0, 0.0), True, (1.9, 1.9, 0.785), shape)


def _odometry_once() -> None:
    """
    Compile the odometry's kernels: hypotheses, search and fit, two corners and lines a side.

    With the argument types :func:`wctls_ros.frontend.odometry.estimate_step` calls them with.
    """
    corners, corner_cov = np.array([[2.0, 1.0], [2.0, -1.0]]), np.tile(1e-4 * np.eye(2), (2, 1, 1))
    lines, line_cov = np.array([[0.0, 2.0], [1.5, 1.0]]), np.tile(1e-4 * np.eye(2), (2, 1, 1))
    ends = np.array([[[2.0, -1.0], [2.0, 1.0]], [[-1.0, 1.0], [1.0, 1.0]]])
    scan = (corners, corner_cov, lines, line_cov, ends)
    steps, information = odometry.hypotheses(*scan[:4], *scan[:4]), np.eye(3)
    step, corner_pairs, line_pairs = odometry.search(*scan, *scan, steps, np.zeros(len(steps)),
                                                     np.zeros(3), information, False, 2.0, 4)
    odometry.fit(*scan[:4], *scan[:4], corner_pairs, line_pairs, step, np.zeros(3), information,
                 True)


def pipeline_is_cached() -> bool:
    """
    Return whether numba's cache holds the compiled pipeline, or cannot hold anything.

    Either way no compile of its own is needed: the pipeline (the tracker's kernels with it)
    loads, or nothing would be kept. Sets up the cache first (:func:`._jit.use_disk_cache`):
    stale kernels are not the pipeline.
    """
    use_disk_cache()
    folder = cache_folder()
    if folder is None:
        return True
    for entry in _ENTRY_POINTS:
        function = getattr(entry, 'py_func', None)   # None: NUMBA_DISABLE_JIT is set
        if function is None:
            return True
        name = f'{function.__module__.rsplit(".", 1)[-1]}.{function.__qualname__}'
        if not glob.glob(os.path.join(glob.escape(folder), f'{name}-*.nbi')):
            return False
    return True
