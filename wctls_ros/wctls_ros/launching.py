# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
What the launch files share: nodes whose launch arguments override their parameter file.

A launch argument left empty ('') is not passed, so the node keeps the value of its parameter
file (a user's YAML is never silently overridden by a launch default); a given one is typed by
the node's parameter schema (:mod:`wctls_ros.params`), so ``rate:=2`` reaches a double parameter
as 2.0. Nodes are created when the launch runs (an OpaqueFunction), so a launch file shows
exactly its own arguments in ``ros2 launch ... --show-args``. Imports launch and launch_ros:
only the launch files use this module.
"""

from typing import Dict, Iterable, Tuple

from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch.utilities import perform_substitutions
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.substitutions import FindPackageShare
from lifecycle_msgs.msg import Transition

from .params import ConfigError, defaults, load_parameters, SCHEMAS

PACKAGE = 'wctls_ros'
# Parameters every rclpy node has besides its schema's.
_BUILT_IN = {'use_sim_time': False}


def config_file(name: str) -> PathJoinSubstitution:
    """
    Return the installed path of one of the package's configuration files.

    :param name: e.g. 'feature_node.yaml'
    :return: the substitution
    """
    return PathJoinSubstitution([FindPackageShare(PACKAGE), 'config', name])


def optional_argument(name: str, description: str) -> DeclareLaunchArgument:
    """
    Declare a launch argument that is passed to its node only when given.

    :param name: the argument name
    :param description: what it sets
    :return: the declaration (default '': the parameter file's value)
    """
    return DeclareLaunchArgument(name, default_value='',
                                 description=f'{description} (default: the parameter file)')


def _typed(node_name: str, parameter: str, text: str):
    """Turn a launch argument's text into the parameter's type from the node's schema."""
    schema = {row.name: row.default for row in SCHEMAS[node_name]}
    default = schema.get(parameter, _BUILT_IN.get(parameter))
    if isinstance(default, bool):
        if text.lower() not in ('true', 'false'):
            raise ValueError(f'{parameter} must be true or false, got {text!r}')
        return text.lower() == 'true'
    if isinstance(default, (int, float)):
        return type(default)(float(text) if isinstance(default, float) else int(text))
    return text


def node(executable: str, params_file, arguments: Iterable[Tuple[str, str]] = (),
         fixed: Dict[str, object] = None, remappings=(), **options) -> OpaqueFunction:
    """
    Start one of the package's nodes with its parameter file and the given launch arguments.

    :param executable: the node's executable, also its name and its schema's key
    :param params_file: the parameter file (a path or a substitution)
    :param arguments: (launch argument, parameter) pairs passed when the argument is not ''
    :param fixed: parameters always set, over the file (e.g. use_sim_time for a replay)
    :param remappings: (from, to) topic remappings, substitutions allowed
    :param options: more Node options (condition, on_exit, ...)
    :return: the action
    """
    def start(context):
        given = _given(context, executable, arguments)
        return [Node(package=PACKAGE, executable=executable, name=executable, output='screen',
                     parameters=[params_file, {**given, **(fixed or {})}],
                     remappings=list(remappings), **options)]
    return OpaqueFunction(function=start)


def lifecycle_node(executable: str, params_file, arguments: Iterable[Tuple[str, str]] = (),
                   fixed: Dict[str, object] = None, remappings=(),
                   **options) -> OpaqueFunction:
    """
    Start one of the package's lifecycle nodes; drive it to active when it does not itself.

    The node's ``autostart`` (the launch argument mapped to it when given, else its parameter
    file's) decides: true, the node configures and activates itself; false, the launch emits
    the configure transition, and activate once the node is inactive (as ros2/demos'
    lifecycle launch files do), so a failed configure leaves it unconfigured, its reason in
    its log.

    :param executable: the node's executable, also its name and its schema's key
    :param params_file: the parameter file (a path or a substitution)
    :param arguments: (launch argument, parameter) pairs passed when the argument is not ''
    :param fixed: parameters always set, over the file (e.g. use_sim_time for a replay)
    :param remappings: (from, to) topic remappings, substitutions allowed
    :param options: options of the whole action (e.g. condition: no node and no transitions
        when false)
    :return: the action
    """
    def start(context):
        given = {**_given(context, executable, arguments), **(fixed or {})}
        path = (params_file if isinstance(params_file, str)
                else perform_substitutions(context, [params_file]))
        autostart = given.get('autostart', _file_value(path, executable, 'autostart'))
        # LifecycleNode needs a namespace: '' puts the node and its lifecycle services at the
        # root, as a plain Node started by these files was.
        node = LifecycleNode(package=PACKAGE, executable=executable, name=executable,
                             namespace='', output='screen', parameters=[params_file, given],
                             remappings=list(remappings))
        if autostart:
            return [node]

        def change_state(transition: int) -> EmitEvent:
            return EmitEvent(event=ChangeState(
                lifecycle_node_matcher=matches_action(node), transition_id=transition))

        return [node,
                RegisterEventHandler(OnStateTransition(
                    target_lifecycle_node=node, goal_state='inactive',
                    entities=[change_state(Transition.TRANSITION_ACTIVATE)])),
                change_state(Transition.TRANSITION_CONFIGURE)]
    return OpaqueFunction(function=start, **options)


def _given(context, executable: str, arguments: Iterable[Tuple[str, str]]) -> dict:
    """Return the node's parameters set by the launch arguments given (not ''), typed."""
    given = {}
    for argument, parameter in arguments:
        text = LaunchConfiguration(argument).perform(context)
        if text:
            given[parameter] = _typed(executable, parameter, text)
    return given


def _file_value(path: str, executable: str, name: str):
    """
    Return a parameter's value in a node's parameter file, else its default.

    A file the node would warn about (an unknown name) or refuse is the node's to report, in
    its own log: the launch goes on with the default.
    """
    try:
        return load_parameters(path, executable)[name]
    except ConfigError:
        return defaults(SCHEMAS[executable])[name]
