# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiled implementation of the feature pipeline: loops over each scan's returns, by numba.

Imports numba (and sets up its cache, :mod:`._jit`): only :mod:`wctls_ros.core.runtime`
imports it, once numba is known to be there and recent enough. The same steps, names and
results as :mod:`wctls_ros.core.numpy_core`, which the tests hold it to.
"""
