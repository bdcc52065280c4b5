# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The numpy implementation of the core, kept as the tests' slow, obviously-correct reference.

Until the core was compiled (28c8ec9 is the last such tree) the production core was this
code: batched numpy over all segments of a scan.
The compiled core (``wctls_ros.core``, numba loops) must give the same segments and corners
on every scan, with values within 1e-9 relative; the equivalence tests run both side by side.
It shares the results' dataclasses and the configuration with the production core.
"""

from .pipeline import extract_features

__all__ = ['extract_features']
