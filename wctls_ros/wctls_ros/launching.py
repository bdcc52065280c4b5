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

from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from .params import SCHEMAS

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
        given = {}
        for argument, parameter in arguments:
            text = LaunchConfiguration(argument).perform(context)
            if text:
                given[parameter] = _typed(executable, parameter, text)
        return [Node(package=PACKAGE, executable=executable, name=executable, output='screen',
                     parameters=[params_file, {**given, **(fixed or {})}],
                     remappings=list(remappings), **options)]
    return OpaqueFunction(function=start)
