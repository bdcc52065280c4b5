# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""`make demo`'s program end to end: emulator -> driver -> feature_node -> bag, table, figure."""

import os
import random
import signal
import subprocess
import time

from conftest import spin_until
import pytest
from test_feature_node import installed_executable

pytest.importorskip('rclpy')

# One of the suite's slowest modules (make test-fast leaves it out), and one that runs
# nodes, emulators or signals against deadlines (make test runs it in its realtime group).
pytestmark = [pytest.mark.slow, pytest.mark.realtime]


def own_domain():
    """Return an environment with a DDS domain of the demo's own (away from other tests)."""
    used = int(os.environ.get('ROS_DOMAIN_ID', '0'))
    return {**os.environ, 'ROS_DOMAIN_ID': str(random.choice(
        [d for d in range(1, 100) if d != used]))}


def leftovers(marker):
    """Return the processes whose command line names this test's output folder."""
    found = subprocess.run(['pgrep', '-f', str(marker)], capture_output=True, text=True)
    return found.stdout.split()


def summary_rows(out):
    """Return the demo's summary table (summary.md) as measure -> value."""
    table = (out / 'summary.md').read_text().split('\n\n')[0]
    rows = dict(line.strip('|').split('|')[:2] for line in table.splitlines()[2:])
    return {name.strip(): value.strip() for name, value in rows.items()}


def test_demo_records_a_bag_and_writes_the_table_and_the_figure(tmp_path):
    out = tmp_path / 'demo'
    result = subprocess.run([str(installed_executable('demo')), '--seconds', '3',
                             '--out', str(out)], capture_output=True, text=True, timeout=180,
                            env=own_domain())
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'corners per scan' in result.stdout and 'NEES against the truth' in result.stdout
    from rosbags.highlevel import AnyReader
    with AnyReader([out / 'bag']) as bag:
        times = {topic: [] for topic in bag.topics}
        for connection, log_time_ns, _ in bag.messages():
            times[connection.topic].append(log_time_ns * 1e-9)
    assert set(times) == {'/scan', '/corners', '/lines', '/markers', '/landmarks',
                          '/landmark_markers'}
    # The still sensor's corners keep their track ids: one confirmed id through most arrays.
    with AnyReader([out / 'bag']) as bag:
        arrays = [bag.deserialize(raw, c.msgtype) for c, _, raw in bag.messages()
                  if c.topic == '/landmarks']
    confirmed = [m.id for a in arrays for m in a.landmarks if m.kind == 0 and m.state == 1]
    assert confirmed and max(map(confirmed.count, set(confirmed))) >= len(arrays) / 2
    assert len(times['/scan']) >= 25                                # 10 Hz for 3 s
    # Features flowed through the recording. Not one per scan: on a busy machine feature_node
    # skips the scans that came while it was busy (17 CornerArrays for 51 scans once, beside
    # the other test worker).
    assert max(times['/corners']) - min(times['/corners']) >= 2.0, times['/corners']
    assert (out / 'scan.png').stat().st_size > 10000
    # The shipped default (generic preset) on the emulated S1: most corners are true, their
    # covariance honest.
    rows = summary_rows(out)
    matched = float(rows['corners within 10 cm of a true one'].split('(')[1].split()[0])
    assert matched > 90.0, rows
    assert 0.5 < float(rows['NEES against the truth (mean; 2 = calibrated)'].split()[0]) < 5.0
    assert not leftovers(out)


