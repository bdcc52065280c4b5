# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The front end: pure libraries that turn the core's features into what a SLAM back end needs.

Like the core they import no rclpy and no messages; the nodes, ``process_bag`` and ``score``
call them.
"""
