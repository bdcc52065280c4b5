# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The codec's array-at-a-time builders give, field for field, what plain builders give.

The reference builders below fill one message field at a time from the features' records
(``features.corners[i]``), with math's own sin and cos and the 6x6 layout spelled out, in the
most obvious way. On every scan of the real recordings, for rclpy's and rosbags' classes, the
codec's messages must equal theirs; and the CDR bytes of either family must be the same, and
read back by rclpy and rosbags: feature_node publishes rosbags' bytes to rclpy subscribers.
"""

import dataclasses
import math

from conftest import REAL_DATA
import numpy as np
import pytest

pytest.importorskip('rclpy')

from rclpy.node import Node  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from rosbags.typesys import get_types_from_msg, get_typestore, Stores  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402
from wctls_msgs.msg import CornerArray  # noqa: E402
from wctls_ros.bags import read_scans, typestore  # noqa: E402
from wctls_ros.conversions import (copy_header, corner_array, laser_scan,  # noqa: E402
                                   line_segment_array, marker_array, MessageTypes,
                                   mismatched_types, scan_features)
from wctls_ros.core import (CornerSet, ellipse, Features, line_landmarks,  # noqa: E402
                            METHODS, SegmentSet)
from wctls_ros.params import feature_settings, load_parameters, MarkerStyle  # noqa: E402

RECORDINGS = ('urg04lx_office', 'sick_lms111_static', 'sick_lms1xx_static',
              'ros1/sick_lms1xx_static.bag')
# The rows and columns of x, y and yaw in a 6x6 (x, y, z, roll, pitch, yaw) covariance.
POSE_ROWS = (0, 1, 5)
# feature_node's default bound on a line landmark's angle std, deg.
LANDMARK_SIGMA_DEG = 3.0


def reference_corner_array(features, header, types):
    """Build a CornerArray one corner and one field at a time."""
    corners = []
    for i in range(len(features.corners)):
        corner = features.corners[i]
        first = features.segments[corner.first_segment]
        second = features.segments[corner.second_segment]
        covariance = np.zeros(36)
        for row in range(3):
            for column in range(3):
                covariance[6 * POSE_ROWS[row] + POSE_ROWS[column]] = \
                    corner.covariance[row, column]
        position = types.Point(x=corner.x_m, y=corner.y_m, z=0.0)
        orientation = types.Quaternion(x=0.0, y=0.0, z=math.sin(corner.yaw_rad / 2),
                                       w=math.cos(corner.yaw_rad / 2))
        pose = types.PoseWithCovariance(
            pose=types.Pose(position=position, orientation=orientation), covariance=covariance)
        corners.append(types.Corner(
            pose=pose, first_line=corner.first_segment, second_line=corner.second_segment,
            opening_angle=corner.opening_angle_rad, first_line_points=first.num_points,
            second_line_points=second.num_points,
            first_line_chi2_dof=first.residual_chi2_dof,
            second_line_chi2_dof=second.residual_chi2_dof,
            first_end_seen=corner.first_end_seen, second_end_seen=corner.second_end_seen))
    return types.CornerArray(header=header, method=features.method, corners=corners)


def reference_line_segment_array(features, header, types):
    """Build a LineSegmentArray one segment and one field at a time."""
    segments = []
    for i in range(len(features.segments)):
        segment = features.segments[i]
        covariance = np.array([segment.covariance[0, 0], segment.covariance[0, 1],
                               segment.covariance[1, 0], segment.covariance[1, 1]])
        segments.append(types.LineSegment(
            angle=segment.angle_rad, radius=segment.radius_m, covariance=covariance,
            start=types.Point(x=float(segment.start_xy_m[0]), y=float(segment.start_xy_m[1]),
                              z=0.0),
            end=types.Point(x=float(segment.end_xy_m[0]), y=float(segment.end_xy_m[1]), z=0.0),
            first_index=segment.first_index, last_index=segment.last_index,
            num_points=segment.num_points, residual_chi2_dof=segment.residual_chi2_dof,
            landmark=is_landmark(segment)))
    return types.LineSegmentArray(header=header, method=features.method, segments=segments)


def is_landmark(segment) -> bool:
    """Return whether a segment is a line landmark under feature_node's default bound."""
    return math.sqrt(segment.covariance[0, 0]) <= math.radians(LANDMARK_SIGMA_DEG)


