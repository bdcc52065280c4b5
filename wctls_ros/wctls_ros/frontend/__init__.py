# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The front end: pure libraries that turn the core's features into what a SLAM back end needs.

Odometry from the features (:mod:`.odometry`), the landmarks of a scan and their moves between
frames (:mod:`.frames`), landmark tracks with persistent ids (:mod:`.tracking`), the dock
detector (:mod:`.dock`). Like the core they import no rclpy and no messages; the nodes,
``process_bag`` and ``score`` call them.
"""
