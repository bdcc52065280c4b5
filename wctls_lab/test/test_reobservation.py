# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Re-observation consistency of corners and lines from a moving sensor, against simulated truth.

The simulator moves the sensor at a known velocity and knows every pose exactly. With the
noise model the simulation used, the share of re-observations inside the 95 % gate must be
about 0.95, for the pose-free quantities (corner-corner distance, line-line angle, corner-line
distance) and in the world frame with the true poses; with every covariance halved it must
fall clearly below (a test that can fail). ``score --poses`` must give the same figures as the
function from a pose file. A line track takes only segments on the stretch of wall it has seen
(a cabinet before the wall, alike as an infinite line, is another landmark), and the pose
Jacobian of a line's world (angle, radius) matches finite differences. On the moving robots of
data/ with their SLAM poses, the line landmarks (the default rule) are inside their 95 % gate in
at least 93 % of the re-observations, and every segment taken as a line is not.
"""

import math

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_lab.evaluation import load_scans, StaticScans
from wctls_lab.evaluation.poses import load_poses, PoseError, poses_at, write_poses
from wctls_lab.evaluation.reobservation import (
    Landmarks, measure, reobservation, to_world, with_poses)
from wctls_lab.simulation import floor_plan_from_dict, NoiseModel, simulate_recording
from wctls_ros.core import FeatureConfig

ROOM = {'name': 'room', 'polylines': [
    {'closed': True, 'points': [[0.0, 0.0], [4.5, 0.0], [4.5, 2.5], [1.5, 2.5], [1.5, 1.6],
                                [0.0, 1.6]]}],
    'boxes': [{'center': [3.6, 1.9], 'size': [0.8, 0.6], 'yaw_deg': 30.0}],
    'sensor': {'x': 2.5, 'y': 1.0, 'yaw_deg': 10.0}}
RANGE_SIGMA_M = 0.01
BEARING_SIGMA_RAD = math.radians(0.05)
SCANS = 80
# 2 cm and 1.7 deg a scan: across the room and a quarter turn over the recording.
START = (2.0, 0.8, 0.2)
VELOCITY = (0.2, 0.1, 0.3)


@pytest.fixture(scope='module')
def moving():
    plan = floor_plan_from_dict(ROOM)
    noise = NoiseModel(range_sigma_m=RANGE_SIGMA_M, bearing_sigma_rad=BEARING_SIGMA_RAD)
    recording = simulate_recording(plan, noise, SCANS, seed=11, pose=START, velocity=VELOCITY,
                                   beams=1080)
    stamps_ns = 1_700_000_000 * 10 ** 9 + 100_000_000 * np.arange(SCANS)
    scans = StaticScans(recording.ranges, recording.angle_min, recording.angle_increment, 0.05,
                        40.0, stamps_ns, 'simulated moving sensor')
    return scans, recording.poses


def calibrated(method='wctls'):
    return FeatureConfig().replace(method=method, range_sigma_m=RANGE_SIGMA_M,
                                   bearing_sigma_rad=BEARING_SIGMA_RAD)


def shares(figures):
    return {'corner distances': figures.corner_distance, 'line angles': figures.line_angle,
            'corner-line distances': figures.corner_line_distance,
            'corners with poses': figures.corner_tracks, 'lines with poses': figures.line_tracks}


@pytest.mark.parametrize('method', ['wtls', 'wctls'])
def test_calibrated_covariances_put_95_percent_inside_the_gate(moving, method):
    scans, poses = moving
    figures = reobservation(scans, calibrated(method), poses)
    for name, gate in shares(figures).items():
        assert gate.tested >= 200, (name, gate)
        # 200 Bernoulli(0.95) trials: 2.5 standard errors are about 4 points.
        assert 0.91 <= gate.share <= 0.99, (name, gate.describe())


def test_halved_covariances_fail_the_gate_clearly(moving):
    scans, poses = moving
    figures = reobservation(scans, calibrated(), poses, covariance_scale=0.5)
    for name, gate in shares(figures).items():
        # Halved covariances: a chi2 share of 0.78 (2 dof) or 0.83 (1 dof) inside the gate.
        assert gate.share < 0.88, (name, gate.describe())


def test_tracks_follow_the_landmarks_through_the_recording(moving):
    scans, poses = moving
    figures = reobservation(scans, calibrated(), poses)
    assert np.median(figures.corner_track_lengths) >= SCANS / 2
    assert np.percentile(figures.line_track_lengths, 90) >= SCANS / 2
    assert figures.landmarks_per_scan == pytest.approx(
        figures.corners_per_scan + figures.lines_per_scan)
    assert figures.corners_per_scan >= 3 and figures.lines_per_scan >= 5


def test_a_wrong_pose_covariance_shows_in_the_pose_test_not_in_the_pose_free_one(moving):
    scans, poses = moving
    rng = np.random.default_rng(3)
    noisy = poses + rng.normal(0.0, 1.0, poses.shape) * (0.02, 0.02, math.radians(1.0))
    stated = reobservation(scans, calibrated(), noisy, 0.02, math.radians(1.0))
    ignored = reobservation(scans, calibrated(), noisy)
    assert stated.corner_tracks.share >= 0.9 and stated.line_tracks.share >= 0.9
    assert ignored.corner_tracks.share < 0.6 and ignored.line_tracks.share < 0.6
    assert stated.corner_distance == ignored.corner_distance


def test_world_frame_covariance_matches_monte_carlo():
    landmarks = Landmarks(np.array([[1.2, -0.4]]), np.diag([1e-4, 4e-4])[None],
                          np.array([[0, 1]]), np.array([[0.7, 1.5]]),
                          np.array([[[1e-4, 2e-5], [2e-5, 9e-4]]]),
                          np.array([[[1.4, 0.6], [0.8, 1.8]]]))
    pose = np.array([0.8, -1.1, 2.5])
    pose_cov = np.diag([0.03, 0.02, 0.05]) ** 2
    _, corner_cov, line, line_cov = to_world(landmarks, pose, pose_cov)
    rng = np.random.default_rng(1)
    samples = []
    for pose_drawn in rng.multivariate_normal(pose, pose_cov, 400):    # 50 landmarks a pose
        drawn = Landmarks(rng.multivariate_normal(landmarks.corner_xy[0],
                                                  landmarks.corner_cov[0], 50),
                          np.zeros((50, 2, 2)), np.zeros((50, 2), dtype=int),
                          rng.multivariate_normal(landmarks.line[0], landmarks.line_cov[0], 50),
                          np.zeros((50, 2, 2)), np.zeros((50, 2, 2)))
        xy, _, drawn_line, _ = to_world(drawn, pose_drawn, np.zeros((3, 3)))
        samples.append(np.column_stack([xy, drawn_line]))
    samples = np.concatenate(samples)
    samples[:, 2] = line[0, 0] + np.angle(np.exp(1j * (samples[:, 2] - line[0, 0])))
    empirical = np.cov(samples.T)
    assert np.allclose(empirical[:2, :2], corner_cov[0], rtol=0.05, atol=1e-6)
    assert np.allclose(empirical[2:, 2:], line_cov[0], rtol=0.05, atol=1e-6)


def wall_piece(start_xy, end_xy, sigma_m=0.01):
    """Return the landmarks of a scan that sees one piece of wall (no corners)."""
    start, end = np.asarray(start_xy, dtype=float), np.asarray(end_xy, dtype=float)
    direction = (end - start) / np.linalg.norm(end - start)
    normal = np.array([direction[1], -direction[0]])
    if normal @ start < 0.0:                         # from the sensor towards the wall
        normal = -normal
    line = np.array([[math.atan2(normal[1], normal[0]), normal @ start]])
    return Landmarks(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2), dtype=np.intp),
                     line, np.diag([(sigma_m / 2.0) ** 2, sigma_m ** 2])[None],
                     np.array([[start, end]]))


def test_a_line_joins_a_track_only_where_its_segment_overlaps_the_tracks_last_one():
    # A wall 2 m ahead, then a cabinet front 5 cm before it, 1 m further along: alike as
    # infinite lines within the association gate (3.5 sigma apart), but two landmarks.
    wall = wall_piece((2.0, -1.5), (2.0, -0.5))
    cabinet = wall_piece((1.95, 0.5), (1.95, 1.2))
    wall_again = wall_piece((2.0, -0.8), (2.0, 0.2))
    poses = np.zeros((3, 3))
    corners, lines, _, line_lengths = with_poses([wall, cabinet, wall_again], poses,
                                                 np.zeros((3, 3)))
    assert corners.tested == 0
    # The cabinet starts a track of its own; the wall seen again joins the wall's.
    assert (lines.tested, lines.inside) == (1, 1)
    assert sorted(line_lengths) == [1, 2]


def test_a_line_track_keeps_the_stretch_of_wall_it_has_seen():
    # The whole wall, then only its left end (the rest hidden), then its right end: the third
    # piece misses the second but lies on the stretch the track has seen.
    pieces = [wall_piece((2.0, -1.5), (2.0, 0.5)), wall_piece((2.0, -1.0), (2.0, -0.5)),
              wall_piece((2.0, 0.0), (2.0, 0.4))]
    _, lines, _, line_lengths = with_poses(pieces, np.zeros((3, 3)), np.zeros((3, 3)))
    assert (lines.tested, lines.inside) == (2, 2)
    assert line_lengths == (3,)


def test_the_line_pose_jacobian_matches_finite_differences():
    landmarks = wall_piece((1.5, -0.4), (1.2, 0.9))
    pose = np.array([0.8, -1.1, 2.5])
    _, _, line, no_pose = to_world(landmarks, pose, np.zeros((3, 3)))
    step = 1e-6
    for axis in range(3):
        moved = pose.copy()
        moved[axis] += step
        _, _, line_moved, _ = to_world(landmarks, moved, np.zeros((3, 3)))
        derivative = (line_moved[0] - line[0]) / step
        pose_cov = np.zeros((3, 3))
        pose_cov[axis, axis] = 1.0
        _, _, _, with_pose = to_world(landmarks, pose, pose_cov)
        assert np.allclose(with_pose[0] - no_pose[0], np.outer(derivative, derivative),
                           atol=1e-5), axis


def test_poses_are_interpolated_to_the_stamps_with_the_laser_offset(tmp_path):
    path = write_poses(tmp_path / 'poses.csv', np.array([10.0, 11.0, 12.0]),
                       np.array([[0.0, 0.0, 0.0], [1.0, 0.0, math.pi / 2],
                                 [1.0, 1.0, math.pi]]))
    poses = poses_at(load_poses(path), np.array([9.0, 10.5, 11.5]), (0.2, 0.0, 0.0))
    assert np.isnan(poses[0]).all()                          # before the first pose
    yaw = math.pi / 4
    assert np.allclose(poses[1], [0.5 + 0.2 * math.cos(yaw), 0.2 * math.sin(yaw), yaw])
    yaw = 3 * math.pi / 4
    assert np.allclose(poses[2], [1.0 + 0.2 * math.cos(yaw), 0.5 + 0.2 * math.sin(yaw), yaw])


@pytest.mark.parametrize('text, message', [
    ('stamp_s,x_m,y_m\n1,2,3\n2,3,4\n', 'yaw_rad missing'),
    ('stamp_s,x_m,y_m,yaw_rad\n1,2,3,x\n2,3,4,5\n', 'not a number'),
    ('stamp_s,x_m,y_m,yaw_rad\n1,2,3,4\n', 'at least 2 rows'),
])
def test_a_bad_pose_file_is_refused_with_the_reason(tmp_path, text, message):
    path = tmp_path / 'poses.csv'
    path.write_text(text)
    with pytest.raises(PoseError, match=message):
        load_poses(path)


def test_unknown_poses_leave_their_scans_out_of_the_tracks_only(moving):
    scans, poses = moving
    from wctls_lab.evaluation.analysis import features_per_scan
    from wctls_ros.frontend.frames import landmarks_from_features
    config = calibrated()
    landmarks = [landmarks_from_features(f, config.max_landmark_angle_sigma_rad)
                 for f, _ in features_per_scan(scans, config)]
    partial = poses.copy()
    partial[:20] = np.nan
    some = measure(landmarks, partial)
    later = measure(landmarks[20:], poses[20:])
    assert some.corner_tracks == later.corner_tracks
    assert some.corner_distance == measure(landmarks).corner_distance


def write_robot_bag(path, scans, base_poses):
    """
    Write the scans, the base's odometry and its TF (odom -> base_link) with rosbags.

    The odometry and TF are stamped half a scan period after each scan, so that score has to
    interpolate them to the scans' stamps.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from wctls_ros.bags import typestore
    store = typestore()
    types = store.types

    def header(stamp_ns, frame):
        sec, nanosec = divmod(int(stamp_ns), 10 ** 9)
        return types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec),
            frame_id=frame)

    def quaternion(yaw):
        return types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                     w=math.cos(yaw / 2))

    half_period_ns = 50_000_000
    odometry_stamps = np.append(scans.stamps_ns - half_period_ns,
                                scans.stamps_ns[-1] + half_period_ns)
    odometry_poses = np.vstack([base_poses[0] - (base_poses[1] - base_poses[0]) / 2,
                                (base_poses[:-1] + base_poses[1:]) / 2,
                                base_poses[-1] + (base_poses[-1] - base_poses[-2]) / 2])
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        scan_topic = bag.add_connection('/scan', 'sensor_msgs/msg/LaserScan', typestore=store)
        odom_topic = bag.add_connection('/odom', 'nav_msgs/msg/Odometry', typestore=store)
        tf_topic = bag.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=store)
        for ranges, stamp in zip(scans.ranges, scans.stamps_ns):
            scan = types['sensor_msgs/msg/LaserScan'](
                header=header(stamp, 'laser'), angle_min=scans.angle_min,
                angle_max=scans.angle_min + (len(ranges) - 1) * scans.angle_increment,
                angle_increment=scans.angle_increment, time_increment=0.0, scan_time=0.1,
                range_min=0.05, range_max=40.0, ranges=ranges.astype(np.float32),
                intensities=np.zeros(0, np.float32))
            bag.write(scan_topic, int(stamp),
                      store.serialize_cdr(scan, 'sensor_msgs/msg/LaserScan'))
        for stamp, (x, y, yaw) in zip(odometry_stamps, odometry_poses):
            point = types['geometry_msgs/msg/Point'](x=x, y=y, z=0.0)
            pose = types['geometry_msgs/msg/PoseWithCovariance'](
                pose=types['geometry_msgs/msg/Pose'](position=point, orientation=quaternion(yaw)),
                covariance=np.zeros(36))
            twist = types['geometry_msgs/msg/TwistWithCovariance'](
                twist=types['geometry_msgs/msg/Twist'](
                    linear=types['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0),
                    angular=types['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0)),
                covariance=np.zeros(36))
            odometry = types['nav_msgs/msg/Odometry'](header=header(stamp, 'odom'),
                                                      child_frame_id='base_link', pose=pose,
                                                      twist=twist)
            bag.write(odom_topic, int(stamp),
                      store.serialize_cdr(odometry, 'nav_msgs/msg/Odometry'))
            moved = types['geometry_msgs/msg/Transform'](
                translation=types['geometry_msgs/msg/Vector3'](x=x, y=y, z=0.0),
                rotation=quaternion(yaw))
            # A transform of another pair of frames in the same message is left alone.
            elsewhere = types['geometry_msgs/msg/Transform'](
                translation=types['geometry_msgs/msg/Vector3'](x=5.0, y=-3.0, z=0.0),
                rotation=quaternion(1.0))
            other = types['geometry_msgs/msg/TransformStamped'](
                header=header(stamp, 'map'), child_frame_id='odom', transform=elsewhere)
            wanted = types['geometry_msgs/msg/TransformStamped'](
                header=header(stamp, 'odom'), child_frame_id='base_link', transform=moved)
            tf = types['tf2_msgs/msg/TFMessage'](transforms=[other, wanted])
            bag.write(tf_topic, int(stamp), store.serialize_cdr(tf, 'tf2_msgs/msg/TFMessage'))
    return path


@pytest.mark.parametrize('source', ['file', '/odom', '/tf'])
def test_score_takes_poses_from_a_file_odometry_or_tf_and_prints_the_same_figures(
        moving, tmp_path, capsys, source):
    pytest.importorskip('rclpy')
    from wctls_lab.evaluation.score_cli import main, node_config
    scans, poses = moving
    # The poses of the robot base, the sensor 0.1 m ahead of it: score composes the offset.
    base = poses - np.column_stack([0.1 * np.cos(poses[:, 2]), 0.1 * np.sin(poses[:, 2]),
                                    np.zeros(len(poses))])
    bag = write_robot_bag(tmp_path / 'moving', scans, base)
    given = (['--poses', str(write_poses(tmp_path / 'poses.csv', scans.stamps_ns * 1e-9, base))]
             if source == 'file' else ['--poses-topic', source])
    capsys.readouterr()
    assert main([str(bag), '--methods', 'wctls', '--range-sigma', str(RANGE_SIGMA_M),
                 '--bearing-sigma-deg', '0.05', '--common-range-sigma', '0', '--laser-offset',
                 '0.1', '0', '0', '--still', 'no'] + given) == 0
    out = capsys.readouterr().out
    config = node_config().replace(range_sigma_m=RANGE_SIGMA_M,
                                   bearing_sigma_rad=math.radians(0.05),
                                   common_range_sigma_m=0.0, method='wctls')
    from wctls_lab.evaluation import load_scans
    expected = reobservation(load_scans(bag), config, poses)     # the bag's float32 ranges
    for line in expected.lines():
        assert line in out, (line, out)
    assert f'{SCANS} of {SCANS} scans covered' in out


def test_a_pose_topic_the_bag_lacks_is_refused_with_the_topics_it_has(moving, tmp_path, capsys):
    pytest.importorskip('rclpy')
    from wctls_lab.evaluation.score_cli import main
    scans, poses = moving
    bag = write_robot_bag(tmp_path / 'moving', scans.part(0, 8), poses[:8])
    capsys.readouterr()
    assert main([str(bag), '--poses-topic', '/odometry', '--still', 'no']) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and error.startswith('score: error:')
    assert 'no nav_msgs/msg/Odometry or tf2_msgs/msg/TFMessage topic /odometry' in error
    assert '/odom (nav_msgs/msg/Odometry), /tf (tf2_msgs/msg/TFMessage)' in error
    assert main([str(bag), '--poses-topic', '/tf', '--tf-frames', 'odom', 'base_footprint',
                 '--still', 'no']) == 2
    assert 'holds 0 poses' in capsys.readouterr().err


# name, sensor ahead of the posed base (m), scans tested (the first; gh25 in ~20 s, not ~80 s).
MOVING_ROBOTS = [('mrpt_malaga_moving', 0.78, None), ('tuw_gh25_moving', 0.12, 40)]


@pytest.mark.parametrize('name,laser_x_m,count', MOVING_ROBOTS)
def test_line_landmarks_of_moving_robots_pass_their_gate_where_all_segments_do_not(
        name, laser_x_m, count):
    # As wctls_lab/tools/make_score_results.sh scores them: default preset, poses at 5 cm / 1 deg.
    pytest.importorskip('rosbags')
    from wctls_lab.evaluation.score_cli import node_config
    scans = load_scans(REAL_DATA / name, limit=count)
    poses = poses_at(load_poses(REAL_DATA / name / 'poses.csv'), scans.stamps_ns * 1e-9,
                     (laser_x_m, 0.0, 0.0))
    config = node_config()
    landmarks = reobservation(scans, config, poses, 0.05, math.radians(1.0))
    every_segment = reobservation(scans, config.replace(max_landmark_angle_sigma_rad=math.pi),
                                  poses, 0.05, math.radians(1.0))
    # Measured: gh25 94.6 % of 426 (scans 0-39; 94.3 % of 1855 over all), Malaga 95.1 % of 427;
    # every segment: 91.1 % of 576 and 89.6 % of 584.
    assert landmarks.line_tracks.share >= 0.93 > every_segment.line_tracks.share
    assert landmarks.line_tracks.tested >= 400
    assert landmarks.corner_tracks == every_segment.corner_tracks
    assert landmarks.lines_per_scan < every_segment.lines_per_scan
