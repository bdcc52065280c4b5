# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""feature_node with the real rclpy: topics, headers, QoS, parameters, malformed scans."""

import math
import os
import pathlib
import shutil
import struct
import subprocess
import sys
from types import SimpleNamespace

from conftest import spin_until
import numpy as np
import pytest

pytest.importorskip('rclpy')

from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from scans import NODE_PARAMETERS, room_scan_message, room_truth  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402
from wctls_msgs.msg import CornerArray, LineSegmentArray  # noqa: E402
from wctls_ros.core import nees  # noqa: E402
from wctls_ros.feature_node import FeatureNode  # noqa: E402

# Runs nodes, emulators or signals against deadlines: make test runs it in its realtime group.
pytestmark = pytest.mark.realtime

PACKAGE = pathlib.Path(__file__).resolve().parents[1]


class Harness:
    """A feature node plus a peer node publishing scans and collecting the outputs."""

    def __init__(self, context, executor, parameters=NODE_PARAMETERS,
                 reliability=ReliabilityPolicy.RELIABLE):
        self.node = FeatureNode(
            context=context, use_global_arguments=False,
            parameter_overrides=[Parameter(k, value=v) for k, v in parameters.items()])
        self.peer = Node('peer', context=context)
        for node in (self.node, self.peer):
            executor.add_node(node)
        self.executor = executor
        self.scans = self.peer.create_publisher(
            LaserScan, 'scan', QoSProfile(depth=10, reliability=reliability))
        self.received = {'corners': [], 'lines': [], 'markers': []}
        for topic, kind in (('corners', CornerArray), ('lines', LineSegmentArray),
                            ('markers', MarkerArray)):
            self.peer.create_subscription(kind, topic, self.received[topic].append, 10)

    def wait_for_subscriber(self):
        assert spin_until(self.executor, lambda: self.scans.get_subscription_count() > 0)

    def exchange(self, scan, count=1):
        """Publish a scan and step until `count` CornerArrays in total have arrived."""
        self.wait_for_subscriber()
        self.scans.publish(scan)
        assert spin_until(self.executor, lambda: len(self.received['corners']) >= count
                          and len(self.received['lines']) >= count)
        return self.received['corners'][-1], self.received['lines'][-1]


def pose_covariance(corner):
    return np.array(corner.pose.covariance).reshape(6, 6)


def test_room_corners_arrive_with_header_covariance_and_indices(ros_context, executor):
    harness = Harness(ros_context, executor)
    scan = room_scan_message()
    corners, lines = harness.exchange(scan)
    assert corners.header == scan.header and lines.header == scan.header
    assert corners.method == lines.method == 'wctls'
    truth = room_truth()
    found = np.array([[c.pose.pose.position.x, c.pose.pose.position.y] for c in corners.corners])
    distance = np.hypot(*(found[None] - truth[:, None]).transpose(2, 0, 1))
    index = distance.argmin(axis=1)
    assert len(corners.corners) == len(truth) and sorted(index) == list(range(len(truth)))
    for corner, true_xy in zip([corners.corners[i] for i in index], truth):
        full = pose_covariance(corner)
        np.testing.assert_array_equal(full, full.T)
        xy_yaw = full[np.ix_([0, 1, 5], [0, 1, 5])]
        assert np.all(np.linalg.eigvalsh(xy_yaw) > 0)
        assert np.count_nonzero(full) == np.count_nonzero(xy_yaw) == 9
        error = np.array([corner.pose.pose.position.x, corner.pose.pose.position.y]) - true_xy
        assert nees(error, xy_yaw[:2, :2]) < 11.8                       # within 3 sigma
        assert corner.pose.pose.position.z == 0.0
        q = corner.pose.pose.orientation
        assert q.x == q.y == 0.0 and q.z ** 2 + q.w ** 2 == pytest.approx(1.0)
        assert corner.first_line < len(lines.segments)
        assert corner.second_line < len(lines.segments)
        assert 0.0 < corner.opening_angle < 2 * math.pi
        # What a front end gates on repeats the walls' own entries; a clean room corner's
        # walls are seen to their ends and fit within the noise.
        first, second = lines.segments[corner.first_line], lines.segments[corner.second_line]
        assert (corner.first_line_points, corner.second_line_points) == (
            first.num_points, second.num_points)
        assert (corner.first_line_chi2_dof, corner.second_line_chi2_dof) == (
            first.residual_chi2_dof, second.residual_chi2_dof)
        assert 0.0 < corner.first_line_chi2_dof < 3.0 and 0.0 < corner.second_line_chi2_dof < 3.0
        assert corner.first_end_seen and corner.second_end_seen
    for segment in lines.segments:
        assert segment.radius >= 0.0 and segment.num_points >= 8
        assert 0 <= segment.first_index < len(scan.ranges)
        cov = np.array(segment.covariance).reshape(2, 2)
        assert np.all(np.linalg.eigvalsh(cov) > 0)
    markers = harness.received['markers']
    assert spin_until(executor, lambda: markers)
    assert markers[-1].markers[0].action == Marker.DELETEALL
    namespaces = [m.ns for m in markers[-1].markers[1:]]
    # One ellipse per corner; the text ids are off by default (marker_text_ids).
    assert namespaces.count('ellipses') == len(truth) and 'corner_ids' not in namespaces
    assert all(m.header == scan.header for m in markers[-1].markers)


