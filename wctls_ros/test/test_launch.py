# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The launch files parse, declare documented arguments and start what exists.

launch / launch_ros are not on PyPI, so CI cannot run them: these tests read them as Python
syntax trees and check every executable, parameter file and argument they name against the
package; where launch_ros is importable they also build the launch descriptions, list their
arguments as ``--show-args`` does, and run feature_node.launch.py against a user's file.
"""

import ast
import importlib.util
import pathlib
import re

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1]
LAUNCH_FILES = sorted((PACKAGE / 'launch').glob('*.launch.py'))
CONSOLE_SCRIPTS = set(re.findall(r"'(\w+) = wctls_ros[\w.]*:\w+'",
                                 (PACKAGE / 'setup.py').read_text()))
EXPECTED_ARGUMENTS = {
    'feature_node.launch.py': {'params_file', 'scan_topic', 'sensor', 'method', 'use_sim_time',
                               'autostart'},
    'odometry.launch.py': {'params_file', 'scan_topic', 'sensor', 'publish_tf', 'use_sim_time'},
    'replay.launch.py': {'bag', 'rate', 'loop', 'params_file', 'sensor', 'method'},
    'rplidar_s1.launch.py': {'serial_port', 'channel_type', 'tcp_ip', 'frame_id', 'autostart',
                             'params_file', 'sensor', 'method', 'feature_params_file',
                             'with_feature_node'},
}
# Launch arguments that set a parameter which the node's parameter file also sets: passed only
# when given, so that a user's file is never silently overridden by a launch default...
FILE_PARAMETERS = {'sensor', 'method', 'use_sim_time', 'serial_port', 'channel_type', 'tcp_ip',
                   'frame_id', 'autostart', 'publish_tf'}
# ... except where the launch file is about one sensor (documented in its --show-args).
DELIBERATE_DEFAULTS = {('rplidar_s1.launch.py', 'sensor'): 'rplidar_s1'}
launch_ros_missing = pytest.mark.skipif(importlib.util.find_spec('launch_ros') is None,
                                        reason='launch_ros is not installed (not on PyPI)')


def calls(path, name):
    """Return the calls of a function or class named ``name`` in a launch file."""
    tree = ast.parse(path.read_text())
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call)
            and getattr(node.func, 'id', getattr(node.func, 'attr', None)) == name]


def keyword(call, name):
    return next((k.value for k in call.keywords if k.arg == name), None)


def test_every_launch_file_is_checked():
    assert {p.name for p in LAUNCH_FILES} == set(EXPECTED_ARGUMENTS)


def declared_arguments(path):
    """Return {name: default} of the arguments a launch file declares (None: no default)."""
    declared = {}
    for call in calls(path, 'DeclareLaunchArgument'):
        assert keyword(call, 'description') is not None, f'{path.name}: undocumented argument'
        if not isinstance(call.args[0], ast.Constant):
            continue                    # declared from a table, read below
        default = keyword(call, 'default_value')
        declared[call.args[0].value] = (default.value if isinstance(default, ast.Constant)
                                        else None if default is None else 'a substitution')
    for call in calls(path, 'optional_argument'):
        if isinstance(call.args[0], ast.Constant):
            declared[call.args[0].value] = ''
    # Arguments declared from a table of (name, description) tuples count too.
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Tuple):
            declared |= {ast.literal_eval(e)[0]: '' for e in node.value.elts
                         if isinstance(e, ast.Tuple) and len(e.elts) == 2}
    return declared


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_declares_its_documented_arguments(path):
    assert set(declared_arguments(path)) == EXPECTED_ARGUMENTS[path.name]


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_arguments_that_a_parameter_file_sets_are_passed_only_when_given(path):
    declared = declared_arguments(path)
    for name in FILE_PARAMETERS & set(declared):
        expected = DELIBERATE_DEFAULTS.get((path.name, name), '')
        assert declared[name] == expected, f'{path.name}: {name} has a default over the file'


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_starts_installed_executables_with_existing_files(path):
    started = calls(path, 'node') + calls(path, 'lifecycle_node')
    assert started
    for call in started:
        assert call.args[0].value in CONSOLE_SCRIPTS
    for call in calls(path, 'config_file'):
        assert (PACKAGE / 'config' / call.args[0].value).is_file(), call.args[0].value


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_feature_node_is_started_as_a_lifecycle_node(path):
    # As a plain Node, autostart false would leave it unconfigured: no launch transitions.
    assert 'feature_node' not in [call.args[0].value for call in calls(path, 'node')]
    started = [call.args[0].value for call in calls(path, 'lifecycle_node')]
    assert started == ([] if path.name == 'odometry.launch.py' else ['feature_node'])


def test_the_rplidar_driver_is_started_as_a_lifecycle_node_by_its_own_launch_file():
    # Its autostart false needs the launch file to drive the configure and activate transitions.
    driver = PACKAGE.parent / 'wctls_rplidar' / 'launch' / 'rplidar.launch.py'
    started = calls(driver, 'LifecycleNode')
    assert [keyword(call, 'executable').value for call in started] == ['rplidar_node']
    transitions = {node.attr for node in ast.walk(ast.parse(driver.read_text()))
                   if isinstance(node, ast.Attribute) and node.attr.startswith('TRANSITION_')}
    assert transitions == {'TRANSITION_CONFIGURE', 'TRANSITION_ACTIVATE'}
    assert calls(driver, 'OnStateTransition') and calls(driver, 'ChangeState')
    assert set(declared_arguments(driver)) == {name for name in EXPECTED_ARGUMENTS[
        'rplidar_s1.launch.py'] if name not in ('sensor', 'method', 'feature_params_file',
                                                'with_feature_node')}
    # The S1 launch file includes it, passing the driver's arguments on.
    included, = calls(PACKAGE / 'launch' / 'rplidar_s1.launch.py', 'IncludeLaunchDescription')
    assert 'rplidar.launch.py' in ast.unparse(included)


@launch_ros_missing
@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_builds_a_launch_description_that_shows_only_its_own_arguments(path):
    spec = importlib.util.spec_from_file_location(path.stem.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    # What `ros2 launch ... --show-args` lists: included files' arguments used to leak in.
    shown = {argument.name for argument in description.get_launch_arguments()}
    assert shown == EXPECTED_ARGUMENTS[path.name]


@launch_ros_missing
@pytest.mark.parametrize('arguments,expected', [
    ({}, ['ml', 0.009]), ({'method': 'utls'}, ['utls', 0.009]),
    ({'sensor': 'rplidar_s1'}, ['ml', 0.02])])
def test_a_users_parameter_file_wins_unless_the_argument_is_given(tmp_path, arguments,
                                                                  expected):
    import threading

    from launch import LaunchDescription, LaunchService
    from launch.actions import IncludeLaunchDescription
    from launch.launch_description_sources import PythonLaunchDescriptionSource
    import rclpy
    from rcl_interfaces.srv import GetParameters
    user_file = tmp_path / 'user.yaml'
    user_file.write_text('feature_node:\n  ros__parameters:\n    method: ml\n'
                         '    sensor: sick_lms1xx\n')
    service = LaunchService()
    service.include_launch_description(LaunchDescription([IncludeLaunchDescription(
        PythonLaunchDescriptionSource(str(PACKAGE / 'launch' / 'feature_node.launch.py')),
        launch_arguments={'params_file': str(user_file), **arguments}.items())]))
    answer = []

    def ask_the_node():
        # The launch service must run in the main thread; the question is asked from this one.
        context = rclpy.context.Context()
        rclpy.init(context=context)
        try:
            client_node = rclpy.create_node('launch_test_client', context=context)
            client = client_node.create_client(GetParameters, '/feature_node/get_parameters')
            if client.wait_for_service(timeout_sec=20.0):
                future = client.call_async(GetParameters.Request(
                    names=['method', 'range_sigma_m']))
                executor = rclpy.executors.SingleThreadedExecutor(context=context)
                executor.add_node(client_node)
                executor.spin_until_future_complete(future, timeout_sec=10.0)
                method, sigma = future.result().values
                answer.extend([method.string_value, sigma.double_value])
        finally:
            rclpy.try_shutdown(context=context)
            service.shutdown()                      # thread-safe

    asker = threading.Thread(target=ask_the_node)
    asker.start()
    service.run()
    asker.join()
    assert answer == expected


@launch_ros_missing
@pytest.mark.parametrize('autostart', ['', 'false'])
def test_the_launched_feature_node_becomes_active_with_autostart_either_way(autostart):
    import threading

    from launch import LaunchDescription, LaunchService
    from launch.actions import IncludeLaunchDescription
    from launch.launch_description_sources import PythonLaunchDescriptionSource
    from lifecycle_msgs.srv import GetState
    import rclpy
    service = LaunchService()
    service.include_launch_description(LaunchDescription([IncludeLaunchDescription(
        PythonLaunchDescriptionSource(str(PACKAGE / 'launch' / 'feature_node.launch.py')),
        launch_arguments={'autostart': autostart}.items())]))
    states = []

    def watch_the_state():
        context = rclpy.context.Context()
        rclpy.init(context=context)
        try:
            client_node = rclpy.create_node('launch_test_client', context=context)
            client = client_node.create_client(GetState, '/feature_node/get_state')
            executor = rclpy.executors.SingleThreadedExecutor(context=context)
            executor.add_node(client_node)
            if client.wait_for_service(timeout_sec=20.0):
                # The launch's transitions are asynchronous: poll until active or 30 s.
                for _ in range(60):
                    future = client.call_async(GetState.Request())
                    executor.spin_until_future_complete(future, timeout_sec=5.0)
                    states.append(future.result().current_state.label)
                    if states[-1] == 'active':
                        break
                    executor.spin_once(timeout_sec=0.5)
        finally:
            rclpy.try_shutdown(context=context)
            service.shutdown()                      # thread-safe

    watcher = threading.Thread(target=watch_the_state)
    watcher.start()
    service.run()
    watcher.join()
    assert states and states[-1] == 'active', states
