# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Launch feature_node with its parameter file: ros2 launch wctls_ros feature_node.launch.py."""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    """Return the launch description: arguments params_file, scan_topic, method, use_sim_time."""
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file', description='feature_node parameter file',
            default_value=PathJoinSubstitution(
                [FindPackageShare('wctls_ros'), 'config', 'feature_node.yaml'])),
        DeclareLaunchArgument('scan_topic', default_value='scan',
                              description='LaserScan topic to read'),
        DeclareLaunchArgument('method', default_value='wctls',
                              description='line fit: utls | wtls | wctls | ml'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='use /clock (true when replaying a bag with --clock)'),
        Node(package='wctls_ros', executable='feature_node', name='feature_node',
             output='screen',
             parameters=[LaunchConfiguration('params_file'),
                         {'method': LaunchConfiguration('method'),
                          'use_sim_time': LaunchConfiguration('use_sim_time')}],
             remappings=[('scan', LaunchConfiguration('scan_topic'))]),
    ])
