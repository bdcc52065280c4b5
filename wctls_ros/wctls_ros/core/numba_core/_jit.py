# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiler of the core's loops: numba's ``njit``, with its on-disk cache in a writable place.

Every loop of the core is compiled once per machine and kept on disk (``cache=True``), next to the
source when that is writable (a colcon install space), else in ``$XDG_CACHE_HOME/wctls_ros``
(``~/.cache/wctls_ros``; an apt install under /opt is read-only). ``NUMBA_CACHE_DIR`` set by the
user wins over both. numba checks a cached function against the time stamp of its own file only,
not of the functions it calls from other files: after an upgrade that changed ``_order.py`` alone,
``pipeline.py``'s cached code would still hold the old sort. So the cache is tied to a fingerprint
of every source file of the core: when that changes, the core's cached functions are deleted before
any is loaded. The options are the same for every kernel: ``error_model='numpy'`` so that a
division by zero gives inf or NaN as in numpy (degenerate segments and corners are dropped later,
not raised on), and no fastmath, so that NaN compares and rounding are IEEE as in the numpy
reference the tests hold the kernels to.

The first run on a machine compiles every kernel (15-20 s of CPU on a 2-core EPYC VM; helper
processes share it, :mod:`.precompile`), so the kernels avoid what costs compile time without need:
an array assigned to a slice (``a[:-1] = b[1:]``) makes numba compile its shape-mismatch message
(string formatting), 1.7 s for the one such line the core had; the core's kernels write those as
loops. And numba builds each compiled function's machine code with its callees linked in, so a step
that only calls others (the pipeline's ``_fit_walls`` and ``_corners``) has the code of its whole
subtree built once more: such thin steps are inlined into their caller (:func:`jit_inline`), about
1.5 s less. Inlining a step with much code of its own costs more than it saves (one run each,
against 20.5 s: every kernel called at one place inlined 21.5 s, all of them 38 s).
"""

import glob
import hashlib
import os
from typing import Optional

_CACHE_VARIABLE = 'NUMBA_CACHE_DIR'
_HERE = os.path.dirname(os.path.abspath(__file__))
# Kernels use constants of the shared modules and of the numpy core too: every core source counts.
_CORE_SOURCES = os.path.join(os.path.dirname(_HERE), '**', '*.py')
# ... but the one that chooses which implementation runs: no kernel reads it.
_NOT_READ_BY_KERNELS = os.path.join(os.path.dirname(_HERE), 'runtime.py')
_FINGERPRINT_FILE = 'wctls_ros_core.fingerprint'


def _user_cache_dir() -> str:
    """Return $XDG_CACHE_HOME/wctls_ros (XDG's default ~/.cache when unset)."""
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return os.path.join(base, 'wctls_ros')


if _CACHE_VARIABLE not in os.environ and not os.access(os.path.dirname(__file__), os.W_OK):
    os.environ[_CACHE_VARIABLE] = _user_cache_dir()

import numba  # noqa: E402  (numba reads NUMBA_CACHE_DIR when imported)
from numba.core.caching import FunctionCache  # noqa: E402

# A user's script may have imported numba before us: it then re-reads its environment.
numba.config.reload_config()


def _located_here():
    """Stand for every function of the core when asking numba where their cache is."""


def _fingerprint() -> str:
    """Return a digest of numba's version and every source file of the core kernels read."""
    digest = hashlib.sha256(numba.__version__.encode())
    for path in sorted(glob.glob(_CORE_SOURCES, recursive=True)):
        if path == _NOT_READ_BY_KERNELS:
            continue
        digest.update(os.path.relpath(path, _HERE).encode())
        with open(path, 'rb') as source:
            digest.update(source.read())
    return digest.hexdigest()


def cache_folder() -> Optional[str]:
    """Return the folder of the core's cached functions, or None when nothing can be cached."""
    try:
        return FunctionCache(_located_here).cache_path
    except RuntimeError:          # no writable cache location: numba compiles in memory
        return None


def _forget_stale_kernels() -> None:
    """Delete the core's cached functions if any core source changed since they were made."""
    folder = cache_folder()
    if folder is None:
        return
    stamp, current = os.path.join(folder, _FINGERPRINT_FILE), _fingerprint()
    try:
        with open(stamp) as recorded:
            if recorded.read() == current:
                return
    except OSError:
        pass
    modules = {os.path.splitext(os.path.basename(path))[0]
               for path in glob.glob(os.path.join(_HERE, '*.py'))}
    for cached in glob.glob(os.path.join(folder, '*.nb[ic]')):
        if os.path.basename(cached).split('.', 1)[0] in modules:
            try:
                os.remove(cached)
            except OSError:       # another process got there first
                pass
    try:
        os.makedirs(folder, exist_ok=True)
        with open(stamp, 'w') as recorded:
            recorded.write(current)
    except OSError:               # unwritable: numba will not cache there either
        pass


_forget_stale_kernels()


def jit(function):
    """
    Compile a function of the core with numba, cached on disk.

    :param function: a function written in numba's subset of Python and numpy
    :return: the compiled dispatcher (callable from Python and from other compiled functions)
    """
    return numba.njit(cache=True, error_model='numpy', nogil=True)(function)


def jit_inline(function):
    """
    Compile a step of the core that only calls other kernels, inlined where it is called.

    Numba inlines it into its caller's intermediate representation (``inline='always'``), so
    that it has no machine code of its own (see the module's docstring for why). Called from
    Python it compiles as :func:`jit` does.

    :param function: a function written in numba's subset of Python and numpy
    :return: the dispatcher
    """
    return numba.njit(cache=True, error_model='numpy', nogil=True, inline='always')(function)