def test_lines_carry_every_segment_flagged_landmark_and_corners_index_them_all(
        ros_context, executor):
    harness = Harness(ros_context, executor)
    scan = room_scan_message()
    corners, lines = harness.exchange(scan)
    sigma_deg = np.degrees(np.sqrt([s.covariance[0] for s in lines.segments]))
    # The default bound, 3 deg, applied to each segment's own covariance.
    assert [s.landmark for s in lines.segments] == (sigma_deg <= 3.0).tolist()
    # A bound between the corner walls' angle stds: some walls are landmarks, some are not.
    walls = sorted({i for c in corners.corners for i in (c.first_line, c.second_line)})
    bound = float(np.median(sigma_deg[walls]))
    assert harness.node.set_parameters(
        [Parameter('max_landmark_angle_sigma_deg', value=bound)])[0].successful
    bounded_corners, bounded_lines = harness.exchange(scan, count=2)
    # Every segment is still there, in the same order; only the flags follow the bound.
    assert [s.first_index for s in bounded_lines.segments] == [
        s.first_index for s in lines.segments]
    flags = [s.landmark for s in bounded_lines.segments]
    assert flags == (sigma_deg <= bound).tolist()
    assert any(flags[i] for i in walls) and not all(flags[i] for i in walls)
    # The corners and their wall indices do not change: they index every segment.
    assert bounded_corners.corners == corners.corners
    assert len(corners.corners) == len(room_truth())
    for corner in bounded_corners.corners:
        for side in ('first', 'second'):
            wall = bounded_lines.segments[getattr(corner, f'{side}_line')]
            assert getattr(corner, f'{side}_line_points') == wall.num_points
            assert getattr(corner, f'{side}_line_chi2_dof') == wall.residual_chi2_dof


@pytest.mark.parametrize('reliability', [ReliabilityPolicy.BEST_EFFORT,
                                         ReliabilityPolicy.RELIABLE])
def test_best_effort_and_reliable_publishers_both_reach_the_node(ros_context, executor,
                                                                 reliability):
    harness = Harness(ros_context, executor, reliability=reliability)
    corners, _ = harness.exchange(room_scan_message())
    assert len(corners.corners) == 5


def test_two_publishers_taking_turns_are_not_counted_as_skipped_scans(ros_context, executor):
    # Each publisher numbers its own messages: read as one sequence, 5, 1, 6 gave a "gap" of 4
    # scans although the node kept up with every scan.
    harness = Harness(ros_context, executor)
    second = harness.peer.create_publisher(LaserScan, 'scan',
                                           QoSProfile(depth=10,
                                                      reliability=ReliabilityPolicy.RELIABLE))
    assert spin_until(executor, lambda: harness.node.count_publishers('scan') == 2)
    for turn in range(8):              # 1, 2, 3, 4 from the first, then 5, 1, 6, 2
        publisher = second if turn >= 4 and turn % 2 else harness.scans
        publisher.publish(room_scan_message(stamp=(turn + 1, 0)))
        assert spin_until(executor, lambda: len(harness.received['corners']) == turn + 1)
    assert harness.node.counters.processed == 8
    assert harness.node.counters.skipped == 0


def test_scans_lost_follow_the_running_total_of_dds_and_never_wrap(ros_context, executor):
    # Fast DDS's message-lost event carried a change of 2^32 - 1 (its count gone back by one,
    # unsigned) after a large scan was dropped: the node's count jumped by 2^32.
    node = Harness(ros_context, executor).node
    for total, change in ((3, 3), (2, 2**32 - 1), (3, 1), (5, 2)):
        node._on_scans_lost(SimpleNamespace(total_count=total, total_count_change=change))
    assert node.counters.lost == 5


def test_diagnostics_say_which_feature_pipeline_serves_and_whether_it_is_settled(
        ros_context, executor):
    from diagnostic_msgs.msg import DiagnosticArray
    from wctls_ros.core import status
    harness = Harness(ros_context, executor)
    reports = []
    harness.peer.create_subscription(DiagnosticArray, '/diagnostics', lambda array: reports.extend(
        {value.key: value.value for value in report.values} for report in array.status), 10)
    harness.exchange(room_scan_message())
    # Asked of the runtime after the report: a load may end in between, never start again.
    assert spin_until(executor, lambda: reports, 5.0)
    served, now = reports[0], status()
    assert served['feature pipeline'] in ('numba', 'numpy')
    if served['feature pipeline settled'] == 'yes':
        assert (served['feature pipeline'], now.pending) == (now.name, False)
    else:
        assert (served['feature pipeline'], served['feature pipeline settled']) == ('numpy', 'no')


