# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The markers draw what the features say, drawn by matplotlib the way RViz draws them.

RViz draws a CYLINDER as a cylinder of diameters scale.x and scale.y along its pose's x and y
axes; seen from above, a flat one is an ellipse. A LINE_LIST joins its points two by two, a
SPHERE_LIST puts a dot at each point, a TEXT_VIEW_FACING marker writes its text at its pose. The
picture is checked with matplotlib's own geometry: every corner's drawn ellipse must be its
k-sigma covariance ellipse, (p - c)^T C^-1 (p - c) = (k * magnification)^2 on the outline.
"""

import math

from conftest import REAL_DATA
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse
import numpy as np
import pytest
from wctls_ros.bags import read_scans, typestore
from wctls_ros.conversions import laser_scan, marker_array, MessageTypes, scan_features
from wctls_ros.core import line_landmarks
from wctls_ros.params import feature_settings, load_parameters, MarkerStyle

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

ANGLES = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
UNIT_CIRCLE = np.column_stack([np.cos(ANGLES), np.sin(ANGLES)])


def yaw_of(quaternion) -> float:
    """Return the rotation about z of a quaternion that only turns about z."""
    assert quaternion.x == 0.0 and quaternion.y == 0.0
    return 2.0 * math.atan2(quaternion.z, quaternion.w)


def render(markers, axes) -> dict:
    """Draw a MarkerArray from above as RViz does; return (namespace, id) -> what was drawn."""
    Marker = type(markers.markers[0])
    drawn = {}
    for marker in markers.markers:
        if marker.action == Marker.DELETEALL:
            drawn.clear()
            continue
        assert marker.action == Marker.ADD
        position, color = marker.pose.position, marker.color
        rgba = (color.r, color.g, color.b, color.a)
        if marker.type == Marker.CYLINDER:
            artist = axes.add_patch(Ellipse(
                (position.x, position.y), marker.scale.x, marker.scale.y,
                angle=math.degrees(yaw_of(marker.pose.orientation)), color=rgba))
        elif marker.type == Marker.LINE_LIST:
            points = [(p.x, p.y) for p in marker.points]
            artist = axes.add_collection(LineCollection(
                [points[i:i + 2] for i in range(0, len(points), 2)], colors=[rgba]))
        elif marker.type == Marker.SPHERE_LIST:
            artist = axes.scatter([p.x for p in marker.points], [p.y for p in marker.points],
                                  color=rgba)
        elif marker.type == Marker.TEXT_VIEW_FACING:
            artist = axes.text(position.x, position.y, marker.text, color=rgba)
        else:
            raise AssertionError(f'a marker type RViz draws differently: {marker.type}')
        drawn[(marker.ns, marker.id)] = artist
    return drawn


def office_features(count=40):
    """
    Yield (scan, features, line landmark flags) for office scans with corners.

    A hand-held sensor, real noise; the flags by feature_node's default bound.
    """
    config, _, _ = feature_settings(load_parameters(None))
    for record in list(read_scans(REAL_DATA / 'urg04lx_office'))[:count]:
        features, problems = scan_features(record.scan, config)
        assert not problems
        if len(features.corners):
            yield record.scan, features, line_landmarks(features.segments,
                                                        config.max_landmark_angle_sigma_rad)


@pytest.mark.parametrize('kind', ['rosbags', 'rclpy'])
@pytest.mark.parametrize('text_ids', [True, False])
def test_each_ellipse_is_drawn_with_the_axes_and_orientation_of_its_covariance(
        kind, text_ids, tmp_path):
    if kind == 'rclpy':
        pytest.importorskip('rclpy')
        types = MessageTypes.from_rclpy()
    else:
        types = MessageTypes.from_typestore(typestore())
    style = MarkerStyle(ellipse_sigma=2.0, ellipse_scale=10.0, text_ids=text_ids)
    ellipses = other_segments = 0
    for scan, features, is_landmark in office_features():
        scan = laser_scan(scan, types)
        figure = Figure()
        axes = figure.add_subplot()
        drawn = render(marker_array(features, scan.header, style, types,
                                    is_landmark=is_landmark), axes)
        axes.set_aspect('equal')
        axes.autoscale_view()
        figure.savefig(tmp_path / 'markers.png')         # the picture renders
        corners, segments = features.corners, features.segments
        # The line landmarks opaque (id 0), the other segments faint (id 1, when there are).
        kinds = [(0, is_landmark)] + ([(1, ~is_landmark)] if not is_landmark.all() else [])
        expected = {('segments', marker_id) for marker_id, _ in kinds} | {('corners', 0)}
        expected |= {(namespace, i) for i in range(len(corners))
                     for namespace in ('ellipses',) + (('corner_ids',) if text_ids else ())}
        assert set(drawn) == expected
        for marker_id, kind in kinds:
            lines = drawn[('segments', marker_id)]
            # rclpy's ColorRGBA holds float32.
            assert lines.get_colors()[0][3] == pytest.approx(1.0 if marker_id == 0 else 0.35,
                                                             rel=1e-6)
            ends = lines.get_segments()
            assert np.allclose([line[0] for line in ends], segments.start_xy_m[kind])
            assert np.allclose([line[1] for line in ends], segments.end_xy_m[kind])
        other_segments += len(kinds) - 1
        assert np.allclose(drawn[('corners', 0)].get_offsets(), corners.xy_m)
        for i, (xy, covariance) in enumerate(zip(corners.xy_m, corners.covariance)):
            if text_ids:
                label = drawn[('corner_ids', i)]
                assert label.get_text() == str(i) and np.allclose(label.get_position(), xy)
            # The outline as drawn, in metres: the patch's own transform of its unit circle.
            outline = drawn[('ellipses', i)].get_patch_transform().transform(UNIT_CIRCLE)
            offsets = outline - xy
            quadratic = np.einsum('ni,ij,nj->n', offsets, np.linalg.inv(covariance[:2, :2]),
                                  offsets)
            k = style.ellipse_sigma * style.ellipse_scale
            assert np.allclose(quadratic, k * k, rtol=1e-6), (i, quadratic, k * k)
            ellipses += 1
    assert ellipses > 100 and other_segments > 0
