# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Small bags written by the tests: simulated room scans, damaged and foreign bags."""

import shutil

from conftest import REAL_DATA
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from scans import room_scan_message
from wctls_ros.bags import BagWriter, typestore

START_NS = 1_700_000_000_000_000_000
PERIOD_NS = 100_000_000
# Header stamps lag the log times (as a driver's do), so tests can tell them apart.
STAMP_LAG_NS = 3_000_000
# The recordings in data/: (bag path, scans).
REAL_BAGS = [
    ('urg04lx_office', 360),
    ('sick_lms111_static', 175),
    ('sick_lms1xx_static', 89),
    ('ros1/urg04lx_office.bag', 360),
    ('ros1/sick_lms1xx_static.bag', 89),
]


def simulated_bag(folder, plan, scans, seed, sensor):
    """
    Write a bag of ``simulate`` (with its truth.yaml) into ``folder``, as a user would.

    :return: the bag's path
    """
    from wctls_lab.evaluation.simulate_cli import main
    path = folder / plan
    assert main([plan, str(path), '--scans', str(scans), '--seed', str(seed),
                 '--sensor', sensor]) == 0
    return path


def scan_at(index):
    """Return the simulated scan number ``index`` and its log time, ns."""
    log_ns = START_NS + index * PERIOD_NS
    scan = room_scan_message(seed=index, stamp=divmod(log_ns - STAMP_LAG_NS, 1_000_000_000))
    return scan, log_ns


def write_scan_bag(path, count=8, storage='mcap', topic='/scan'):
    """
    Write ``count`` simulated room scans 0.1 s apart.

    :return: the header stamps written, as (sec, nanosec)
    """
    stamps = []
    with BagWriter(path, storage=storage) as bag:
        for index in range(count):
            scan, log_ns = scan_at(index)
            bag.write(topic, log_ns, scan)
            stamps.append((scan.header.stamp.sec, scan.header.stamp.nanosec))
    return stamps


def write_wide_invalid_bag(path, count, beams=20000):
    """Write scans with many beams, all invalid (NaN): big messages that are cheap to process."""
    from sensor_msgs.msg import LaserScan
    scan = LaserScan(angle_min=-3.0, angle_increment=6.0 / beams,
                     angle_max=-3.0 + (beams - 1) * 6.0 / beams, range_min=0.1, range_max=30.0,
                     ranges=np.full(beams, np.nan, np.float32))
    scan.header.frame_id = 'laser'
    with BagWriter(path) as bag:
        for index in range(count):
            scan.header.stamp.sec = index
            bag.write('/scan', START_NS + index * PERIOD_NS, scan)


def write_bag_with_bad_message(path, count=6, bad_index=3):
    """Write a scan bag whose message number ``bad_index`` is not a LaserScan's bytes."""
    from rclpy.serialization import serialize_message
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        connection = bag.add_connection('/scan', 'sensor_msgs/msg/LaserScan',
                                        typestore=typestore())
        for index in range(count):
            scan, log_ns = scan_at(index)
            data = b'\x00\x01\x00\x00\xff\xff' if index == bad_index else serialize_message(scan)
            bag.write(connection, log_ns, data)


def write_empty_scan_bag(path):
    """Write a bag with a LaserScan topic that holds no messages (and a String topic that does)."""
    store = typestore()
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        bag.add_connection('/scan', 'sensor_msgs/msg/LaserScan', typestore=store)
        chatter = bag.add_connection('/chatter', 'std_msgs/msg/String', typestore=store)
        text = store.types['std_msgs/msg/String'](data='the scan topic stays empty')
        bag.write(chatter, START_NS, store.serialize_cdr(text, 'std_msgs/msg/String'))


def write_string_bag(path):
    """Write a bag with only a std_msgs/String topic."""
    from std_msgs.msg import String
    with BagWriter(path) as bag:
        for index in range(3):
            bag.write('/chatter', START_NS + index * PERIOD_NS, String(data=f'hello {index}'))


def truncated_copy(source_bag, target, fraction=0.6):
    """Copy a ROS 2 bag folder (or a ROS 1 .bag file) with its data file cut short."""
    if source_bag.is_dir():
        shutil.copytree(source_bag, target)
        data = next(p for p in target.iterdir() if p.suffix in ('.mcap', '.db3'))
    else:
        shutil.copy(source_bag, target)
        data = target
    content = data.read_bytes()
    data.write_bytes(content[:int(len(content) * fraction)])
    return target


def real_bag(name):
    """Return the path of a recording in data/ (fails when it is missing: nothing skips)."""
    path = REAL_DATA / name
    assert path.exists(), f'{path} is missing from the repository'
    return path


def real_scans_slice(name, first, stop, target):
    """
    Copy the LaserScans first to stop - 1 of a recording in data/ into a new mcap bag.

    The messages are copied as they were recorded (their bytes and log times): a piece of a
    real recording, e.g. the part of ``urg04lx_office`` where the sensor is carried.

    :return: the new bag's path
    """
    from rosbags.highlevel import AnyReader
    with AnyReader([real_bag(name)], default_typestore=typestore()) as reader, \
            Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        scans = [c for c in reader.connections if c.msgtype == 'sensor_msgs/msg/LaserScan']
        connection = bag.add_connection('/scan', 'sensor_msgs/msg/LaserScan',
                                        typestore=typestore())
        for index, (_, log_ns, raw) in enumerate(reader.messages(connections=scans)):
            if first <= index < stop:
                bag.write(connection, log_ns, raw)
    return target
