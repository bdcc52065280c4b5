# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The wctls_ros lab: what the team and reviewers run, not what a robot needs.

``simulation`` (an S1-like scan simulator over 2D floor plans), ``evaluation`` (the paper's
analysis, score, calibrate and their command lines), ``simulated_rplidar`` (the driver's
emulator seeing a floor plan), ``demo`` (emulator, driver and feature node live) and
``plotting``. matplotlib, tqdm and rosbags live here, never on a node's path.
"""