def test_ctrl_c_stops_every_process_and_exits_130(tmp_path):
    out = tmp_path / 'interrupted'
    demo = subprocess.Popen([str(installed_executable('demo')), '--seconds', '60', '--out',
                             str(out)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env=own_domain())
    try:
        for line in demo.stdout:
            if 'recording' in line:
                break
        assert leftovers(out), 'the emulator and the driver should be running'
        demo.send_signal(signal.SIGINT)
        assert demo.wait(timeout=30) == 130          # 128 + SIGINT, as every tool
    finally:
        if demo.poll() is None:
            demo.kill()
    deadline = time.monotonic() + 5.0
    while leftovers(out) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not leftovers(out)


def alive(pid):
    """Return whether a process runs (a zombie, ended but not reaped, does not)."""
    try:
        with open(f'/proc/{pid}/stat') as stat:
            return stat.read().rsplit(')', 1)[1].split()[0] != 'Z'
    except FileNotFoundError:
        return False


def test_the_demo_is_sealed_from_the_users_domain_and_its_processes_end_with_it(
        tmp_path, ros_context, executor):
    # Before, the demo published its emulated scans and corners into the environment's
    # ROS_DOMAIN_ID (on a robot: into the live system), and SIGKILL (or a closed terminal) left
    # its emulator, driver and feature_node running for ever.
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import LaserScan
    from wctls_msgs.msg import CornerArray
    heard = []
    listener = rclpy.create_node('users_system', context=ros_context)
    listener.create_subscription(LaserScan, 'scan', heard.append, qos_profile_sensor_data)
    listener.create_subscription(CornerArray, 'corners', heard.append, 10)
    executor.add_node(listener)
    demo = subprocess.Popen([str(installed_executable('demo')), '--seconds', '60', '--out',
                             str(tmp_path / 'demo')], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)     # the user's ROS_DOMAIN_ID
    printed = []
    try:
        for line in demo.stdout:
            printed.append(line)
            if 'recording' in line:
                break
        assert f"ROS_DOMAIN_ID {os.environ['ROS_DOMAIN_ID']}," not in ''.join(printed)
        spin_until(executor, lambda: heard, timeout_s=5.0)
        assert not heard, 'the demo published into the domain of the environment'
        children = [int(pid) for pid in subprocess.run(
            ['pgrep', '-P', str(demo.pid)], capture_output=True, text=True).stdout.split()]
        assert len(children) == 3, children         # emulator, rplidar_node, feature_node
        demo.kill()
        demo.wait(timeout=10)
    finally:
        if demo.poll() is None:
            demo.kill()
    deadline = time.monotonic() + 5.0
    while any(alive(pid) for pid in children) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [pid for pid in children if alive(pid)]


def test_the_summary_explains_missing_corner_arrays_and_corners_beyond_those_in_view():
    from types import SimpleNamespace
    import numpy as np
    from wctls_lab.demo import Recording, summarise

    def corner_array(stamp_s, xy):
        corners = [SimpleNamespace(pose=SimpleNamespace(
            covariance=np.diag([1e-4, 1e-4, 0, 0, 0, 1e-3]).ravel(),
            pose=SimpleNamespace(position=SimpleNamespace(x=x, y=y)))) for x, y in xy]
        return (stamp_s * 10 ** 9 + 5_000_000, SimpleNamespace(
            header=SimpleNamespace(stamp=SimpleNamespace(sec=stamp_s, nanosec=0)),
            corners=corners))

    in_view, hidden = np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([[-1.0, 0.0]])
    seen = Recording(scans={s * 10 ** 9: (s * 10 ** 9 + 1, None) for s in range(1, 7)})
    # Scan 1 before the first answer, 4 skipped, 6 at the end; scan 3 has a corner at the
    # hidden one and a false one besides the two in view.
    seen.corners = [corner_array(2, [[1.0, 0.01], [0.0, 1.0]]),
                    corner_array(3, [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.02], [3.0, 3.0]]),
                    corner_array(5, [[1.0, 0.0]])]
    rows, notes = summarise(seen, lambda stamp_ns: (in_view, hidden))
    assert dict(rows)['corners per scan (mean, min-max)'] == '2.3 (1-4)'
    assert notes[0].startswith('3 recorded scans have no CornerArray')
    assert [int(part.split(';')[0].split(',')[0]) for part in notes[0].split(': ')[1:]] == [
        1, 1, 1]                                     # before, at the end, skipped
    assert 'more corners (4) than the 2 true corners in view. Of the 2 corners' in notes[1]
    assert notes[1].endswith('thin evidence): 1; false: 1.')


