# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The front end: what a SLAM system takes from the features, as pure libraries (no ROS).

Odometry from the features (:mod:`.odometry`), the landmarks of a scan and their moves between
frames (:mod:`.frames`).
"""
