"""Bags without a ROS install: read LaserScans (ROS 1 and 2), write mcap bags of our outputs."""

from .bag_io import (BagError, BagWriter, choose_scan_topic, LASER_SCAN, read_scans,
                     scan_topics, ScanRecord, typestore)

__all__ = ['BagError', 'BagWriter', 'LASER_SCAN', 'ScanRecord', 'choose_scan_topic',
           'read_scans', 'scan_topics', 'typestore']
