# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Start an RPLIDAR S1 and the feature node: ros2 launch wctls_ros rplidar_s1.launch.py.

Arguments: serial_port, channel_type, tcp_ip, frame_id (the driver's, over params_file);
with_feature_node (default true), method and feature_params_file (feature_node's).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

# Driver arguments that override the parameter file: (name, default, description).
DRIVER_ARGUMENTS = (
    ('serial_port', '/dev/ttyUSB0', 'serial device of the S1 (e.g. the udev link /dev/rplidar)'),
    ('channel_type', 'serial', 'serial or tcp'),
    ('tcp_ip', '192.168.0.7', 'device address for channel_type tcp'),
    ('frame_id', 'laser', 'frame of the scans'),
)


def generate_launch_description():
    """Return the launch description: rplidar_node, and feature_node on its scans."""
    share = FindPackageShare('wctls_ros')
    declared = [DeclareLaunchArgument(name, default_value=default, description=description)
                for name, default, description in DRIVER_ARGUMENTS]
    declared += [
        DeclareLaunchArgument('params_file', description='rplidar_node parameter file',
                              default_value=PathJoinSubstitution(
                                  [share, 'config', 'rplidar_s1.yaml'])),
        DeclareLaunchArgument('with_feature_node', default_value='true',
                              description='also start feature_node on the scans'),
        DeclareLaunchArgument('method', default_value='wctls',
                              description='feature_node line fit: utls | wtls | wctls | ml'),
        DeclareLaunchArgument('feature_params_file', description='feature_node parameter file',
                              default_value=PathJoinSubstitution(
                                  [share, 'config', 'feature_node.yaml'])),
    ]
    driver = Node(package='wctls_ros', executable='rplidar_node', name='rplidar_node',
                  output='screen',
                  parameters=[LaunchConfiguration('params_file'),
                              {name: LaunchConfiguration(name)
                               for name, _, _ in DRIVER_ARGUMENTS}])
    features = IncludeLaunchDescription(
        PythonLaunchDescriptionSource(PathJoinSubstitution(
            [share, 'launch', 'feature_node.launch.py'])),
        condition=IfCondition(LaunchConfiguration('with_feature_node')),
        launch_arguments={'method': LaunchConfiguration('method'),
                          'params_file': LaunchConfiguration('feature_params_file')}.items())
    return LaunchDescription(declared + [driver, features])
