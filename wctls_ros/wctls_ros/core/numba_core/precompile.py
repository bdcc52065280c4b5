# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The pipeline compiled before the first scan, with helper processes when the cache lacks it.

From numba's on-disk cache the compiled pipeline loads in a fraction of a second. Without it (the
first run on a machine, or after an upgrade) numba compiles it: 16-20 s on a 2-core EPYC VM,
numba's typing and lowering and LLVM, one function at a time under a lock that lets no second
thread in. The kernels are separate units in the cache, though, and numba looks there before it
compiles one: so helper processes compile kernels into the cache while this process compiles the
pipeline, and this process loads theirs when it comes to them. It walks the pipeline from its
first step; the helpers take the kernels from the last step back
(:data:`.pipeline.PIPELINE_KERNELS` backwards, each with the argument types declared at its
definition: :func:`.pipeline.kernels_last_first`; each helper every k-th), so that they meet in
the middle and little is compiled twice. The pipeline function itself, which has every kernel
linked into its module, is compiled here in any case (4-5 s of the 20). When this process is
done, helpers still running are only compiling what it has already saved, and are stopped.
"""

import glob
import math
import os
import subprocess
import sys
import time
from typing import List, Optional

import numpy as np

from ._jit import cache_folder, use_disk_cache
from .pipeline import _features_of_scan, extract_features, kernels_last_first

# With three, the kernels' 11-12 s of a 2-core VM come to about 3 s per process, less than the
# pipeline function's own part that no helper can take: more would mostly add start-up.
MAX_HELPERS = 3


def warm_up(helpers: Optional[int] = None) -> float:
    """
    Compile the pipeline for this machine, or load it from the on-disk cache.

    The first scan would otherwise pay it: seconds on a machine that has never run it, a
    fraction of one from the cache. Nodes and tools call it before their first scan.

    :param helpers: how many helper processes may compile kernels when the cache lacks the
        pipeline; default :func:`default_helpers`
    :return: how long it took, s
    """
    started = time.perf_counter()
    use_disk_cache()
    count = default_helpers() if helpers is None else helpers
    running = start_helpers(count) if count > 0 and not pipeline_is_cached() else []
    try:
        beams = 360
        angle_min, increment = -math.pi, 2.0 * math.pi / beams
        bearing = angle_min + increment * np.arange(beams)
        square_room = 2.0 / np.maximum(np.abs(np.cos(bearing)), np.abs(np.sin(bearing)))
        extract_features(square_room, angle_min, increment)
    finally:
        for helper in running:
            helper.kill()
        for helper in running:
            helper.wait()
    return time.perf_counter() - started


def default_helpers() -> int:
    """Return one helper per further CPU this process may run on, at most MAX_HELPERS."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:        # not on Linux
        cpus = os.cpu_count() or 1
    return max(0, min(cpus - 1, MAX_HELPERS))


def pipeline_is_cached() -> bool:
    """
    Return whether numba's cache holds the compiled pipeline, or cannot hold anything.

    Either way helpers would not help: the pipeline loads, or nothing they compile is kept.
    Sets up the cache first (:func:`._jit.use_disk_cache`): stale kernels are not the pipeline.
    """
    use_disk_cache()
    folder = cache_folder()
    function = getattr(_features_of_scan, 'py_func', None)   # None: NUMBA_DISABLE_JIT is set
    if folder is None or function is None:
        return True
    name = f'{function.__module__.rsplit(".", 1)[-1]}.{function.__qualname__}'
    return bool(glob.glob(os.path.join(glob.escape(folder), f'{name}-*.nbi')))


def start_helpers(count: int) -> List[subprocess.Popen]:
    """
    Start helper processes that compile the pipeline's kernels into the cache.

    They run this interpreter on this process's import path, with no input or output (a helper
    that fails only leaves more for this process to compile).

    :param count: how many
    :return: the processes
    """
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(path for path in sys.path if path))
    helpers = []
    for share in range(count):
        try:
            helpers.append(subprocess.Popen(
                [sys.executable, '-c', f'from {__name__} import compile_share; '
                                       f'compile_share({share}, {count}, {os.getpid()})'],
                env=environment, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL))
        except OSError:           # no interpreter to start (an embedded Python): compile alone
            break
    return helpers


def compile_share(share: int, shares: int, parent_pid: int) -> None:
    """
    Compile every shares-th kernel of the pipeline from its last step back, from the share-th on.

    What a helper runs. A kernel already in the cache is loaded instead of compiled. A helper
    whose parent has died stops at the next kernel.

    :param share: which share, 0 <= share < shares
    :param shares: how many helpers share the kernels
    :param parent_pid: the process that started the helper
    """
    use_disk_cache()
    for kernel, argument_types in kernels_last_first()[share::shares]:
        if os.getppid() != parent_pid:
            return
        kernel.compile(argument_types)
