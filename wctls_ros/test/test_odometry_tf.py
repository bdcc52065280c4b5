# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
odometry_node's TF (``publish_tf``) through the real rclpy, with a tf2_msgs built for the test.

Every ROS install has tf2_msgs; the PyPI ROS wheels these tests run on do not. So the test
builds the one message the node publishes, tf2_msgs/TFMessage, from the definition ros2/geometry2
publishes for Jazzy (``geometry_msgs/TransformStamped[] transforms``), with colcon into the
test's temporary folder, and runs the node and a subscriber in a child process that alone has
it on its paths: nothing lands where a user's ROS install would find it. Where tf2_msgs is
installed, the child uses that one. The RPLIDAR car's scans go in; every scan's transform
odom -> base_link must carry the Odometry's stamp, frames and pose.
"""

import json
import math
import os
import pathlib
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip('rclpy')

# One of the suite's slowest modules (a colcon build): make test-fast leaves it out.
pytestmark = pytest.mark.slow

RECORDING = pathlib.Path(__file__).resolve().parents[2] / 'data' / 'rplidar_barc_moving'
SCANS = 40
TF2_MSGS_PACKAGE = """\
<?xml version="1.0"?>
<package format="3">
  <name>tf2_msgs</name>
  <version>0.0.0</version>
  <description>TFMessage alone, built for a test from its published definition.</description>
  <maintainer email="maintainers@wctls-ros.dev">wctls_ros maintainers</maintainer>
  <license>BSD-3-Clause</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>geometry_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
TF2_MSGS_CMAKE = """\
cmake_minimum_required(VERSION 3.8)
project(tf2_msgs)
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
find_package(geometry_msgs REQUIRED)
rosidl_generate_interfaces(${PROJECT_NAME} "msg/TFMessage.msg" DEPENDENCIES geometry_msgs)
ament_export_dependencies(rosidl_default_runtime)
ament_package()
"""
TF_MESSAGE = 'geometry_msgs/TransformStamped[] transforms\n'


def tf2_msgs_environment(workspace: pathlib.Path) -> dict:
    """Return the environment of a child that imports tf2_msgs: built here unless installed."""
    try:
        import tf2_msgs.msg  # noqa: F401
        return dict(os.environ)
    except ImportError:
        pass
    package = workspace / 'src' / 'tf2_msgs'
    (package / 'msg').mkdir(parents=True)
    (package / 'package.xml').write_text(TF2_MSGS_PACKAGE)
    (package / 'CMakeLists.txt').write_text(TF2_MSGS_CMAKE)
    (package / 'msg' / 'TFMessage.msg').write_text(TF_MESSAGE)
    environment = {k: v for k, v in os.environ.items() if k not in ('MAKEFLAGS', 'MFLAGS')}
    built = subprocess.run(
        ['colcon', 'build', '--base-paths', str(workspace / 'src'),
         '--build-base', str(workspace / 'build'), '--install-base', str(workspace / 'install'),
         '--event-handlers', 'console_cohesion-', '--cmake-args',
         f'-DPython3_EXECUTABLE={sys.executable}', '-DBUILD_TESTING=OFF'],
        cwd=workspace, env=environment, capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stdout[-3000:] + built.stderr[-3000:]
    prefix = workspace / 'install' / 'tf2_msgs'
    python = next(prefix.glob('lib/python3*/site-packages'))
    for name, path in (('PYTHONPATH', python), ('LD_LIBRARY_PATH', prefix / 'lib'),
                       ('AMENT_PREFIX_PATH', prefix)):
        environment[name] = os.pathsep.join([str(path)] + [p for p in [os.environ.get(name)]
                                                           if p])
    return environment


# The child: odometry_node with publish_tf, the car's scans in, Odometry and TF out, as JSON.
CHILD = textwrap.dedent(f"""
    import json, math
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from tf2_msgs.msg import TFMessage
    from conftest import spin_until
    from test_odometry_node import Harness, PARAMETERS, pose_of, recorded_scans

    rclpy.init()
    executor = SingleThreadedExecutor()
    harness = Harness(rclpy.get_default_context(), executor,
                      dict(PARAMETERS, publish_tf=True))
    transforms = []
    harness.peer.create_subscription(TFMessage, '/tf', transforms.append, 100)
    rows = []
    for scan in recorded_scans()[0][:{SCANS}]:
        odometry = harness.exchange(scan)
        assert spin_until(executor, lambda: any(
            t.header.stamp == odometry.header.stamp for m in transforms for t in m.transforms),
            timeout_s=10.0)
        rows.append({{'odometry': [odometry.header.stamp.sec, odometry.header.stamp.nanosec,
                                   odometry.header.frame_id, odometry.child_frame_id,
                                   *pose_of(odometry)]}})
    rows.append({{'tf': [[[t.header.stamp.sec, t.header.stamp.nanosec, t.header.frame_id,
                          t.child_frame_id, t.transform.translation.x,
                          t.transform.translation.y, t.transform.translation.z,
                          t.transform.rotation.x, t.transform.rotation.y,
                          2 * math.atan2(t.transform.rotation.z, t.transform.rotation.w)]
                         for t in message.transforms] for message in transforms]}})
    print(json.dumps(rows))
""")


@pytest.mark.skipif(not RECORDING.is_dir(), reason='no recording')
def test_every_scan_gives_the_transform_of_its_odometry(tmp_path):
    environment = tf2_msgs_environment(tmp_path / 'tf2_msgs_workspace')
    # The child imports the harness of test_odometry_node and the root conftest's spin_until.
    here = pathlib.Path(__file__).resolve().parent
    environment['PYTHONPATH'] = os.pathsep.join(
        [str(here), str(here.parents[1]), environment.get('PYTHONPATH', '')])
    child = subprocess.run([sys.executable, '-c', CHILD], env=environment, capture_output=True,
                           text=True, timeout=300)
    assert child.returncode == 0, child.stderr[-3000:]
    *rows, last = json.loads(child.stdout.strip().splitlines()[-1])
    odometry = [row['odometry'] for row in rows]
    messages = last['tf']
    assert len(odometry) == SCANS and len(messages) == SCANS
    # One transform per message, one message per scan, in the scans' order.
    assert [len(message) for message in messages] == [1] * SCANS
    for (sec, nanosec, frame, child_frame, x, y, yaw), [transform] in zip(odometry, messages):
        assert transform[:4] == [sec, nanosec, frame, child_frame] == [sec, nanosec, 'odom',
                                                                       'base_link']
        assert transform[4:7] == pytest.approx([x, y, 0.0], abs=1e-12)
        assert transform[7:9] == [0.0, 0.0]
        assert math.remainder(transform[9] - yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    # The car drove: the transforms follow a pose that moves, not a constant.
    assert math.hypot(odometry[-1][4], odometry[-1][5]) > 0.5
