# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Start the RPLIDAR S1 driver with config/rplidar_s1.yaml, and optionally the feature node."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

# Launch arguments that override the YAML file: (name, default, description).
ARGUMENTS = (
    ('channel_type', 'serial', 'serial or tcp'),
    ('serial_port', '/dev/ttyUSB0', 'serial device of the S1'),
    ('tcp_ip', '192.168.0.7', 'device address for channel_type tcp'),
    ('frame_id', 'laser', 'frame of the scans'),
)


def generate_launch_description():
    """Return the launch description: rplidar_node, plus feature_node on request."""
    config = os.path.join(get_package_share_directory('wctls_ros'), 'config', 'rplidar_s1.yaml')
    declared = [DeclareLaunchArgument(name, default_value=default, description=description)
                for name, default, description in ARGUMENTS]
    declared.append(DeclareLaunchArgument(
        'with_feature_node', default_value='false',
        description='also start feature_node on the scans'))
    driver = Node(package='wctls_ros', executable='rplidar_node', name='rplidar_node',
                  output='screen',
                  parameters=[config, {name: LaunchConfiguration(name)
                                       for name, _, _ in ARGUMENTS}])
    features = Node(package='wctls_ros', executable='feature_node', name='feature_node',
                    output='screen',
                    condition=IfCondition(LaunchConfiguration('with_feature_node')))
    return LaunchDescription(declared + [driver, features])