def test_the_dock_demo_records_and_summarises_the_dock_poses(tmp_path):
    out = tmp_path / 'demo'
    result = subprocess.run([str(installed_executable('demo')), '--seconds', '3', '--dock',
                             '--out', str(out)], capture_output=True, text=True, timeout=180,
                            env=own_domain())
    assert result.returncode == 0, result.stdout + result.stderr
    from rosbags.highlevel import AnyReader
    with AnyReader([out / 'bag']) as bag:
        counts = {topic: info.msgcount for topic, info in bag.topics.items()}
    assert counts.get('/detected_dock_pose_with_covariance', 0) >= 10, counts
    rows = summary_rows(out)
    median_mm, median_deg = (float(v) for v in rows[
        'dock error against the truth (median mm, deg)'].split(','))
    # The example dock 1 m ahead, the shipped generic noise model on the emulated S1.
    assert median_mm < 20.0 and median_deg < 3.0, rows
    assert 0.5 < float(rows['dock NEES against the truth (mean; 3 = calibrated)']) < 9.0, rows
    assert (out / 'dock_plan.yaml').is_file() and not leftovers(out)


def test_the_moving_demo_follows_the_emulated_robot_with_the_odometry(tmp_path):
    out = tmp_path / 'demo'
    result = subprocess.run([str(installed_executable('demo')), '--seconds', '12', '--moving',
                             '--out', str(out)], capture_output=True, text=True, timeout=180,
                            env=own_domain())
    assert result.returncode == 0, result.stdout + result.stderr
    from rosbags.highlevel import AnyReader
    with AnyReader([out / 'bag']) as bag:
        counts = {topic: info.msgcount for topic, info in bag.topics.items()}
    assert counts.get('/odom', 0) >= 60, counts
    rows = summary_rows(out)
    # 12 s at 0.1 m/s round the circle: the odometry against the emulator's own true poses.
    path_m = float(rows['odometry poses, true path (m)'].split(',')[1])
    assert 0.8 < path_m < 1.4, rows
    assert float(rows['odometry ATE, SE(2) aligned (m)']) < 0.03, rows
    nees_mean = float(rows['odometry step NEES (mean; 3 = honest), inside the 95 % gate']
                      .split(',')[0])
    assert 0.5 < nees_mean < 9.0, rows
    # The corners are compared with the plan seen from the true pose of each scan.
    matched = float(rows['corners within 10 cm of a true one'].split('(')[1].split()[0])
    assert matched > 80.0, rows
    assert not leftovers(out)


def test_the_emulated_robot_drives_round_its_circle_at_its_speed():
    import math
    import numpy as np
    from wctls_lab.simulated_rplidar import Circle
    circle, start = Circle(radius_m=0.35, speed_m_s=0.1), np.array([2.2, 1.25, math.pi / 2])
    times = np.linspace(0.0, 30.0, 3001)
    poses = np.array([circle.pose(start, t) for t in times])
    assert np.allclose(poses[0], start)
    centre = np.array([2.2 - 0.35, 1.25])
    assert np.allclose(np.hypot(*(poses[:, :2] - centre).T), 0.35)
    velocity = np.diff(poses[:, :2], axis=0) / np.diff(times)[:, None]
    assert np.allclose(np.hypot(*velocity.T), 0.1, rtol=1e-4)
    # Heading along the path (finite differences), turning left.
    heading = np.arctan2(velocity[:, 1], velocity[:, 0])
    middle = 0.5 * (poses[1:, 2] + poses[:-1, 2])
    assert np.allclose(np.angle(np.exp(1j * (heading - middle))), 0.0, atol=1e-6)
    assert np.all(np.diff(poses[:, 2]) > 0)
