# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Replay a bag into feature_node: ros2 launch wctls_ros replay.launch.py bag:=<bag folder>."""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription, Shutdown
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    """
    Return the launch description: bag_replay, and feature_node on the bag's clock.

    Arguments: bag, rate, loop; and feature_node.launch.py's method and params_file.
    """
    return LaunchDescription([
        DeclareLaunchArgument('bag', description='ROS 2 bag folder (or .mcap / .db3) or ROS 1 '
                                                 '.bag with sensor_msgs/LaserScan'),
        DeclareLaunchArgument('rate', default_value='1.0',
                              description='playback speed (bag seconds per wall second)'),
        DeclareLaunchArgument('loop', default_value='false',
                              description='start again at the end of the bag'),
        # Publishes the scans on /scan and the bag time on /clock; starts once feature_node
        # has subscribed, so no scan is lost; at the end of the bag everything stops.
        Node(package='wctls_ros', executable='bag_replay', name='bag_replay', output='screen',
             on_exit=Shutdown(reason='end of the bag'),
             parameters=[{'bag': LaunchConfiguration('bag'),
                          'rate': ParameterValue(LaunchConfiguration('rate'), value_type=float),
                          'loop': ParameterValue(LaunchConfiguration('loop'), value_type=bool),
                          'publish_clock': True,
                          'wait_for_subscribers': 1}]),
        # feature_node with its parameter file and method (arguments params_file, method).
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(PathJoinSubstitution(
                [FindPackageShare('wctls_ros'), 'launch', 'feature_node.launch.py'])),
            launch_arguments={'use_sim_time': 'true'}.items()),
    ])
