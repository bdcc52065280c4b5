# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Line segments and corners with calibrated covariances from 2D LiDAR scans."""
