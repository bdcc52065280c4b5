# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiler of the core's loops: numba's ``njit``, with its on-disk cache in a writable place.

Every loop of the core is compiled once per machine and kept on disk, next to the source when
that is writable (a colcon install space), else in ``$XDG_CACHE_HOME/wctls_ros``
(``~/.cache/wctls_ros``; an apt install under /opt is read-only). ``NUMBA_CACHE_DIR`` set by the
user wins over both. numba checks a cached function against the time stamp of its own file only,
not of the functions it calls from other files: after an upgrade that changed ``_order.py`` alone,
``pipeline.py``'s cached code would still hold the old sort. So the cache is tied to a fingerprint
of every source file of the core: when that changes, the core's cached functions are deleted before
any is loaded. None of this happens at import: importing the core changes neither the process's
environment nor numba's configuration nor any file. numba fixes a function's cache folder when
its caching is switched on, so the kernels are made without a cache, and :func:`use_disk_cache`
(called by the pipeline's entry points, :mod:`.precompile` and so :mod:`..runtime`, before they
compile anything) chooses the folder, sweeps stale kernels and switches the cache on for every
kernel, with numba's cache folder set for just that moment. A kernel called on its own before
that (a test of one step) compiles in memory.

The options are the same for every kernel: ``error_model='numpy'`` so that a division by zero
gives inf or NaN as in numpy (degenerate segments and corners are dropped later, not raised on),
and no fastmath, so that NaN compares and rounding are IEEE as in the numpy reference the tests
hold the kernels to. numba types each kernel from the arguments of its first call, lazily: the
pipeline's compiled function types all of its callees in one compile.

The first run on a machine compiles every kernel (the pipeline's 15-22 s of CPU on a 2-core EPYC
VM, the tracker's 8 s more, in a process of its own while the numpy pipeline serves:
:mod:`..runtime`), so the kernels avoid what costs compile time without need:
an array assigned to a slice (``a[:-1] = b[1:]``) makes numba compile its shape-mismatch message
(string formatting), 1.7 s for the one such line the core had; the core's kernels write those as
loops. And numba builds each compiled function's machine code with its callees linked in, so a step
that only calls others (the pipeline's ``_fit_walls`` and ``_corners``) has the code of its whole
subtree built once more: such thin steps are inlined into their caller (:func:`jit_inline`), about
1.5 s less. Inlining a step with much code of its own costs more than it saves (one run each,
against 20.5 s: every kernel called at one place inlined 21.5 s, all of them 38 s).
"""

import contextlib
import glob
import hashlib
import os
import threading
from typing import Any, Callable, Iterator, List, Optional

import numba
from numba.core.caching import FunctionCache

_CACHE_VARIABLE = 'NUMBA_CACHE_DIR'
_HERE = os.path.dirname(os.path.abspath(__file__))
# Kernels use constants and records of the shared modules too: every core source counts...
_CORE_SOURCES = os.path.join(os.path.dirname(_HERE), '**', '*.py')
# ... but the one that chooses which implementation runs and the numpy twin: no kernel reads
# them (the shared rule constants are in ..rules), so editing them recompiles nothing.
_NOT_READ_BY_KERNELS = (os.path.join(os.path.dirname(_HERE), 'runtime.py'),
                        os.path.join(os.path.dirname(_HERE), 'numpy_core', ''))
_FINGERPRINT_FILE = 'wctls_ros_core.fingerprint'
# numba makes its configuration's attributes when it reads its environment, so no type checker
# knows them.
_NUMBA_CONFIG: Any = numba.config

# Every kernel of the core, in the order of definition.
_kernels: List[Callable] = []
_cache_on = False
# The runtime's thread may set the cache up while the node's thread asks whether it is there.
_setting_up = threading.Lock()


def _user_cache_dir() -> str:
    """Return $XDG_CACHE_HOME/wctls_ros (XDG's default ~/.cache when unset)."""
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return os.path.join(base, 'wctls_ros')


def _chosen_cache_dir() -> Optional[str]:
    """Return the folder numba is to cache in: the user's, ours, or None for next to the source."""
    if _CACHE_VARIABLE in os.environ:
        return os.environ[_CACHE_VARIABLE]
    return None if os.access(_HERE, os.W_OK) else _user_cache_dir()


@contextlib.contextmanager
def _numba_caching_in_our_folder() -> Iterator[None]:
    """Set numba's cache folder to the core's choice while the block runs, then restore it."""
    chosen, before = _chosen_cache_dir(), _NUMBA_CONFIG.CACHE_DIR
    if chosen is not None:
        _NUMBA_CONFIG.CACHE_DIR = chosen
    try:
        yield
    finally:
        _NUMBA_CONFIG.CACHE_DIR = before


def _located_here():
    """Stand for every function of the core when asking numba where their cache is."""


def _fingerprint() -> str:
    """Return a digest of numba's version and every source file of the core kernels read."""
    digest = hashlib.sha256(numba.__version__.encode())
    for path in sorted(glob.glob(_CORE_SOURCES, recursive=True)):
        if path.startswith(_NOT_READ_BY_KERNELS):
            continue
        digest.update(os.path.relpath(path, _HERE).encode())
        with open(path, 'rb') as source:
            digest.update(source.read())
    return digest.hexdigest()


def cache_folder() -> Optional[str]:
    """Return the folder of the core's cached functions, or None when nothing can be cached."""
    try:
        with _numba_caching_in_our_folder():
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


def _cache(kernel) -> None:
    """Switch numba's on-disk cache on for a kernel, in the core's cache folder."""
    try:
        with _numba_caching_in_our_folder():
            kernel.enable_caching()
    except RuntimeError:          # no writable cache location: numba compiles in memory
        pass


def use_disk_cache() -> None:
    """
    Set up the kernels' on-disk cache: call it before the first compile (again: nothing).

    Chooses the cache folder, deletes the core's cached functions when a core source changed
    since they were made, and switches the cache on for every kernel (those defined later get
    it when they are made).
    """
    global _cache_on
    if _cache_on:
        return
    with _setting_up:
        if _cache_on:
            return
        _forget_stale_kernels()
        for kernel in _kernels:
            _cache(kernel)
        _cache_on = True


def _kernel(function, **options):
    """Make and register a kernel of the core (see :func:`jit`)."""
    kernel = numba.njit(error_model='numpy', nogil=True, **options)(function)
    _kernels.append(kernel)
    if _cache_on:
        _cache(kernel)
    return kernel


def jit(function: Callable):
    """
    Compile a function of the core with numba, cached on disk once :func:`use_disk_cache` ran.

    Lazily, as numba does: nothing compiles at import.

    :param function: a function written in numba's subset of Python and numpy (``@jit``)
    :return: the compiled dispatcher (callable from Python and from other compiled functions)
    """
    return _kernel(function)


def jit_inline(function):
    """
    Compile a step of the core that only calls other kernels, inlined where it is called.

    Numba inlines it into its caller's intermediate representation (``inline='always'``), so
    that it has no machine code of its own (see the module's docstring for why). Called from
    Python it compiles as :func:`jit` does.

    :param function: a function written in numba's subset of Python and numpy
    :return: the dispatcher
    """
    return _kernel(function, inline='always')
