# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""process_bag --dock: the dock's poses in the output bag and in dock.csv."""

import csv
import math

import pytest

pytest.importorskip('rclpy')

from scan_bags import real_bag  # noqa: E402
from test_bag_process import output_messages, read_output, run  # noqa: E402
from test_feature_node_dock import dock_scans, PLAN, POSE, SHAPE  # noqa: E402
from test_frontend_dock import true_dock  # noqa: E402
from wctls_ros.bags import BagWriter  # noqa: E402
from wctls_ros.bags.process_bag import DOCK_CSV_COLUMNS  # noqa: E402
from wctls_ros.frontend.dock import wrap_angle  # noqa: E402

POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'
WITH_COVARIANCE = 'geometry_msgs/msg/PoseWithCovarianceStamped'


def write_dock_bag(path, count):
    """Write ``count`` S1-like scans of the dock 1 m away; return their stamps as text."""
    stamps = []
    with BagWriter(path) as bag:
        for index, scan in enumerate(dock_scans(count)):
            stamp = scan.header.stamp
            bag.write('/scan', stamp.sec * 10 ** 9 + stamp.nanosec, scan)
            stamps.append(f'{stamp.sec}.{stamp.nanosec:09d}')
    return stamps


def test_the_dock_is_written_to_the_bag_and_dock_csv(tmp_path, capsys):
    stamps = write_dock_bag(tmp_path / 'bag', 12)
    status, out, err = run([tmp_path / 'bag', '-o', tmp_path / 'out', '--dock', '--sensor',
                            'rplidar_s1', '--jobs', '1'], capsys)
    assert status == 0, err
    with open(tmp_path / 'out' / 'dock.csv', newline='') as table:
        rows = list(csv.DictReader(table))
    assert f'dock: {len(rows)} poses, in dock.csv' in out
    types, counts, _ = read_output(tmp_path / 'out')
    assert types['/detected_dock_pose'] == POSE_STAMPED
    assert types['/detected_dock_pose_with_covariance'] == WITH_COVARIANCE
    # Confirmed after three agreeing scans; the S1-like scans miss a few.
    assert 7 <= len(rows) <= 10
    assert counts['/detected_dock_pose'] == counts['/detected_dock_pose_with_covariance'] == len(
        rows)
    assert tuple(rows[0]) == DOCK_CSV_COLUMNS
    truth = true_dock(PLAN, POSE, SHAPE)
    poses = [m for topic, m in output_messages(tmp_path / 'out')
             if topic == '/detected_dock_pose_with_covariance']
    for row, message in zip(rows, poses):
        assert row['stamp_s'] in stamps
        assert math.hypot(float(row['x_m']) - truth[0], float(row['y_m']) - truth[1]) < 0.03
        assert abs(wrap_angle(float(row['yaw_rad']) - truth[2])) < math.radians(4)
        assert float(row['cov_xx']) > 0 and float(row['cov_yawyaw']) > 0
        assert message.pose.covariance[0] == pytest.approx(float(row['cov_xx']))
        assert message.pose.covariance[35] == pytest.approx(float(row['cov_yawyaw']))
        assert message.pose.covariance[5] == pytest.approx(float(row['cov_xyaw']))


def test_workers_write_the_same_docks_as_one_process(tmp_path, capsys):
    write_dock_bag(tmp_path / 'bag', 8)
    tables = []
    for jobs in ('1', '2'):
        output = tmp_path / f'out{jobs}'
        status, _, err = run([tmp_path / 'bag', '-o', output, '--dock', '--sensor',
                              'rplidar_s1', '--jobs', jobs], capsys)
        assert status == 0, err
        tables.append((output / 'dock.csv').read_text())
    assert tables[0] == tables[1] and tables[0].count('\n') > 1


def test_without_dock_there_is_no_dock_output(tmp_path, capsys):
    write_dock_bag(tmp_path / 'bag', 4)
    status, _, err = run([tmp_path / 'bag', '-o', tmp_path / 'out'], capsys)
    assert status == 0, err
    assert not (tmp_path / 'out' / 'dock.csv').exists()
    assert '/detected_dock_pose' not in read_output(tmp_path / 'out')[0]


def test_a_real_recording_without_a_dock_gives_an_empty_dock_table(tmp_path, capsys):
    status, out, err = run([real_bag('sick_lms111_static'), '-o', tmp_path / 'out', '--dock',
                            '--sensor', 'sick_lms1xx'], capsys)
    assert status == 0, err
    assert 'dock: 0 poses' in out
    assert (tmp_path / 'out' / 'dock.csv').read_text().splitlines() == [
        ','.join(DOCK_CSV_COLUMNS)]


def test_a_dock_description_that_cannot_be_is_one_line_and_exit_2(tmp_path, capsys):
    write_dock_bag(tmp_path / 'bag', 2)
    config = tmp_path / 'dock.yaml'
    config.write_text('feature_node:\n  ros__parameters:\n    dock_right_face_m: 0.05\n')
    status, _, err = run([tmp_path / 'bag', '-o', tmp_path / 'out', '--dock', '-c', config],
                         capsys)
    assert status == 2 and 'shorter than the faces' in err and len(err.splitlines()) == 1
    assert not (tmp_path / 'out').exists()
