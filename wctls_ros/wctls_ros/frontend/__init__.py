# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""What a SLAM or navigation front end needs from the features: pure libraries, no ROS."""
