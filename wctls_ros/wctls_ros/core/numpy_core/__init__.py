# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The numpy implementation of the feature pipeline: batched array operations over a scan's segments.

It needs numpy alone, so it serves wherever numba is missing (an apt install of ROS 2 Jazzy on
Ubuntu 24.04 has none), too old, or still compiling (:mod:`wctls_ros.core.runtime`). The
compiled implementation (:mod:`wctls_ros.core.numba_core`) gives the same segments and corners
on every scan, values within 1e-9 relative; the tests run both side by side. Being the plainer
of the two, it is also where a rule is easiest to read against docs/derivation.md.
"""

from .pipeline import extract_features

__all__ = ['extract_features']
