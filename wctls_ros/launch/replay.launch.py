# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Replay a bag into feature_node: ros2 launch wctls_ros replay.launch.py bag:=<bag folder>."""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.substitutions import LaunchConfiguration
from wctls_ros.launching import config_file, lifecycle_node, node, optional_argument
from wctls_ros.sensors import sensor_presets


def generate_launch_description():
    """
    Return the launch description: bag_replay, and feature_node on the bag's clock.

    Arguments: bag, rate, loop (bag_replay's); sensor, method and params_file (feature_node's).
    """
    return LaunchDescription([
        DeclareLaunchArgument('bag', description='ROS 2 bag folder (or .mcap / .db3) or ROS 1 '
                                                 '.bag with sensor_msgs/LaserScan'),
        DeclareLaunchArgument('rate', default_value='1.0',
                              description='playback speed (bag seconds per wall second)'),
        DeclareLaunchArgument('loop', default_value='false',
                              description='start again at the end of the bag'),
        DeclareLaunchArgument('params_file', default_value=config_file('feature_node.yaml'),
                              description='feature_node parameter file'),
        optional_argument('sensor', 'feature_node sensor preset: ' + ' | '.join(
            sensor_presets())),
        optional_argument('method', 'feature_node line fit: utls | wtls | wctls | ml'),
        # Publishes the scans on /scan and the bag time on /clock; starts once feature_node
        # has subscribed, so no scan is lost; at the end of the bag everything stops.
        node('bag_replay', config_file('bag_replay.yaml'),
             arguments=[('bag', 'bag'), ('rate', 'rate'), ('loop', 'loop')],
             fixed={'publish_clock': True, 'wait_for_subscribers': 1},
             on_exit=Shutdown(reason='end of the bag')),
        # feature_node runs on the bag's clock, whatever its parameter file says.
        lifecycle_node('feature_node', LaunchConfiguration('params_file'),
                       arguments=[('sensor', 'sensor'), ('method', 'method')],
                       fixed={'use_sim_time': True}),
    ])
