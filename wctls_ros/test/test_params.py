# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The one parameter schema: derived from FeatureConfig, checked like rclpy, free of rclpy."""

import dataclasses
import math
import os
import pathlib
import subprocess
import sys

from hypothesis import given, settings, strategies
import pytest
from wctls_ros.core import FeatureConfig
from wctls_ros.params import (BAG_REPLAY, ConfigError, FEATURE_NODE, feature_settings,
                              load_parameters, markdown_table, SCHEMAS)
from wctls_ros.sensors import DEFAULT_SENSOR, PRESET_PARAMETERS, sensor_presets
import yaml

BY_NAME = {parameter.name: parameter for parameter in FEATURE_NODE}


def test_every_pipeline_setting_is_a_parameter_with_the_core_default():
    # ... except the noise model, whose default is the default sensor preset's (test_sensors).
    settings_of = {p.setting: p for p in FEATURE_NODE if p.setting}
    for field in dataclasses.fields(FeatureConfig):
        parameter = settings_of[field.name]
        if parameter.name in PRESET_PARAMETERS:
            continue
        core_default = getattr(FeatureConfig(), field.name)
        if isinstance(core_default, str):
            assert parameter.default == core_default
        else:
            assert parameter.to_setting(parameter.default) == pytest.approx(core_default,
                                                                            rel=1e-6)


def test_angles_are_parameters_in_degrees_with_the_limits_converted():
    lam = BY_NAME['breakpoint_lambda_deg']
    assert lam.setting == 'breakpoint_lambda_rad' and lam.default == 10.0
    assert (lam.limits.low, lam.limits.high) == (0.0, 90.0)
    assert lam.limits.low_open and lam.limits.high_open
    assert BY_NAME['bearing_sigma_deg'].limits.high == pytest.approx(10.0)


def test_names_are_unique_in_every_schema():
    for schema in SCHEMAS.values():
        names = [parameter.name for parameter in schema]
        assert len(names) == len(set(names))


def _values_of(parameter):
    """Values around and beyond a numeric parameter's limits, and ones of other types."""
    low, high = parameter.limits.low, parameter.limits.high
    finite_high = high if math.isfinite(high) else 1e12
    numbers = [low, high, low - 1e-9 - abs(low) * 1e-9, finite_high * (1 + 1e-9) + 1e-9,
               (low + finite_high) / 2, -1.0, 0.0, math.nan]
    if isinstance(parameter.default, int):
        return [int(v) for v in numbers if math.isfinite(v)] + [2.5, True]
    return numbers + ['1', True]


@pytest.mark.parametrize('parameter', [p for p in FEATURE_NODE if p.limits and p.setting
                                       in FeatureConfig.__dataclass_fields__],
                         ids=lambda p: p.name)
def test_a_parameter_value_passes_its_check_exactly_when_the_core_accepts_it(parameter):
    # One statement of each limit: the core's FeatureConfig and the parameter schema agree on
    # every value (range_min_m is checked against range_max_m as well, so it is left high).
    for value in _values_of(parameter):
        try:
            parameter.check(value)
            schema_ok = True
        except ConfigError:
            schema_ok = False
        changes = {parameter.setting: parameter.to_setting(value) if schema_ok else value}
        if parameter.name == 'range_max_m':
            changes['range_min_m'] = 0.0
        # The range noise may not exceed its plausibility bound: each is checked with the
        # other out of the way.
        if parameter.name == 'range_sigma_m':
            changes['max_range_sigma_m'] = 100.0
        if parameter.name == 'max_range_sigma_m' and schema_ok:
            changes['range_sigma_m'] = min(changes['max_range_sigma_m'], 0.001)
        try:
            FeatureConfig().replace(**changes)
            core_ok = True
        except (ValueError, TypeError):
            core_ok = False
        if parameter.name == 'range_min_m' and schema_ok and value == math.inf:
            continue
        assert schema_ok == core_ok, (parameter.name, value)


@settings(max_examples=200, deadline=None)
@given(strategies.floats(allow_nan=False, allow_infinity=False, min_value=-10, max_value=200))
def test_degree_parameters_refuse_what_the_radian_fields_refuse(degrees):
    for parameter in FEATURE_NODE:
        if not parameter.name.endswith('_deg') or parameter.setting is None:
            continue            # a node's own degrees, no FeatureConfig field
        try:
            parameter.check(degrees)
            schema_ok = True
        except ConfigError:
            schema_ok = False
        try:
            FeatureConfig().replace(**{parameter.setting: math.radians(degrees)})
            core_ok = True
        except ValueError:
            core_ok = False
        # Converting to radians may move a value that sits on a limit across it by one ulp.
        on_limit = min(abs(degrees - parameter.limits.low),
                       abs(degrees - parameter.limits.high)) < 1e-9
        assert schema_ok == core_ok or on_limit, (parameter.name, degrees)


def test_settings_name_the_parameter_and_its_unit_when_refusing():
    values = load_parameters(None)
    values['breakpoint_lambda_deg'] = 90.0
    values['iepf_threshold_m'] = 0.0
    with pytest.raises(ConfigError) as refused:
        feature_settings(values)
    assert 'breakpoint_lambda_deg = 90.0 is outside its range (0, 90)' in str(refused.value)
    assert 'iepf_threshold_m = 0.0 is outside its range (0, 10]' in str(refused.value)


def test_settings_refuse_a_rule_between_two_values():
    values = load_parameters(None, overrides={'range_min_m': 5.0, 'range_max_m': 4.0})
    with pytest.raises(ValueError, match=r'range_min_m \(5\) must be below range_max_m \(4\)'):
        feature_settings(values)


