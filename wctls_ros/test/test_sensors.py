# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Sensor presets: each number sourced, the preset sets defaults, and what a user sets wins."""

import math
import pathlib
import re
import subprocess

import pytest
from wctls_ros.params import ConfigError, FEATURE_NODE, feature_settings, load_parameters
from wctls_ros.sensors import (DEFAULT_SENSOR, PRESET_PARAMETERS, PresetError, sensor_presets,
                               SensorPreset)

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
BY_NAME = {parameter.name: parameter for parameter in FEATURE_NODE}
BASES = re.compile(r'datasheet|measured|measurement|assumed|not published')
# What the issue asks for, at least.
REQUIRED = {'rplidar_s1', 'sick_lms1xx', 'sick_tim5xx_7xx', 'hokuyo_urg04lx', 'hokuyo_utm30lx',
            'generic', 'rplidar_a1', 'rplidar_a2', 'rplidar_a3', 'rplidar_c1'}


def test_every_required_sensor_has_a_preset_whose_numbers_each_have_a_source():
    presets = sensor_presets()
    assert REQUIRED <= set(presets) and DEFAULT_SENSOR in presets
    for preset in presets.values():
        assert preset.description
        for name in PRESET_PARAMETERS:
            BY_NAME[name].check(preset.parameters[name])      # within the node's ranges
            # Each source says what kind it is: a datasheet, our measurement, or an assumption.
            assert BASES.search(preset.sources[name]), (preset.name, name)


def _listed(text: str, introduction: str, end: str) -> set:
    """Return the names listed between ``introduction`` and ``end`` in a text."""
    listed = text.split(introduction, 1)[1].split(end, 1)[0]
    return set(re.findall(r'[a-z][a-z0-9_]+', listed.replace('#', ' ')))


def test_the_preset_lists_of_the_readme_and_the_parameter_file_are_the_presets():
    presets = set(sensor_presets())
    readme = (REPOSITORY / 'README.md').read_text()
    assert _listed(readme, 'noise model preset:', '([') == presets
    node_file = (REPOSITORY / 'wctls_ros' / 'config' / 'feature_node.yaml').read_text()
    assert _listed(node_file, 'a preset of config/sensors (', ')') == presets


def test_the_preset_table_of_sensors_md_has_every_preset_with_its_numbers():
    rows = {}
    for line in (REPOSITORY / 'docs' / 'sensors.md').read_text().split(
            '| preset | range sigma |', 1)[1].splitlines()[2:]:
        if not line.startswith('| `'):
            break
        cells = [cell.strip() for cell in line.strip('|').split('|')]
        rows[re.match(r'`(\w+)`', cells[0])[1]] = cells
    presets = sensor_presets()
    assert set(rows) == set(presets)
    for name, (_, range_sigma, from_scan, bearing, common, _) in rows.items():
        values = presets[name].parameters
        assert float(range_sigma.split()[0]) == pytest.approx(1e3 * values['range_sigma_m']), name
        assert (from_scan == 'yes') == values['range_sigma_from_scan'], name
        assert float(bearing.split()[0]) == pytest.approx(values['bearing_sigma_deg']), name
        common_mm = 0.0 if common == '0' else float(common.split()[0])
        assert common_mm == pytest.approx(1e3 * values['common_range_sigma_m']), name


def test_the_triangulating_rplidars_follow_their_range_noise_scan_by_scan():
    # The core has one range sigma per scan: the nearest equivalent of the A-series' noise
    # growing with distance is to estimate it from each scan, never a fixed figure.
    presets = sensor_presets()
    for name in ('rplidar_a1', 'rplidar_a2', 'rplidar_a3'):
        assert presets[name].parameters['range_sigma_from_scan'] is True, name
        assert 'distance' in presets[name].sources['range_sigma_from_scan'], name


