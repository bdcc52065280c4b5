# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""rplidar_node's parameters: the shipped file, the documented table and the descriptors agree."""

import pathlib

import pytest
from wctls_rplidar.parameters import markdown_table, PARAMETERS
import yaml

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]


def test_the_shipped_file_sets_every_parameter_at_its_default():
    path = REPOSITORY / 'wctls_rplidar' / 'config' / 'rplidar_s1.yaml'
    written = yaml.safe_load(path.read_text())['rplidar_node']['ros__parameters']
    assert written == {parameter.name: parameter.default for parameter in PARAMETERS}


def test_the_user_guide_shows_the_table_of_the_parameters():
    guide = (REPOSITORY / 'docs' / 'user_guide.md').read_text()
    block = guide.split('<!-- params:rplidar_node -->\n', 1)[1].split(
        '<!-- /params:rplidar_node -->', 1)[0]
    assert block.strip() == markdown_table(), (
        'regenerate it with python -m wctls_rplidar.parameters')


def test_each_parameter_is_declared_with_its_range_and_refused_outside_it(ros_context):
    from rclpy.exceptions import ParameterException
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from wctls_rplidar.parameters import declare_all
    node = Node('rplidar_parameters', context=ros_context)
    try:
        values = declare_all(node)
        assert values == {parameter.name: parameter.default for parameter in PARAMETERS}
        described = node.describe_parameters([parameter.name for parameter in PARAMETERS])
        assert all(descriptor.read_only for descriptor in described)
        rate = next(d for d in described if d.name == 'scan_frequency')
        assert (rate.floating_point_range[0].from_value,
                rate.floating_point_range[0].to_value) == (5.0, 20.0)
    finally:
        node.destroy_node()
    too_fast = Node('rplidar_parameters_refused', context=ros_context,
                    parameter_overrides=[Parameter('scan_frequency', value=40.0)])
    try:
        with pytest.raises(ParameterException):
            declare_all(too_fast)
    finally:
        too_fast.destroy_node()
