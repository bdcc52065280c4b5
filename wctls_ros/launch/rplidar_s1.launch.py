# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Start an RPLIDAR S1 and the feature node: ros2 launch wctls_ros rplidar_s1.launch.py.

The driver is wctls_rplidar's rplidar.launch.py, included with its arguments: serial_port,
channel_type, tcp_ip, frame_id, autostart and params_file (each of the first five overrides the
file only when given: autostart false makes it configure and then activate the lifecycle node
rplidar_node); with_feature_node (default true), sensor
(default rplidar_s1: the S1's noise model, over the file's preset; '' keeps the file's), method
and feature_params_file (feature_node's).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.substitutions import FindPackageShare
from wctls_ros.launching import config_file, lifecycle_node, optional_argument
from wctls_ros.sensors import sensor_presets

DRIVER = 'wctls_rplidar'

# Driver parameters a launch argument of the same name overrides when given.
DRIVER_ARGUMENTS = (
    ('serial_port', 'serial device of the S1 (e.g. the udev link /dev/rplidar)'),
    ('channel_type', 'serial or tcp'),
    ('tcp_ip', 'device address for channel_type tcp'),
    ('frame_id', 'frame of the scans'),
    ('autostart', 'true: rplidar_node activates itself; false: this launch file drives its '
                  'lifecycle transitions (configure, then activate)'),
)


def generate_launch_description():
    """Return the launch description: rplidar_node, and feature_node on its scans."""
    return LaunchDescription([
        *(optional_argument(name, description) for name, description in DRIVER_ARGUMENTS),
        DeclareLaunchArgument('params_file', default_value=PathJoinSubstitution(
            [FindPackageShare(DRIVER), 'config', 'rplidar_s1.yaml']),
            description='rplidar_node parameter file'),
        DeclareLaunchArgument('with_feature_node', default_value='true',
                              description='also start feature_node on the scans'),
        DeclareLaunchArgument('sensor', default_value='rplidar_s1',
                              description="feature_node sensor preset ('' keeps the parameter "
                                          "file's): " + ' | '.join(sensor_presets())),
        optional_argument('method', 'feature_node line fit: utls | wtls | wctls | ml'),
        DeclareLaunchArgument('feature_params_file',
                              default_value=config_file('feature_node.yaml'),
                              description='feature_node parameter file'),
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(PathJoinSubstitution(
                [FindPackageShare(DRIVER), 'launch', 'rplidar.launch.py'])),
            launch_arguments=[(name, LaunchConfiguration(name))
                              for name, _ in (*DRIVER_ARGUMENTS, ('params_file', ''))]),
        lifecycle_node('feature_node', LaunchConfiguration('feature_params_file'),
                       arguments=[('sensor', 'sensor'), ('method', 'method')],
                       condition=IfCondition(LaunchConfiguration('with_feature_node'))),
    ])
