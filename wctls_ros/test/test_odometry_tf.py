# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
odometry_node's TF through the real rclpy, with a tf2_msgs built for the test.

Every ROS install has tf2_msgs; the PyPI ROS wheels these tests run on do not. So the test
builds the one message the node uses, tf2_msgs/TFMessage, from the definition ros2/geometry2
publishes for Jazzy (``geometry_msgs/TransformStamped[] transforms``), with colcon into the
test's temporary folder, and runs the node and its peer in a child process that alone has it
on its paths: nothing lands where a user's ROS install would find it. Where tf2_msgs is
installed, the child uses that one. ``publish_tf``: the RPLIDAR car's scans go in; every
scan's transform odom -> base_link must carry the Odometry's stamp, frames and pose.
``mount_from_tf``: with the laser's mount on /tf_static (a chain of two static transforms),
the odometry must be the one the mount's parameters give, the scans before it left out.
``wheel_odometry_tf_frame``: the wheel odometry as odom -> base_link on /tf; the steps of scans
without landmarks must be its own, interpolated at their stamps.
"""

import json
import math
import os
import pathlib
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from wctls_ros.odometry_messages import planar_mount

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


@pytest.fixture(scope='module')
def child_environment(tmp_path_factory):
    """Return the environment of a child process that imports tf2_msgs and the node harness."""
    environment = tf2_msgs_environment(tmp_path_factory.mktemp('tf2_msgs_workspace'))
    # The child imports the harness of test_odometry_node and the root conftest's spin_until.
    here = pathlib.Path(__file__).resolve().parent
    environment['PYTHONPATH'] = os.pathsep.join(
        [str(here), str(here.parents[1]), environment.get('PYTHONPATH', '')])
    return environment


def run_child(code: str, environment: dict, *arguments: str):
    """Run a child's code with arguments; return the JSON it printed last."""
    child = subprocess.run([sys.executable, '-c', code, *arguments], env=environment,
                           capture_output=True, text=True, timeout=300)
    assert child.returncode == 0, child.stderr[-3000:]
    return json.loads(child.stdout.strip().splitlines()[-1])


def tf2_msgs_environment(workspace: pathlib.Path) -> dict:
    """Return an environment in which tf2_msgs imports: built here unless installed."""
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
def test_every_scan_gives_the_transform_of_its_odometry(child_environment):
    *rows, last = run_child(CHILD, child_environment)
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


def quaternion_of(roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0):
    """Return (x, y, z, w) of rotations about x, then y, then z (rad), as a quaternion."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def test_a_chain_of_static_transforms_gives_the_mount_on_the_plane():
    # base_link -> plate: 1 m ahead, turned 90 deg left; plate -> laser: 0.5 m along the
    # plate's x (the robot's y), turned 90 deg more, 0.2 m up. By hand: (1, 0.5), 180 deg.
    transforms = {'plate': ('base_link', (1.0, 0.0, 0.3), quaternion_of(yaw_rad=math.pi / 2)),
                  'laser': ('plate', (0.5, 0.0, 0.2), quaternion_of(yaw_rad=math.pi / 2))}
    x, y, yaw = planar_mount(transforms, 'base_link', 'laser')
    assert (x, y) == pytest.approx((1.0, 0.5), abs=1e-12)
    assert abs(math.remainder(yaw - math.pi, 2 * math.pi)) < 1e-12
    assert planar_mount(transforms, 'base_link', 'base_link') == (0.0, 0.0, 0.0)
    assert planar_mount(transforms, 'base_link', 'camera') is None       # not (yet) known
    assert planar_mount({'laser': ('plate', (0, 0, 0), (0, 0, 0, 1))}, 'base_link',
                        'laser') is None


def test_a_tilted_upside_down_or_looping_mount_is_refused():
    level = planar_mount({'laser': ('base_link', (0.1, 0.0, 0.2),
                                    quaternion_of(roll_rad=math.radians(1.5), yaw_rad=0.3))},
                         'base_link', 'laser')
    assert level[2] == pytest.approx(0.3, abs=1e-3)
    with pytest.raises(ValueError, match='3.0 deg from the plane'):
        planar_mount({'laser': ('base_link', (0, 0, 0), quaternion_of(pitch_rad=math.radians(3)))},
                     'base_link', 'laser')
    with pytest.raises(ValueError, match='upside down'):
        planar_mount({'laser': ('base_link', (0, 0, 0), quaternion_of(roll_rad=math.pi))},
                     'base_link', 'laser')
    with pytest.raises(ValueError, match='loop'):
        planar_mount({'laser': ('plate', (0, 0, 0), (0, 0, 0, 1)),
                      'plate': ('laser', (0, 0, 0), (0, 0, 0, 1))}, 'base_link', 'laser')


# The child: the car's scans through odometry_node, its mount given as parameters or, with
# mount_from_tf, on /tf_static as a chain of two transforms published after the first scans
# (a late robot_state_publisher); the poses after the mount is known, and whether an Odometry
# came for any of the scans before.
MOUNT_CHILD = textwrap.dedent(f"""
    import json, sys
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    from conftest import spin_until
    from test_odometry_node import Harness, PARAMETERS, pose_of, recorded_scans
    from wctls_ros.odometry_node import TF_STATIC_QOS

    from_tf = sys.argv[1] == 'tf'
    rclpy.init()
    executor = SingleThreadedExecutor()
    parameters = dict(PARAMETERS)
    if from_tf:
        del parameters['laser_x_m']
        parameters['mount_from_tf'] = True
    harness = Harness(rclpy.get_default_context(), executor, parameters)
    scans = recorded_scans()[0][:{SCANS}]
    if from_tf:
        for scan in scans[:3]:
            harness.scans.publish(scan)
        spin_until(executor, lambda: False, timeout_s=1.0)
        static = harness.peer.create_publisher(TFMessage, '/tf_static', TF_STATIC_QOS)
        chain = []
        for child, parent, x in (('plate', 'base_link', -0.05), ('laser', 'plate', -0.07)):
            moved = TransformStamped(child_frame_id=child)
            moved.header.frame_id = parent
            moved.transform.translation.x, moved.transform.translation.z = x, 0.1
            moved.transform.rotation.w = 1.0
            chain.append(moved)
        static.publish(TFMessage(transforms=chain))
    early = len(harness.odometry)
    poses = [list(pose_of(harness.exchange(scan))) for scan in scans[3:]]
    print(json.dumps({{'early': early, 'poses': poses}}))
