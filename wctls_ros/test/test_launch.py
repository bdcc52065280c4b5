# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The launch files parse, declare documented arguments and start what exists.

launch / launch_ros are not on PyPI, so CI cannot run them: these tests read them as Python
syntax trees and check every executable, parameter file and included launch file they name
against the package (and build the launch descriptions when launch_ros is importable).
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
    'feature_node.launch.py': {'params_file', 'scan_topic', 'method', 'use_sim_time'},
    'replay.launch.py': {'bag', 'rate', 'loop'},
    'rplidar_s1.launch.py': {'serial_port', 'params_file', 'method', 'feature_params_file',
                             'with_feature_node'},
}


def calls(path, name):
    """Return the calls of a function or class named ``name`` in a launch file."""
    tree = ast.parse(path.read_text())
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call)
            and getattr(node.func, 'id', getattr(node.func, 'attr', None)) == name]


def keyword(call, name):
    return next((k.value for k in call.keywords if k.arg == name), None)


def test_every_launch_file_is_checked():
    assert {p.name for p in LAUNCH_FILES} == set(EXPECTED_ARGUMENTS)


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_declares_its_documented_arguments(path):
    declared = calls(path, 'DeclareLaunchArgument')
    names = set()
    for call in declared:
        name = call.args[0]
        names |= {name.value} if isinstance(name, ast.Constant) else set()
        assert keyword(call, 'description') is not None, f'{path.name}: undocumented argument'
    # Arguments declared from a table of (name, default, description) tuples count too.
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Tuple):
            names |= {ast.literal_eval(e)[0] for e in node.value.elts
                      if isinstance(e, ast.Tuple) and len(e.elts) == 3}
    assert EXPECTED_ARGUMENTS[path.name] <= names


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_starts_installed_executables_with_existing_files(path):
    for node in calls(path, 'Node'):
        assert keyword(node, 'package').value == 'wctls_ros'
        assert keyword(node, 'executable').value in CONSOLE_SCRIPTS
    for join in calls(path, 'PathJoinSubstitution'):
        parts = [e.value for e in join.args[0].elts if isinstance(e, ast.Constant)]
        assert (PACKAGE.joinpath(*parts)).is_file(), f'{path.name} names missing {parts}'


@pytest.mark.skipif(importlib.util.find_spec('launch_ros') is None,
                    reason='launch_ros is not installed (not on PyPI)')
@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_builds_a_launch_description(path):
    spec = importlib.util.spec_from_file_location(path.stem.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.generate_launch_description().entities