def reference_marker_array(features, header, style, types):
    """Build the markers one marker and one field at a time, as the codec documents them."""
    Marker = types.Marker
    no_bytes = np.zeros(0, np.uint8)

    def marker(namespace, marker_id, kind, rgba, scale, xyz=(0.0, 0.0, 0.0), yaw=0.0,
               points=(), text='', action=Marker.ADD):
        return Marker(
            header=header, ns=namespace, id=marker_id, type=kind, action=action,
            pose=types.Pose(position=types.Point(x=xyz[0], y=xyz[1], z=xyz[2]),
                            orientation=types.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                         w=math.cos(yaw / 2))),
            scale=types.Vector3(x=scale[0], y=scale[1], z=scale[2]),
            color=types.ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
            lifetime=types.Duration(sec=0, nanosec=0), frame_locked=False,
            points=[types.Point(x=float(x), y=float(y), z=0.0) for x, y in points],
            colors=[], texture_resource='',
            texture=types.CompressedImage(
                header=types.Header(stamp=types.Time(sec=0, nanosec=0), frame_id=''),
                format='', data=no_bytes),
            uv_coordinates=[], text=text, mesh_resource='',
            mesh_file=types.MeshFile(filename='', data=no_bytes),
            mesh_use_embedded_materials=False)

    markers = [marker('', 0, Marker.ARROW, (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                      action=Marker.DELETEALL)]
    segments, corners = features.segments, features.corners
    # The line landmarks opaque, the other segments faint.
    for marker_id, (landmark, alpha) in enumerate(((True, 1.0), (False, 0.35))):
        ends = [end for segment in segments if is_landmark(segment) == landmark
                for end in (segment.start_xy_m, segment.end_xy_m)]
        if ends:
            markers.append(marker('segments', marker_id, Marker.LINE_LIST, (0.1, 0.5, 1.0, alpha),
                                  (style.line_width_m, 0.0, 0.0), points=ends))
    if not len(corners):
        return types.MarkerArray(markers=markers)
    size = style.corner_size_m
    markers.append(marker('corners', 0, Marker.SPHERE_LIST, (1.0, 0.2, 0.2, 1.0),
                          (size, size, size), points=corners.xy_m))
    diameter = 2.0 * style.ellipse_sigma * style.ellipse_scale
    for i in range(len(corners)):
        corner = corners[i]
        if style.text_ids:
            markers.append(marker('corner_ids', i, Marker.TEXT_VIEW_FACING, (1.0, 1.0, 1.0, 1.0),
                                  (0.0, 0.0, 2.0 * size), (corner.x_m, corner.y_m, 2.0 * size),
                                  text=str(i)))
        shape = ellipse(corner.covariance[:2, :2])
        markers.append(marker('ellipses', i, Marker.CYLINDER, (1.0, 0.6, 0.0, 0.5),
                              (diameter * float(shape.semi_major),
                               diameter * float(shape.semi_minor), 0.005),
                              (corner.x_m, corner.y_m, 0.0), float(shape.orientation_rad)))
    return types.MarkerArray(markers=markers)


def fields(message) -> dict:
    """Return a message's fields by name (rclpy or rosbags classes)."""
    if dataclasses.is_dataclass(message):
        return {f.name: getattr(message, f.name) for f in dataclasses.fields(message)}
    return {name: getattr(message, name) for name in message.get_fields_and_field_types()}


def assert_same(got, expected, where='message'):
    """
    Assert two messages hold the same values, field by field (rclpy or rosbags classes).

    Integers, booleans and strings must be equal and of the same type; floats too, to within
    the last bits that numpy's and math's sin and cos may round differently (a relative 1e-15;
    NaN equals NaN).
    """
    if isinstance(expected, (np.ndarray, list, tuple)) or type(expected).__name__ == 'array':
        got, expected = list(got), list(expected)
        assert len(got) == len(expected), where
        for index, (a, b) in enumerate(zip(got, expected)):
            assert_same(a, b, f'{where}[{index}]')
    elif isinstance(expected, (float, np.floating)):
        assert isinstance(got, (float, np.floating)), where
        assert (math.isnan(got) and math.isnan(expected)) or math.isclose(
            got, expected, rel_tol=1e-15, abs_tol=0.0), (where, got, expected)
    elif isinstance(expected, (bool, int, str)):
        assert type(got) is type(expected) and got == expected, (where, got, expected)
    else:
        assert type(got).__name__ == type(expected).__name__, (where, got, expected)
        got_fields, expected_fields = fields(got), fields(expected)
        assert got_fields.keys() == expected_fields.keys(), where
        for name, value in expected_fields.items():
            assert_same(got_fields[name], value, f'{where}.{name}')


def real_features(methods=('wctls',)):
    """Yield (scan, features) for every scan of the recordings, by each method."""
    config, _, _ = feature_settings(load_parameters(None))
    for recording in RECORDINGS:
        for record in read_scans(REAL_DATA / recording):
            for method in methods:
                features, problems = scan_features(record.scan, config.replace(method=method))
                assert not problems
                yield record.scan, features
    # A scan without features, as a malformed scan gives.
    yield record.scan, Features('wctls', SegmentSet.empty(), CornerSet.empty())


def landmarks(features):
    """Return the codec's landmark flags of a scan's segments (the core's rule)."""
    return line_landmarks(features.segments, math.radians(LANDMARK_SIGMA_DEG))


BUILDERS = [
    ('corners', corner_array, reference_corner_array),
    ('lines', lambda f, h, t: line_segment_array(f, h, t, is_landmark=landmarks(f)),
     reference_line_segment_array),
    ('markers', lambda f, h, t: marker_array(f, h, STYLE, t, is_landmark=landmarks(f)),
     lambda f, h, t: reference_marker_array(f, h, STYLE, t)),
    ('markers without ids',
     lambda f, h, t: marker_array(f, h, STYLE_WITHOUT_IDS, t, is_landmark=landmarks(f)),
     lambda f, h, t: reference_marker_array(f, h, STYLE_WITHOUT_IDS, t)),
]
STYLE = MarkerStyle(ellipse_sigma=2.0, ellipse_scale=3.0, text_ids=True)
STYLE_WITHOUT_IDS = MarkerStyle(text_ids=False)


@pytest.fixture(scope='module')
def families():
    """Return rclpy's and rosbags' message types."""
    return {'rclpy': MessageTypes.from_rclpy(),
            'rosbags': MessageTypes.from_typestore(typestore())}


def test_the_builders_give_what_plain_builders_give_on_real_recordings(families):
    counts = dict.fromkeys(['corners', 'segments', 'landmarks', 'scans'], 0)
    for scan, features in real_features():
        for family, types in families.items():
            header = copy_header(scan.header, types)
            for name, build, reference in BUILDERS:
                assert_same(build(features, header, types), reference(features, header, types),
                            f'{family} {name}')
        counts['scans'] += 1
        counts['corners'] += len(features.corners)
        counts['segments'] += len(features.segments)
        counts['landmarks'] += sum(is_landmark(segment) for segment in features.segments)
    assert counts['scans'] > 600 and counts['corners'] > 1000 and counts['segments'] > 3000
    # Both kinds of segment were built: the flag was checked either way.
    assert 0.5 * counts['segments'] < counts['landmarks'] < counts['segments']


def test_every_method_builds_what_plain_builders_give(families):
    types = families['rosbags']
    scans = 0
    for scan, features in real_features(METHODS):
        header = copy_header(scan.header, types)
        for name, build, reference in BUILDERS[:2]:
            assert_same(build(features, header, types), reference(features, header, types), name)
        scans += 1
        if scans >= 4 * 40:
            break


@pytest.mark.parametrize('wrong', ['one too few', 'one too many', 'a scalar', 'a column'])
@pytest.mark.parametrize('build', [line_segment_array, marker_array])
def test_landmark_flags_that_are_not_one_per_segment_are_refused(families, build, wrong):
    scan, features = next((scan, features) for scan, features in real_features()
                          if len(features.segments) >= 3)
    count = len(features.segments)
    flags = landmarks(features)
    # Each of these once indexed the wrong segments, or all or none, without a word.
    flags = {'one too few': flags[:-1], 'one too many': np.append(flags, True),
             'a scalar': True, 'a column': flags[:, None]}[wrong]
    types = families['rosbags']
    with pytest.raises(ValueError, match=f'landmark flags for {count} segments'):
        build(features, copy_header(scan.header, types), types, is_landmark=flags)


def test_either_familys_bytes_read_back_alike_in_rclpy_and_rosbags(families):
    rclpy_types, rosbags_types = families['rclpy'], families['rosbags']
    store = typestore()
    read = 0
    for index, (scan, features) in enumerate(real_features()):
        if index % 7:                           # every 7th scan: the bytes cost more to check
            continue
        for name, build, _ in BUILDERS:
            # What an rclpy subscriber receives from feature_node (rosbags' bytes) is what it
            # would receive from rclpy's classes; the bytes differ only in CDR padding, which
            # rclpy leaves unset. A bag reader (rosbags) reads either alike too.
            built = build(features, copy_header(scan.header, rosbags_types), rosbags_types)
            published = rosbags_types.serialize(built)
            sent_by_rclpy = rclpy_types.serialize(
                build(features, copy_header(scan.header, rclpy_types), rclpy_types))
            assert len(published) == len(sent_by_rclpy), name
            kind = getattr(rclpy_types, built.__msgtype__.rsplit('/', 1)[1])
            assert_same(deserialize_message(published, kind),
                        deserialize_message(sent_by_rclpy, kind), name)
            assert_same(store.deserialize_cdr(published, built.__msgtype__),
                        store.deserialize_cdr(sent_by_rclpy, built.__msgtype__), name)
            read += 1
    assert read > 4 * 90


def test_laser_scans_copy_between_families_unchanged(families):
    record = next(read_scans(REAL_DATA / 'urg04lx_office'))
    copies = {family: laser_scan(record.scan, types) for family, types in families.items()}
    assert_same(copies['rclpy'], deserialize_message(
        families['rosbags'].serialize(copies['rosbags']), type(copies['rclpy'])))
    assert len(copies['rclpy'].ranges) == 681


def test_a_typestore_whose_definitions_differ_is_told_apart(ros_context):
    node = Node('hash_probe', context=ros_context)
    for kind, topic in ((CornerArray, 'corners'), (MarkerArray, 'markers')):
        node.create_publisher(kind, topic, 10)
    published = {info.topic_type: str(info.topic_type_hash)
                 for topic in ('/corners', '/markers')
                 for info in node.get_publishers_info_by_topic(topic)}
    assert sorted(published) == ['visualization_msgs/msg/MarkerArray',
                                 'wctls_msgs/msg/CornerArray']
    assert mismatched_types(typestore(), published) == []
    # The wctls_msgs of an older release, whose corners lacked a field.
    older = get_typestore(Stores.ROS2_JAZZY)
    for path in (REAL_DATA.parent / 'wctls_msgs' / 'msg').glob('*.msg'):
        definition = path.read_text()
        if path.stem == 'Corner':
            assert 'bool second_end_seen' in definition
            definition = definition.replace('bool second_end_seen', '')
        older.register(get_types_from_msg(definition, f'wctls_msgs/msg/{path.stem}'))
    assert mismatched_types(older, published) == ['wctls_msgs/msg/CornerArray']
    assert mismatched_types(older, {'unknown_msgs/msg/Thing': 'RIHS01_00'}) == [
        'unknown_msgs/msg/Thing']
    node.destroy_node()