""")


@pytest.mark.skipif(not RECORDING.is_dir(), reason='no recording')
def test_the_mount_from_tf_static_gives_the_odometry_of_the_same_mount_as_parameters(
        child_environment):
    given = run_child(MOUNT_CHILD, child_environment, 'parameters')
    from_tf = run_child(MOUNT_CHILD, child_environment, 'tf')
    assert from_tf['early'] == 0                # the scans before the mount: left out
    assert len(from_tf['poses']) == len(given['poses']) == SCANS - 3
    np.testing.assert_allclose(from_tf['poses'], given['poses'], rtol=0.0, atol=1e-9)
    # The mount matters: the robot's track differs from the laser's.
    assert math.hypot(*given['poses'][-1][:2]) > 0.5


# The child: the wheel odometry as the transform odom -> base_link on /tf (a robot's wheel
# odometry node), scans without landmarks, the steps of the published Odometry.
WHEEL_CHILD = textwrap.dedent("""
    import json, math
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    from conftest import spin_until
    from test_odometry_node import (arc, empty_scan, Harness, pose_of, step_of,
                                    WHEEL_PARAMETERS, WHEEL_START_S)

    rclpy.init()
    executor = SingleThreadedExecutor()
    parameters = dict(WHEEL_PARAMETERS, wheel_odometry_topic='',
                      wheel_odometry_tf_frame='odom')
    harness = Harness(rclpy.get_default_context(), executor, parameters)
    tf = harness.peer.create_publisher(TFMessage, '/tf', 100)
    assert spin_until(executor, lambda: tf.get_subscription_count() > 0)
    transforms = []
    for k in range(51):
        moved = TransformStamped(child_frame_id='base_link')
        moved.header.frame_id = 'odom'
        moved.header.stamp.sec, moved.header.stamp.nanosec = divmod(
            round((WHEEL_START_S + 0.02 * k) * 1e9), 10 ** 9)
        x, y, yaw = arc(0.02 * k)
        moved.transform.translation.x, moved.transform.translation.y = x, y
        moved.transform.rotation.z, moved.transform.rotation.w = math.sin(yaw / 2), math.cos(
            yaw / 2)
        transforms.append(moved)
    # Another transform in the same message, of another frame: not the wheel's.
    other = TransformStamped(child_frame_id='camera')
    other.header.frame_id = 'base_link'
    tf.publish(TFMessage(transforms=transforms[:25] + [other]))
    tf.publish(TFMessage(transforms=transforms[25:]))
    kept = harness.node._wheel._stamps
    assert spin_until(executor, lambda: len(kept) == 51, timeout_s=10.0)
    stamps = [0.05 + 0.1 * k for k in range(10)]
    messages = [harness.exchange(empty_scan(t)) for t in stamps]
    steps = [list(step_of(messages[k], messages[k - 1])[0]) for k in range(1, len(messages))]
    print(json.dumps({'stamps': stamps, 'steps': steps, 'pose': list(pose_of(messages[-1]))}))
""")


def test_the_wheel_odometry_from_tf_gives_the_prior(child_environment):
    from test_odometry_node import arc
    from wctls_ros.frontend.odometry import compose, inverse
    result = run_child(WHEEL_CHILD, child_environment)
    stamps = result['stamps']
    assert len(result['steps']) == len(stamps) - 1
    for k, step in enumerate(result['steps'], start=1):
        assert np.allclose(step, compose(inverse(arc(stamps[k - 1])), arc(stamps[k])),
                           atol=5e-5)
    assert np.allclose(result['pose'], compose(inverse(arc(stamps[0])), arc(stamps[-1])),
                       atol=2e-4)