@pytest.mark.parametrize('text,reason', [
    ('parameters: {range_sigma_m: 0.01, bearing_sigma_deg: 0.1}\nsources: {}\n', 'exactly'),
    ('parameters: {range_sigma_m: 0.01, range_sigma_from_scan: false, bearing_sigma_deg: 0.1,'
     ' common_range_sigma_m: 0, model_error_sigma_m: 0.01, wall_flatness_sigma_m: 0}\n'
     'sources: {range_sigma_m: datasheet, bearing_sigma_deg: measured}\n', 'source of each'),
    ('parameters: {range_sigma_m: 0.01, range_sigma_from_scan: false, bearing_sigma_deg: 0.1,'
     ' common_range_sigma_m: 0, model_error_sigma_m: -1, wall_flatness_sigma_m: 0}\n'
     'sources: {range_sigma_m: a, range_sigma_from_scan: b, bearing_sigma_deg: c,'
     ' common_range_sigma_m: d, model_error_sigma_m: e, wall_flatness_sigma_m: f}\n', '>= 0'),
])
def test_a_preset_without_a_number_or_its_source_is_refused(tmp_path, text, reason):
    path = tmp_path / 'mine.yaml'
    path.write_text(text)
    with pytest.raises(PresetError, match=reason):
        SensorPreset.from_file(path)


def test_the_preset_sets_the_noise_model_and_a_given_value_still_wins(tmp_path):
    lms = sensor_presets()['sick_lms1xx'].parameters
    values = load_parameters(None, overrides={'sensor': 'sick_lms1xx'})
    assert {name: values[name] for name in PRESET_PARAMETERS} == lms
    config = feature_settings(values).config
    assert config.bearing_sigma_rad == pytest.approx(math.radians(lms['bearing_sigma_deg']))
    # A parameter file's sigma wins over its own sensor's, wherever it is written.
    path = tmp_path / 'params.yaml'
    path.write_text('feature_node:\n  ros__parameters:\n    range_sigma_m: 0.03\n'
                    '    sensor: rplidar_s1\n')
    values = load_parameters(path)
    s1 = sensor_presets()['rplidar_s1'].parameters
    assert values['range_sigma_m'] == 0.03
    assert values['bearing_sigma_deg'] == s1['bearing_sigma_deg']
    with pytest.raises(ConfigError, match="sensor must be one of .*'generic'.*got 'lms'"):
        load_parameters(None, overrides={'sensor': 'lms'})


def test_the_node_takes_its_defaults_from_the_preset(ros_context):
    pytest.importorskip('rclpy')
    from rclpy.parameter import Parameter
    from wctls_ros.feature_node import FeatureNode
    lms = sensor_presets()['sick_lms1xx'].parameters
    for overrides, expected in (({'sensor': 'sick_lms1xx'}, lms['range_sigma_m']),
                                ({'sensor': 'sick_lms1xx', 'range_sigma_m': 0.02}, 0.02),
                                ({}, sensor_presets()[DEFAULT_SENSOR].parameters[
                                    'range_sigma_m'])):
        node = FeatureNode(context=ros_context, use_global_arguments=False,
                           parameter_overrides=[Parameter(k, value=v)
                                                for k, v in overrides.items()])
        try:
            assert node.get_parameter('range_sigma_m').value == expected
            assert node.get_parameter('common_range_sigma_m').value == pytest.approx(
                sensor_presets()[overrides.get('sensor', DEFAULT_SENSOR)].parameters[
                    'common_range_sigma_m'])
            assert node.describe_parameter('sensor').read_only
        finally:
            node.destroy_node()


def test_the_installed_node_refuses_an_unknown_sensor_in_one_line():
    pytest.importorskip('rclpy')
    from test_feature_node import installed_executable
    result = subprocess.run([str(installed_executable('feature_node')), '--ros-args', '-p',
                             'sensor:=sick'], capture_output=True, text=True, timeout=30)
    lines = (result.stdout + result.stderr).splitlines()
    assert result.returncode == 1 and len(lines) == 1, lines
    assert 'sensor must be one of' in lines[0] and "got 'sick'" in lines[0]
