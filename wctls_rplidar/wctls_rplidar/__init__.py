# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
SLAMTEC RPLIDAR A1-S3 for ROS 2: a pure byte-protocol codec, transports, a driver, an emulator.

``protocol`` (bytes in, values out), ``turns`` and ``laserscan`` are pure and numpy only;
``transport`` and ``driver`` do the I/O; ``rplidar_node`` is the ROS 2 lifecycle node and
``parameters`` its parameters; ``emulator`` is an emulated RPLIDAR of every model (device,
server, the built-in room) behind the ``rplidar_emulator`` executable.
"""
