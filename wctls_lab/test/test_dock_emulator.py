# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""A dock through the whole chain: the S1 emulator on a pty, rplidar_node, feature_node."""

import math

from conftest import spin_until
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from emulator_process import EmulatorProcess  # noqa: E402, I100
from geometry_msgs.msg import PoseWithCovarianceStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from test_frontend_dock import APEX, dock_outline, true_dock  # noqa: E402
from wctls_lab.simulation import floor_plan_from_dict  # noqa: E402
from wctls_ros.feature_node import FeatureNode  # noqa: E402
from wctls_ros.frontend.dock import DockShape, wrap_angle  # noqa: E402
from wctls_rplidar.rplidar_node import RplidarNode  # noqa: E402
import yaml  # noqa: E402

# Runs an emulator and nodes against deadlines; among the slowest modules.
pytestmark = [pytest.mark.slow, pytest.mark.realtime]

# 1 m in front of the dock, which stands against the east wall of environment A.
POSE = (APEX[0] - 1.0, APEX[1], 0.0)


def node(kind, context, **parameters):
    return kind(context=context, use_global_arguments=False, parameter_overrides=[
        Parameter(name, value=value) for name, value in parameters.items()])


def test_the_emulated_s1_sees_the_dock_where_it_stands(ros_context, executor, tmp_path):
    spec = {'name': 'environment_a_dock', 'base': 'environment_a',
            'polylines': [{'closed': True, 'points': dock_outline(DockShape())}]}
    (tmp_path / 'plan.yaml').write_text(yaml.safe_dump(spec))
    # The emulator's scene frame is rplidar_node's default laser frame (sllidar's).
    truth = true_dock(floor_plan_from_dict(spec), POSE, DockShape())
    poses = []
    with EmulatorProcess(['--link', str(tmp_path / 'ttyS1'), '--floor-plan',
                          str(tmp_path / 'plan.yaml'), '--pose', str(POSE[0]), str(POSE[1]),
                          '0', '--seed', '5'], startup_timeout_s=60.0,
                         module='wctls_lab.simulated_rplidar') as device:
        driver = node(RplidarNode, ros_context, serial_port=device.link)
        features = node(FeatureNode, ros_context, sensor='rplidar_s1', dock_enabled=True)
        listener = rclpy.create_node('listener', context=ros_context)
        listener.create_subscription(PoseWithCovarianceStamped,
                                     'detected_dock_pose_with_covariance', poses.append, 10)
        for each in (driver, features, listener):
            executor.add_node(each)
        assert spin_until(executor, lambda: len(poses) >= 8, 60.0), f'{len(poses)} poses'
    assert {pose.header.frame_id for pose in poses} == {'laser'}
    for pose in poses:
        position, q = pose.pose.pose.position, pose.pose.pose.orientation
        error = np.array([position.x - truth[0], position.y - truth[1],
                          wrap_angle(2 * math.atan2(q.z, q.w) - truth[2])])
        covariance = np.array(pose.pose.covariance).reshape(6, 6)[np.ix_([0, 1, 5], [0, 1, 5])]
        # The turns' boundaries follow the emulator's clock: each pose is judged by its own
        # covariance (99.9 % bound, 3 dof), and within a few cm.
        assert error @ np.linalg.solve(covariance, error) < 16.3
        assert math.hypot(*error[:2]) < 0.05
