# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiler of the core's loops: numba's ``njit``, with its on-disk cache in a writable place.

Every loop of the core is compiled once per machine and kept on disk (``cache=True``), next to
the source when that is writable (a colcon install space), else in
``$XDG_CACHE_HOME/wctls_ros`` (``~/.cache/wctls_ros``; an apt install under /opt is read-only).
``NUMBA_CACHE_DIR`` set by the user wins over both. The options are the same for every kernel:
``error_model='numpy'`` so that a division by zero gives inf or NaN as in numpy (degenerate
segments and corners are dropped later, not raised on), and no fastmath, so that NaN compares
and rounding are IEEE as in the numpy reference the tests hold the kernels to.
"""

import os

_CACHE_VARIABLE = 'NUMBA_CACHE_DIR'


def _user_cache_dir() -> str:
    """Return $XDG_CACHE_HOME/wctls_ros (XDG's default ~/.cache when unset)."""
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return os.path.join(base, 'wctls_ros')


if _CACHE_VARIABLE not in os.environ and not os.access(os.path.dirname(__file__), os.W_OK):
    os.environ[_CACHE_VARIABLE] = _user_cache_dir()

import numba  # noqa: E402  (numba reads NUMBA_CACHE_DIR when imported)

# A user's script may have imported numba before us: it then re-reads its environment.
numba.config.reload_config()


def jit(function):
    """
    Compile a function of the core with numba, cached on disk.

    :param function: a function written in numba's subset of Python and numpy
    :return: the compiled dispatcher (callable from Python and from other compiled functions)
    """
    return numba.njit(cache=True, error_model='numpy', nogil=True)(function)
