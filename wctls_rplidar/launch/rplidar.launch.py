# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Start an RPLIDAR: ros2 launch wctls_rplidar rplidar.launch.py.

Arguments: params_file (default: the S1's, config/rplidar_s1.yaml), and serial_port,
channel_type, tcp_ip, frame_id and autostart, each passed over the file only when given.
With autostart false (given, or in the file) this file configures rplidar_node and activates it
once it is inactive, as ros2/demos' lifecycle launch files do; a failed configure leaves it
unconfigured, its reason in its log.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import LifecycleNode
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.substitutions import FindPackageShare
from lifecycle_msgs.msg import Transition
import yaml

# Parameters a launch argument of the same name overrides when given.
DRIVER_ARGUMENTS = (
    ('serial_port', 'serial device (e.g. the udev link /dev/rplidar)'),
    ('channel_type', 'serial or tcp'),
    ('tcp_ip', 'device address for channel_type tcp'),
    ('frame_id', 'frame of the scans'),
    ('autostart', 'true: rplidar_node activates itself; false: this launch file drives its '
                  'lifecycle transitions (configure, then activate)'),
)


def _start(context):
    """Return rplidar_node with the arguments given, and the transitions it needs."""
    params_file = LaunchConfiguration('params_file').perform(context)
    given = {name: LaunchConfiguration(name).perform(context) for name, _ in DRIVER_ARGUMENTS}
    given = {name: text for name, text in given.items() if text}
    if 'autostart' in given:
        given['autostart'] = given['autostart'].lower() == 'true'
        autostart = given['autostart']
    else:
        with open(params_file) as stream:
            document = yaml.safe_load(stream) or {}
        autostart = (document.get('rplidar_node', {}).get('ros__parameters', {})
                     .get('autostart', True))
    node = LifecycleNode(package='wctls_rplidar', executable='rplidar_node', name='rplidar_node',
                         namespace='', output='screen', parameters=[params_file, given])
    if autostart:
        return [node]

    def change_state(transition: int) -> EmitEvent:
        return EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(node),
                                           transition_id=transition))

    return [node,
            RegisterEventHandler(OnStateTransition(
                target_lifecycle_node=node, goal_state='inactive',
                entities=[change_state(Transition.TRANSITION_ACTIVATE)])),
            change_state(Transition.TRANSITION_CONFIGURE)]


def generate_launch_description():
    """Return the launch description: rplidar_node."""
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value='',
                                description=f'{description} (default: the parameter file)')
          for name, description in DRIVER_ARGUMENTS),
        DeclareLaunchArgument('params_file', default_value=PathJoinSubstitution(
            [FindPackageShare('wctls_rplidar'), 'config', 'rplidar_s1.yaml']),
            description='rplidar_node parameter file'),
        OpaqueFunction(function=_start),
    ])
