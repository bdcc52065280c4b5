# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
SLAMTEC RPLIDAR S1 support: a pure byte-protocol codec, transports, a driver and an emulator.

``protocol`` (bytes in, values out), ``turns`` and ``laserscan`` are pure and numpy only;
``transport`` and ``driver`` do the I/O; ``rplidar_node`` is the ROS 2 node; ``emulator`` is an
emulated S1 (device, server, child-process harness) that :mod:`wctls_ros.s1_emulator` runs on a
simulated scene.
"""
