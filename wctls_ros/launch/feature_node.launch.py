# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Launch feature_node with its parameter file: ros2 launch wctls_ros feature_node.launch.py."""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from wctls_ros.launching import config_file, lifecycle_node, optional_argument
from wctls_ros.sensors import sensor_presets


def generate_launch_description():
    """
    Return the launch description.

    Arguments: params_file, scan_topic, sensor, method, use_sim_time, autostart.
    """
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=config_file('feature_node.yaml'),
                              description='feature_node parameter file'),
        DeclareLaunchArgument('scan_topic', default_value='scan',
                              description='LaserScan topic to read'),
        optional_argument('sensor', 'sensor preset of the noise model: ' + ' | '.join(
            sensor_presets())),
        optional_argument('method', 'line fit: utls | wtls | wctls | ml'),
        optional_argument('use_sim_time', 'use /clock, e.g. when a bag is replayed with it'),
        optional_argument('autostart', 'true: feature_node activates itself; false: this launch '
                          'file drives its lifecycle transitions (configure, then activate)'),
        lifecycle_node('feature_node', LaunchConfiguration('params_file'),
                       arguments=[('sensor', 'sensor'), ('method', 'method'),
                                  ('use_sim_time', 'use_sim_time'), ('autostart', 'autostart')],
                       remappings=[('scan', LaunchConfiguration('scan_topic'))]),
    ])
