# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Bag reading and writing with rosbags: ROS 1/2 input, clear errors, all-or-nothing output."""

import pytest

pytest.importorskip('rclpy')

from scan_bags import (real_bag, REAL_BAGS, START_NS, truncated_copy,  # noqa: E402
                       write_bag_with_bad_message, write_scan_bag, write_string_bag)
from std_msgs.msg import String  # noqa: E402
from wctls_ros.bags import (bag_info, BagError, BagWriter, choose_scan_topic,  # noqa: E402
                            read_scans)
from wctls_ros.conversions import laser_scan  # noqa: E402


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_written_scans_read_back_with_header_log_time_and_rclpy_conversion(tmp_path, storage):
    stamps = write_scan_bag(tmp_path / 'bag', count=4, storage=storage)
    info = bag_info(tmp_path / 'bag')
    assert info.topics == {'/scan': ('sensor_msgs/msg/LaserScan', 4)}
    assert info.start_ns == START_NS and info.end_ns == START_NS + 3 * 100_000_000
    records = list(read_scans(tmp_path / 'bag'))
    assert [r.timestamp_ns for r in records] == [START_NS + i * 100_000_000 for i in range(4)]
    message = laser_scan(records[1].scan)
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == stamps[1]
    assert message.header.frame_id == 'laser' and len(message.ranges) == 1080
    assert list(message.ranges) == pytest.approx(records[1].scan.ranges.tolist())
    later = list(read_scans(tmp_path / 'bag', start_ns=START_NS + 150_000_000))
    assert [r.timestamp_ns for r in later] == [r.timestamp_ns for r in records[2:]]


def test_a_bag_folder_without_metadata_opens_its_storage_file(tmp_path):
    write_scan_bag(tmp_path / 'bag', count=3)
    (tmp_path / 'bag' / 'metadata.yaml').unlink()
    assert len(list(read_scans(tmp_path / 'bag'))) == 3


@pytest.mark.parametrize('name,count', REAL_BAGS)
def test_real_bags_list_their_laserscan_topic(name, count):
    path = real_bag(name)
    topic = choose_scan_topic(path)
    assert bag_info(path).scan_topics() == {topic: count}


def test_errors_name_the_problem(tmp_path):
    write_string_bag(tmp_path / 'strings')
    write_scan_bag(tmp_path / 'scans', count=2)
    (tmp_path / 'garbage.mcap').write_bytes(b'\x89MCAP0\r\n' + bytes(range(256)) * 8)
    cases = [
        (tmp_path / 'missing', None, 'no bag at'),
        (tmp_path / 'garbage.mcap', None, 'corrupt, truncated'),
        (truncated_copy(tmp_path / 'scans', tmp_path / 'cut'), None, 'corrupt, truncated'),
        (tmp_path / 'strings', None, 'holds no sensor_msgs/msg/LaserScan messages '
                                     '(topics: /chatter (std_msgs/msg/String))'),
        (tmp_path / 'strings', '/chatter', 'carries std_msgs/msg/String'),
        (tmp_path / 'scans', '/front/scan', "no LaserScan topic '/front/scan'"),
    ]
    for path, topic, reason in cases:
        with pytest.raises(BagError, match=reason.replace('(', r'\(').replace(')', r'\)')):
            list(read_scans(path, topic))


def test_a_bad_message_midway_is_reported_with_how_far_reading_got(tmp_path):
    write_bag_with_bad_message(tmp_path / 'bag', count=6, bad_index=3)
    records = []
    with pytest.raises(BagError, match='damaged after 3 messages of /scan'):
        for record in read_scans(tmp_path / 'bag'):
            records.append(record)
    assert len(records) == 3


def test_writer_is_all_or_nothing_and_never_overwrites_by_accident(tmp_path):
    with pytest.raises(RuntimeError, match='boom'):
        with BagWriter(tmp_path / 'out') as bag:
            bag.write('/chatter', 1, String(data='a'))
            bag.sidecar('notes.txt').write_text('half')
            raise RuntimeError('boom')
    assert list(tmp_path.iterdir()) == []
    with BagWriter(tmp_path / 'out') as bag:
        bag.write('/chatter', 1, String(data='first'))
        bag.sidecar('notes.txt').write_text('first')
    with pytest.raises(BagError, match='exists'):
        BagWriter(tmp_path / 'out')
    with BagWriter(tmp_path / 'out', overwrite=True) as bag:
        bag.write('/chatter', 2, String(data='second'))
        bag.sidecar('notes.txt').write_text('second')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['out']
    assert (tmp_path / 'out' / 'notes.txt').read_text() == 'second'
    assert bag_info(tmp_path / 'out').topics == {'/chatter': ('std_msgs/msg/String', 1)}
    with pytest.raises(BagError, match='side file'):
        with BagWriter(tmp_path / 'other') as bag:
            bag.sidecar('../escape.txt')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['out']
