# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The .msg files parse as ROS IDL and document every field."""

import pathlib
import re

import pytest

MSG_DIR = pathlib.Path(__file__).resolve().parents[1] / 'msg'
MSG_FILES = sorted(MSG_DIR.glob('*.msg'))
# A comment documents a unit when it names one of these (or says the field has none).
UNIT_PATTERN = re.compile(r'\b(m|rad|m\^2|rad\^2|index|indices|number|count)\b'
                          r'|Indices|Number|Dimensionless')
NUMERIC_TYPES = ('float32', 'float64', 'int32', 'uint32', 'geometry_msgs/Point',
                 'geometry_msgs/PoseWithCovariance')


def _fields_with_comments(path):
    """
    Yield each field declaration of a .msg file with the comment block just above it.

    Fields declared on consecutive lines share the comment above the first of them.

    :param path: the .msg file
    :return: iterator of (type, name, comment text)
    """
    comment, in_fields = [], False
    for line in path.read_text().splitlines():
        stripped = line.strip()
        if stripped.startswith('#'):
            if in_fields:
                comment, in_fields = [], False
            comment.append(stripped.lstrip('#').strip())
        elif stripped and '=' not in stripped:      # a constant is no field
            field_type, name = stripped.split()[:2]
            in_fields = True
            yield field_type, name, ' '.join(comment)
        else:
            comment, in_fields = [], False


def test_the_designed_messages_exist():
    assert [p.stem for p in MSG_FILES] == [
        'Corner', 'CornerArray', 'Landmark', 'LandmarkArray', 'LineSegment', 'LineSegmentArray']


@pytest.mark.parametrize('path', MSG_FILES, ids=lambda p: p.name)
def test_every_field_is_commented(path):
    for field_type, name, comment in _fields_with_comments(path):
        assert comment, f'{path.name}: field {name} has no comment'
        if field_type.startswith(NUMERIC_TYPES):
            assert UNIT_PATTERN.search(comment), f'{path.name}: field {name} names no unit'


@pytest.mark.parametrize('path', MSG_FILES, ids=lambda p: p.name)
def test_parses_as_ros_idl(path):
    parser = pytest.importorskip('rosidl_adapter.parser')
    spec = parser.parse_message_file('wctls_msgs', str(path))
    declared = [name for _, name, _ in _fields_with_comments(path)]
    assert [f.name for f in spec.fields] == declared