def test_defaults_build_the_default_configuration_with_the_default_sensor_model():
    config, style, publish_markers = feature_settings(load_parameters(None))
    generic = sensor_presets()[DEFAULT_SENSOR].parameters
    assert config == FeatureConfig(
        range_sigma_m=generic['range_sigma_m'], range_sigma_from_scan=generic[
            'range_sigma_from_scan'], common_range_sigma_m=generic[
            'common_range_sigma_m'], bearing_sigma_rad=math.radians(generic['bearing_sigma_deg']),
        model_error_sigma_m=generic['model_error_sigma_m'],
        wall_flatness_sigma_m=generic['wall_flatness_sigma_m'])
    assert publish_markers


def test_a_parameter_file_is_read_from_its_node_section_over_wildcards(tmp_path):
    path = tmp_path / 'params.yaml'
    path.write_text('/**:\n  ros__parameters:\n    method: ml\n    iepf_threshold_m: 0.05\n'
                    'feature_node:\n  ros__parameters:\n    method: wtls\n'
                    'other_node:\n  ros__parameters:\n    anything: 1\n')
    values = load_parameters(path)
    assert values['method'] == 'wtls' and values['iepf_threshold_m'] == 0.05


@pytest.mark.parametrize('text,reason', [
    ('feature_node:\n  ros__parameters:\n    range_sigma_m: fast\n',
     'range_sigma_m must be of type double'),
    ('feature_node:\n  ros__parameters:\n    min_segment_points: 8.5\n',
     'min_segment_points must be of type integer'),
    ('feature_node:\n  ros__parameters:\n    min_segment_points: 2\n',
     'min_segment_points = 2 is outside its range [3, 100000]'),
    ('feature_node:\n  ros__parameters:\n    method: tls\n', 'method must be one of'),
    ('feature_node:\n  ros__parameters:\n    iepf_treshold_m: 0.04\n',
     "unknown feature_node parameters ['iepf_treshold_m']"),
    ('feature_node: 3\n', "section 'feature_node' has no ros__parameters mapping"),
    ('bag_replay:\n  ros__parameters:\n    rate: 2.0\n', 'has no parameters for'),
    ('[1, 2]\n', 'is not a ROS 2 parameter file'),
    ('feature_node: {ros__parameters: {method: [wctls\n', 'cannot read the parameter file'),
])
def test_a_parameter_file_the_node_would_refuse_is_refused_with_the_reason(tmp_path, text,
                                                                           reason):
    path = tmp_path / 'params.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError, match=None) as refused:
        load_parameters(path)
    assert reason in str(refused.value)


def test_the_other_nodes_files_are_checked_with_their_own_schemas(tmp_path):
    path = tmp_path / 'params.yaml'
    path.write_text('bag_replay:\n  ros__parameters:\n    rate: 500.0\n')
    with pytest.raises(ConfigError, match=r'rate = 500.0 is outside its range'):
        load_parameters(path, 'bag_replay')
    assert load_parameters(None, 'bag_replay')['rate'] == 1.0
    assert {p.name for p in BAG_REPLAY if not p.read_only} == {'rate', 'loop'}


def test_the_markdown_table_has_one_row_per_parameter_with_escaped_pipes():
    table = markdown_table(FEATURE_NODE).splitlines()
    assert len(table) == 2 + len(FEATURE_NODE)
    method = next(row for row in table if row.startswith('| `method`'))
    assert method.count(' | ') == 4 and 'utls \\| wtls \\| wctls \\| ml' in method


def test_the_schema_and_the_parameter_files_never_import_rclpy():
    code = ('import sys, wctls_ros.params as p; p.load_parameters(None); '
            'print(sorted(m for m in sys.modules if m.split(".")[0] in '
            '("rclpy", "rcl_interfaces", "sensor_msgs", "wctls_msgs")))')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.strip() == '[]'


@pytest.mark.parametrize('node_name,file_name', [('feature_node', 'feature_node.yaml'),
                                                 ('bag_replay', 'bag_replay.yaml'),
                                                 ('odometry_node', 'odometry_node.yaml')])
def test_each_shipped_parameter_file_sets_every_parameter_at_its_default(node_name, file_name):
    # ... except the noise model, which the file leaves to its sensor preset (commented out).
    path = pathlib.Path(__file__).resolve().parents[1] / 'config' / file_name
    written = yaml.safe_load(path.read_text())[node_name]['ros__parameters']
    names = {parameter.name for parameter in SCHEMAS[node_name]}
    if node_name in ('feature_node', 'odometry_node'):
        names -= set(PRESET_PARAMETERS)
        for name in PRESET_PARAMETERS:
            assert f'# {name}: ' in path.read_text()
    assert set(written) == names
    assert load_parameters(path, node_name) == pytest.approx(load_parameters(None, node_name))


def test_a_fifo_or_a_folder_as_the_parameter_file_is_refused_at_once(tmp_path):
    # Opening a FIFO waits for a writer: process_bag -c FIFO hung, and SIGTERM (which it turns
    # into a request to stop between two scans) could not end it.
    os.mkfifo(tmp_path / 'fifo.yaml')
    code = ('import sys; from wctls_ros.params import ConfigError, load_parameters\n'
            'for path in sys.argv[1:]:\n'
            '    try:\n'
            '        load_parameters(path)\n'
            '    except ConfigError as error:\n'
            '        print(error)\n')
    done = subprocess.run([sys.executable, '-c', code, str(tmp_path / 'fifo.yaml'),
                           str(tmp_path)], capture_output=True, text=True, timeout=20)
    lines = done.stdout.splitlines()
    assert len(lines) == 2 and all('not a regular file' in line for line in lines), done
