# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The bridges against the message types built here from their published definitions.

rtabmap_msgs and cartographer_ros_msgs are not installed here (nor needed by the package):
their types are built in this test alone, with rosbags, from the definitions rtabmap_ros and
Jazzy's cartographer_ros publish (the fields below), and each bridge's message is serialised
and read back as a consumer would. RTAB-Map gets the confirmed corners with ids > 0 and their
(x, y, yaw) covariance, z, roll and pitch unobserved (a large variance, not 0); Cartographer
the confirmed corners in its tracking frame with weights 1/sigma; PoseArray every detection.
Empty scans give empty messages; a bridge whose package is missing is left out in one line.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from wctls_ros.bridges import (bridge_classes, cartographer_landmarks, cartographer_weights,
                               load_bridges, pose_array, rtabmap_detections,
                               UNOBSERVED_VARIANCE)
from wctls_ros.frontend.tracking import CONFIRMED, Detections, Motion, Tracker

# The fields of the published definitions (rtabmap_ros rtabmap_msgs/msg; ros2/cartographer_ros
# cartographer_ros_msgs/msg, the one Jazzy releases).
DEFINITIONS = {
    'rtabmap_msgs/msg/LandmarkDetection': 'std_msgs/Header header\nstring landmark_frame_id\n'
                                          'int32 id\nfloat32 size\n'
                                          'geometry_msgs/PoseWithCovariance pose\n',
    'rtabmap_msgs/msg/LandmarkDetections': 'std_msgs/Header header\n'
                                           'rtabmap_msgs/LandmarkDetection[] landmarks\n',
    'cartographer_ros_msgs/msg/LandmarkEntry': (
        'string id\ngeometry_msgs/Pose tracking_from_landmark_transform\n'
        'float64 translation_weight\nfloat64 rotation_weight\n'),
    'cartographer_ros_msgs/msg/LandmarkList': 'std_msgs/Header header\n'
                                              'cartographer_ros_msgs/LandmarkEntry[] landmark\n',
}


@pytest.fixture(scope='module')
def store():
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def classes_of(store, *names):
    return {name.rsplit('/', 1)[1]: store.types[name] for name in names}


def geometry(store):
    return SimpleNamespace(**classes_of(store, 'geometry_msgs/msg/Pose', 'geometry_msgs/msg/Point',
                                        'geometry_msgs/msg/Quaternion',
                                        'geometry_msgs/msg/PoseWithCovariance'))


def header(store):
    kinds = store.types
    stamp = kinds['builtin_interfaces/msg/Time'](sec=5, nanosec=7)
    return kinds['std_msgs/msg/Header'](stamp=stamp, frame_id='laser')


def round_trip(store, message):
    return store.deserialize_cdr(store.serialize_cdr(message, message.__msgtype__),
                                 message.__msgtype__)


def tracked_scan():
    """Return a scan's detections and tracks: two confirmed corners, a new one, a line."""
    corner_cov = np.array([[4e-4, 1e-4, 2e-5], [1e-4, 9e-4, -3e-5], [2e-5, -3e-5, 1e-3]])
    steady = np.array([[2.0, 1.0, 0.3], [-1.0, 3.0, -2.0]])
    tracker = Tracker()
    for _ in range(3):
        tracker.update(Detections(steady, np.tile(corner_cov, (2, 1, 1)), np.zeros((0, 2)),
                                  np.zeros((0, 2, 2)), np.zeros((0, 2, 2))), Motion.still())
    corners = np.vstack([steady, [[0.5, -2.0, 1.0]]])
    line = np.array([[0.5, 3.0]])
    detections = Detections(corners, np.tile(corner_cov, (3, 1, 1)), line,
                            np.diag([1e-4, 4e-4])[None],
                            np.array([[[2.0, 2.0], [3.0, 0.5]]]))
    return detections, tracker.update(detections, Motion.still())


