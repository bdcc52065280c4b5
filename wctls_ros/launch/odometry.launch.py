# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Launch odometry_node with its parameter file: ros2 launch wctls_ros odometry.launch.py.

For slam_toolbox on a robot without wheel odometry: odometry_node publishes nav_msgs/Odometry on
``odom`` and, with ``publish_tf:=true``, the TF odom -> base_link that slam_toolbox looks up
(its ``odom_frame`` odom, ``base_frame`` base_link); base_link -> laser must come from the
robot's description (robot_state_publisher or a static transform), and the laser's pose on the
robot is given to odometry_node in its parameter file (laser_x_m, laser_y_m, laser_yaw_deg), or
read from that transform on /tf_static with ``mount_from_tf: true``. Where the robot has wheel
odometry, ``wheel_odometry_topic:=<its nav_msgs/Odometry topic>`` makes its step the prior
(docs/odometry.md#with-slam_toolbox-and-robot_localization says who then publishes the TF).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from wctls_ros.launching import config_file, node, optional_argument
from wctls_ros.sensors import sensor_presets


def generate_launch_description():
    """
    Return the launch description.

    Arguments: params_file, scan_topic, sensor, publish_tf, wheel_odometry_topic, use_sim_time.
    """
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=config_file('odometry_node.yaml'),
                              description='odometry_node parameter file'),
        DeclareLaunchArgument('scan_topic', default_value='scan',
                              description='LaserScan topic to read'),
        optional_argument('sensor', 'sensor preset of the noise model: ' + ' | '.join(
            sensor_presets())),
        optional_argument('publish_tf', 'true: also publish the TF odom -> base_link (for '
                          'slam_toolbox; off where an EKF publishes it)'),
        optional_argument('wheel_odometry_topic', "the robot's wheel odometry "
                          '(nav_msgs/Odometry) whose step is the prior'),
        optional_argument('use_sim_time', 'use /clock, e.g. when a bag is replayed with it'),
        node('odometry_node', LaunchConfiguration('params_file'),
             arguments=[('sensor', 'sensor'), ('publish_tf', 'publish_tf'),
                        ('wheel_odometry_topic', 'wheel_odometry_topic'),
                        ('use_sim_time', 'use_sim_time')],
             remappings=[('scan', LaunchConfiguration('scan_topic'))]),
    ])
