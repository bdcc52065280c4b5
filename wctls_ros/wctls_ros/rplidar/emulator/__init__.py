# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
An emulated RPLIDAR S1, in three parts; the ``s1_emulator`` executable puts them together.

``device`` is the S1 itself (pure: requests in, answers and the timed scan stream out, from any
scene that gives a distance per raw angle), ``server`` serves devices on a pseudo-terminal and
TCP and takes control commands, and ``process`` runs ``s1_emulator`` in a child process for tests
and benchmarks. The simulated floor plans are injected by :mod:`wctls_ros.s1_emulator`, so this
package depends on the protocol alone.
"""