def test_parameter_changes_take_effect_on_the_next_scan(ros_context, executor):
    harness = Harness(ros_context, executor)
    corners, _ = harness.exchange(room_scan_message())
    results = harness.node.set_parameters([Parameter('method', value='ml'),
                                           Parameter('iepf_threshold_m', value=5.0)])
    assert all(r.successful for r in results)
    corners, lines = harness.exchange(room_scan_message(), count=2)
    assert corners.method == lines.method == 'ml'
    # A 5 m split threshold never splits a chain: the room's corners are gone.
    assert len(corners.corners) < 5


@pytest.mark.parametrize('name,value,reason', [
    ('method', 'tls', 'method must be one of'),
    ('breakpoint_lambda_deg', 90.0, 'breakpoint_lambda_deg = 90.0 is outside its range (0, 90)'),
    ('iepf_threshold_m', -1.0, 'iepf_threshold_m'),
])
def test_invalid_parameter_changes_are_refused_with_the_reason(ros_context, executor, name,
                                                               value, reason):
    harness = Harness(ros_context, executor)
    before = harness.node.get_parameter(name).value
    result = harness.node.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful and reason in result.reason
    assert harness.node.get_parameter(name).value == before


def test_cross_parameter_rule_is_checked(ros_context, executor):
    harness = Harness(ros_context, executor)
    harness.node.set_parameters([Parameter('range_max_m', value=3.0)])
    result = harness.node.set_parameters([Parameter('range_min_m', value=4.0)])[0]
    assert not result.successful and 'below range_max_m' in result.reason


def malformed_scans():
    good = room_scan_message()
    cases = []
    for change in (
            {'ranges': np.zeros(0, np.float32)},
            {'angle_increment': 0.0},
            {'angle_increment': math.nan},
            {'angle_min': math.inf},
            {'angle_max': 1.0},
            {'intensities': np.ones(10, np.float32)},
            {'range_min': 50.0},
            {'ranges': np.full(1080, np.nan, np.float32)},
            {'ranges': np.full(1080, np.inf, np.float32)}):
        scan = room_scan_message()
        for key, value in change.items():
            setattr(scan, key, value)
        cases.append(scan)
    return good, cases


def test_a_burst_of_malformed_scans_then_a_good_one(ros_context, executor):
    harness = Harness(ros_context, executor)
    good, bad = malformed_scans()
    for count, scan in enumerate(bad, start=1):
        corners, lines = harness.exchange(scan, count)
        assert corners.header == scan.header
        assert len(corners.corners) == len(lines.segments) == 0
    corners, _ = harness.exchange(good, count=len(bad) + 1)
    assert len(corners.corners) == 5


def test_a_scan_of_garbage_is_published_empty_and_counted(ros_context, executor):
    # Every other return a random short echo: the scan's own noise estimate is about a metre,
    # beyond max_range_sigma_m; what it would give is walls fitted through noise.
    harness = Harness(ros_context, executor)
    garbage = room_scan_message()
    ranges = np.array(garbage.ranges, np.float32)
    ranges[::2] = np.random.default_rng(5).uniform(0.2, 1.0, ranges[::2].size)
    garbage.ranges = ranges
    corners, lines = harness.exchange(garbage, 1)
    assert len(corners.corners) == len(lines.segments) == 0
    assert harness.node.counters.implausible_noise == 1
    corners, _ = harness.exchange(room_scan_message(), count=2)
    assert len(corners.corners) == 5


