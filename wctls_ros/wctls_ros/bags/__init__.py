# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Bags without a ROS install: read LaserScans (ROS 1 and 2), write mcap bags of our outputs."""

from .bag_io import (bag_info, BagError, BagInfo, BagWriter, choose_scan_topic, LASER_SCAN,
                     read_scans, scan_topics, ScanRecord, typestore)

__all__ = ['BagError', 'BagInfo', 'BagWriter', 'LASER_SCAN', 'ScanRecord', 'bag_info',
           'choose_scan_topic', 'read_scans', 'scan_topics', 'typestore']
