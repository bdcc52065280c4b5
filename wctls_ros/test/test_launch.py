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
    'odometry.launch.py': {'params_file', 'scan_topic', 'sensor', 'publish_tf',
                           'wheel_odometry_topic', 'use_sim_time'},
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


def run_launch(path, arguments, ask, timeout_s=60.0):
    """
    Run a launch file with its arguments while ``ask(node, executor)`` asks from a thread.

    The launch service must run in the main thread; ``ask`` gets a node and executor of a
    context of its own, and the launch is shut down when it returns (or after timeout_s).

    :return: True when the launch ended by itself before ``ask`` returned
    """
    import threading

    from launch import LaunchDescription, LaunchService
    from launch.actions import IncludeLaunchDescription
    from launch.launch_description_sources import PythonLaunchDescriptionSource
    import rclpy
    service = LaunchService()
    service.include_launch_description(LaunchDescription([IncludeLaunchDescription(
        PythonLaunchDescriptionSource(str(path)), launch_arguments=arguments.items())]))
    ended = threading.Event()

    def asker():
        context = rclpy.context.Context()
        rclpy.init(context=context)
        try:
            node = rclpy.create_node('launch_test_client', context=context)
            executor = rclpy.executors.SingleThreadedExecutor(context=context)
            executor.add_node(node)
            ask(node, executor, ended)
        finally:
            rclpy.try_shutdown(context=context)
            service.shutdown()                      # thread-safe

    thread = threading.Thread(target=asker, daemon=True)
    thread.start()
    service.run()
    ended.set()
    thread.join(timeout_s)
    return not thread.is_alive()


def call(node, executor, service_type, name, request, timeout_s=20.0):
    """Return a service's answer, or None when it does not come within timeout_s."""
    client = node.create_client(service_type, name)
    if not client.wait_for_service(timeout_sec=timeout_s):
        return None
    future = client.call_async(request)
    executor.spin_until_future_complete(future, timeout_sec=10.0)
    return future.result()


def parameters(node, executor, names):
    """Return the values of feature_node's parameters named (None: it did not answer)."""
    from rcl_interfaces.srv import GetParameters
    answer = call(node, executor, GetParameters, '/feature_node/get_parameters',
                  GetParameters.Request(names=names))
    return None if answer is None else answer.values


def state_once_settled(node, executor, settle_s=30.0):
    """Return feature_node's lifecycle states, polled until active (the launch's are async)."""
    from lifecycle_msgs.srv import GetState
    states = []
    for _ in range(int(2 * settle_s)):
        answer = call(node, executor, GetState, '/feature_node/get_state', GetState.Request())
        if answer is None:
            break
        states.append(answer.current_state.label)
        if states[-1] == 'active':
            break
        executor.spin_once(timeout_sec=0.5)
    return states


@launch_ros_missing
@pytest.mark.parametrize('arguments,expected', [
    ({}, ['ml', 0.009]), ({'method': 'utls'}, ['utls', 0.009]),
    ({'sensor': 'rplidar_s1'}, ['ml', 0.02])])
def test_a_users_parameter_file_wins_unless_the_argument_is_given(tmp_path, arguments,
                                                                  expected):
    user_file = tmp_path / 'user.yaml'
    user_file.write_text('feature_node:\n  ros__parameters:\n    method: ml\n'
                         '    sensor: sick_lms1xx\n')
    answer = []

    def ask(node, executor, _):
        values = parameters(node, executor, ['method', 'range_sigma_m'])
        if values is not None:
            answer.extend([values[0].string_value, values[1].double_value])

    run_launch(PACKAGE / 'launch' / 'feature_node.launch.py',
               {'params_file': str(user_file), **arguments}, ask)
    assert answer == expected


@launch_ros_missing
@pytest.mark.parametrize('autostart_in', ['nowhere', 'the file', 'the argument'])
def test_the_launched_feature_node_becomes_active_whatever_its_autostart(
        tmp_path, autostart_in):
    # autostart false in the file or the argument: the launch file drives the transitions
    # (a plain Node would stay unconfigured).
    user_file = tmp_path / 'user.yaml'
    user_file.write_text('feature_node:\n  ros__parameters:\n    autostart: '
                         f'{str(autostart_in != "the file").lower()}\n')
    arguments = {'params_file': str(user_file)}
    if autostart_in == 'the argument':
        arguments['autostart'] = 'false'
    states = []
    run_launch(PACKAGE / 'launch' / 'feature_node.launch.py', arguments,
               lambda node, executor, _: states.extend(state_once_settled(node, executor)))
    assert states and states[-1] == 'active', states


@launch_ros_missing
def test_the_replay_runs_feature_node_active_on_the_bags_clock_until_the_bag_ends():
    bag = PACKAGE.parent / 'data' / 'sick_lms1xx_static'          # 89 scans, 1.8 s: 9 s here
    seen = {}

    def ask(node, executor, ended):
        seen['states'] = state_once_settled(node, executor)
        values = parameters(node, executor, ['use_sim_time'])
        seen['use_sim_time'] = None if values is None else values[0].bool_value
        seen['ended by itself'] = ended.wait(60.0)

    run_launch(PACKAGE / 'launch' / 'replay.launch.py',
               {'bag': str(bag), 'rate': '0.2', 'sensor': 'sick_lms1xx'}, ask, timeout_s=90.0)
    assert seen == {'states': seen['states'][:-1] + ['active'], 'use_sim_time': True,
                    'ended by itself': True}, seen


@launch_ros_missing
@pytest.mark.parametrize('with_feature_node', ['true', 'false'])
def test_the_s1_launch_starts_feature_node_only_when_asked(with_feature_node):
    # No S1 attached: the driver's lifecycle services answer all the same.
    from lifecycle_msgs.srv import GetState
    seen = {}

    def ask(node, executor, _):
        seen['driver'] = call(node, executor, GetState, '/rplidar_node/get_state',
                              GetState.Request()) is not None
        seen['feature_node'] = call(node, executor, GetState, '/feature_node/get_state',
                                    GetState.Request(), timeout_s=10.0) is not None

    run_launch(PACKAGE / 'launch' / 'rplidar_s1.launch.py',
               {'with_feature_node': with_feature_node, 'serial_port': '/dev/null'}, ask)
    assert seen == {'driver': True, 'feature_node': with_feature_node == 'true'}