def test_bytes_that_are_no_scan_are_counted_and_the_next_is_processed(ros_context, executor):
    # The node takes scans as CDR bytes and decodes them itself: whatever a publisher sends
    # on scan (e.g. a raw publish with the wrong layout) must not stop it.
    harness = Harness(ros_context, executor)
    good = serialize_message(room_scan_message())
    ranges_length = good.find(struct.pack('<I', 1080))
    undecodable = (good[:4],                                      # the encapsulation alone
                   good[:len(good) // 2],                         # cut in the ranges
                   good[:ranges_length] + struct.pack('<I', 2 ** 31 - 1)
                   + good[ranges_length + 4:])                    # a sequence too long
    harness.wait_for_subscriber()
    for count, data in enumerate(undecodable, start=1):       # one at a time: a one-scan queue
        harness.scans.publish(data)
        assert spin_until(harness.executor, lambda: harness.node.counters.malformed == count)
    corners, _ = harness.exchange(room_scan_message())
    assert len(corners.corners) == 5 and len(harness.received['corners']) == 1
    assert harness.node.counters.processed == 1


PACKAGES = ('wctls_ros', 'wctls_rplidar', 'wctls_lab')


def installed_executable(name):
    """Return an installed executable: the one on PATH (tools/env.sh), else in a prefix."""
    on_path = shutil.which(name)
    if on_path is not None and pathlib.Path(on_path).parent.name in PACKAGES:
        return pathlib.Path(on_path)
    install = pathlib.Path(sys.prefix).parent.parent / 'install'
    prefixes = [pathlib.Path(p) for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
                if p] + [install / package for package in PACKAGES]
    for path in (prefix / 'lib' / package / name for prefix in prefixes for package in PACKAGES):
        if path.is_file():
            return path
    pytest.skip(f'{name} is not installed (run colcon build)')


def test_installed_executable_runs_with_the_params_file_and_a_remap(ros_context, executor):
    executable = installed_executable('feature_node')
    process = subprocess.Popen(
        [str(executable), '--ros-args', '--params-file',
         str(PACKAGE / 'config' / 'feature_node.yaml'), '-p', 'range_sigma_m:=0.01',
         '-p', 'bearing_sigma_deg:=0.05', '-r', 'scan:=front/scan', '-r',
         'corners:=front/corners'], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        peer = Node('peer', context=ros_context)
        executor.add_node(peer)
        publisher = peer.create_publisher(LaserScan, 'front/scan', 10)
        received = []
        peer.create_subscription(CornerArray, 'front/corners', received.append, 10)
        scan = room_scan_message()
        assert spin_until(executor, lambda: received or publisher.publish(scan), timeout_s=20.0)
        assert received[0].header == scan.header and len(received[0].corners) == 5
    finally:
        process.terminate()
        output, _ = process.communicate(timeout=10)
    assert process.returncode == 0, output


def test_installed_executable_refuses_an_invalid_configuration():
    executable = installed_executable('feature_node')
    result = subprocess.run(
        [str(executable), '--ros-args', '-p', 'range_min_m:=5.0', '-p', 'range_max_m:=4.0'],
        capture_output=True, text=True, timeout=30)
    assert result.returncode == 1
    assert 'range_min_m (5) must be below range_max_m (4)' in result.stdout + result.stderr


def test_installed_executable_refuses_a_parameter_of_the_wrong_type_in_one_line():
    executable = installed_executable('feature_node')
    result = subprocess.run([str(executable), '--ros-args', '-p', 'range_sigma_m:=1'],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 1
    assert 'range_sigma_m' in result.stderr + result.stdout
    assert 'Traceback' not in result.stderr + result.stdout


def test_a_first_start_answers_with_the_numpy_core_while_numba_compiles(
        ros_context, executor, tmp_path):
    pytest.importorskip('numba')             # the stock-install run has the numpy core alone
    executable = installed_executable('feature_node')
    environment = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), WCTLS_ROS_CORE='auto')
    process = subprocess.Popen([str(executable), '--ros-args', '-p', 'range_sigma_m:=0.01',
                                '-p', 'bearing_sigma_deg:=0.05'], env=environment,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        peer = Node('peer', context=ros_context)
        executor.add_node(peer)
        publisher = peer.create_publisher(LaserScan, 'scan', 10)
        received = []
        peer.create_subscription(CornerArray, 'corners', received.append, 10)
        scan = room_scan_message()
        assert spin_until(executor, lambda: received or publisher.publish(scan), timeout_s=60.0)
        assert len(received[0].corners) == 5
        # Answered before the compile (tens of seconds here) has ended: nothing is cached yet.
        assert not list(tmp_path.rglob('*_features_of_scan*.nbi'))
    finally:
        process.terminate()
        output, _ = process.communicate(timeout=30)
    assert process.returncode == 0, output
    assert 'numpy feature pipeline for now: the compiled one' in output
    assert 'now running the compiled feature pipeline' not in output


def test_a_misspelled_parameter_in_a_params_file_is_named_with_the_closest_one(tmp_path):
    params = tmp_path / 'params.yaml'
    params.write_text('feature_node:\n  ros__parameters:\n    range_sigma: 0.01\n'
                      '    publish_markers: false\n')
    process = subprocess.Popen([str(installed_executable('feature_node')), '--ros-args',
                                '--params-file', str(params)], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    lines = []
    try:
        for line in process.stdout:           # until the node says it runs
            lines.append(line)
            if 'extracting features with' in line:
                break
    finally:
        process.terminate()
        lines += process.communicate(timeout=30)[0].splitlines()
    warnings = [line for line in lines if 'ignoring parameter' in line]
    assert len(warnings) == 1
    assert ('ignoring parameter range_sigma: feature_node has no such parameter (did you mean '
            'range_sigma_m?)') in warnings[0]
