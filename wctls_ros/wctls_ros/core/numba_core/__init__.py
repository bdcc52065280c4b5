# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiled implementation of the feature pipeline: loops over each scan's returns, by numba.

Its modules import numba and change nothing outside the package at import: whoever compiles
first sets up the on-disk cache (:func:`._jit.use_disk_cache`). Only
:mod:`wctls_ros.core.runtime` imports it, once numba is known to be there and recent enough. The
same steps, names and results as :mod:`wctls_ros.core.numpy_core`, which the tests hold it to.
"""