def test_rtabmap_gets_the_confirmed_corners_with_their_covariance(store):
    detections, tracked = tracked_scan()
    assert list(tracked.corners.states) == [CONFIRMED, CONFIRMED, 0]
    message = round_trip(store, rtabmap_detections(
        detections, tracked, header(store), geometry(store),
        classes_of(store, 'rtabmap_msgs/msg/LandmarkDetections',
                   'rtabmap_msgs/msg/LandmarkDetection')))
    assert message.header.frame_id == 'laser'
    assert [m.id for m in message.landmarks] == list(tracked.corners.ids[:2])
    for mark, pose, cov in zip(message.landmarks, detections.corner_pose,
                               detections.corner_cov):
        assert mark.id > 0 and mark.header.frame_id == 'laser' and mark.size == 0.0
        assert mark.pose.pose.position.x == pytest.approx(pose[0])
        assert 2 * math.atan2(mark.pose.pose.orientation.z,
                              mark.pose.pose.orientation.w) == pytest.approx(pose[2])
        full = np.asarray(mark.pose.covariance).reshape(6, 6)
        np.testing.assert_allclose(full[np.ix_([0, 1, 5], [0, 1, 5])], cov)
        np.testing.assert_allclose(np.diag(full)[2:5], UNOBSERVED_VARIANCE)
        assert np.linalg.eigvalsh(full).min() > 0      # an information matrix exists
    empty = rtabmap_detections(Detections.empty(), Tracker().update(Detections.empty(),
                                                                    Motion.still()),
                               header(store), geometry(store),
                               classes_of(store, 'rtabmap_msgs/msg/LandmarkDetections',
                                          'rtabmap_msgs/msg/LandmarkDetection'))
    assert round_trip(store, empty).landmarks == []


def test_cartographer_gets_weights_of_one_over_sigma_in_its_tracking_frame(store):
    detections, tracked = tracked_scan()
    mount = (0.1, -0.05, math.pi / 2)
    message = round_trip(store, cartographer_landmarks(
        detections, tracked, header(store), geometry(store),
        classes_of(store, 'cartographer_ros_msgs/msg/LandmarkList',
                   'cartographer_ros_msgs/msg/LandmarkEntry'), mount))
    assert [entry.id for entry in message.landmark] == [str(i) for i in tracked.corners.ids[:2]]
    translation, rotation = cartographer_weights(detections.corner_cov[:2])
    for entry, pose, cov, t, r in zip(message.landmark, detections.corner_pose,
                                      detections.corner_cov, translation, rotation):
        # The laser turned a quarter left on the robot: its x is the tracking frame's y.
        moved = entry.tracking_from_landmark_transform
        assert moved.position.x == pytest.approx(0.1 - pose[1])
        assert moved.position.y == pytest.approx(-0.05 + pose[0])
        assert entry.translation_weight == pytest.approx(t)
        assert entry.rotation_weight == pytest.approx(r)
        # A 1-sigma error along the worst axis, weighted, is a residual of 1.
        assert entry.translation_weight ** 2 * np.linalg.eigvalsh(cov[:2, :2]).max() == \
            pytest.approx(1.0)
        assert entry.rotation_weight ** 2 * cov[2, 2] == pytest.approx(1.0)


def test_pose_array_has_every_detection_corners_then_lines(store):
    detections, _ = tracked_scan()
    message = round_trip(store, pose_array(detections, header(store), geometry(store),
                                           classes_of(store, 'geometry_msgs/msg/PoseArray')))
    assert len(message.poses) == 4
    line = message.poses[3]
    assert (line.position.x, line.position.y) == pytest.approx(
        (3.0 * math.cos(0.5), 3.0 * math.sin(0.5)))


def test_a_bridge_without_its_package_is_left_out_in_one_line():
    pytest.importorskip('geometry_msgs')
    missing = []
    loaded = load_bridges(['pose_array', 'rtabmap', 'cartographer'], missing.append)
    assert 'pose_array' in loaded
    for name, package in (('rtabmap', 'rtabmap-msgs'), ('cartographer', 'cartographer-ros-msgs')):
        try:
            bridge_classes(name)
        except ImportError:
            assert name not in loaded
            assert any(f'ros-jazzy-{package}' in line and f'the {name} bridge is off' in line
                       for line in missing), missing
