# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The landmark codec: a scan's detections with their track ids as a LandmarkArray and as rows.

Both give every detection of the scan, corners first, then line landmarks, as the tracker
(:mod:`.frontend.tracking`) labelled it: id, kind, state, hits, age and the observation's own
pose with covariance in the sensor frame (:func:`~.frontend.tracking.observation_poses`).
Builds with rclpy's classes or rosbags' alike (:class:`~.conversions.MessageTypes`).
:class:`LandmarkStream` is feature_node's tracker: one scan's features in, its detections and
their tracks out.
"""

from typing import List, Optional, Tuple

import numpy as np

from .conversions import MessageTypes, pose_covariances, rclpy_types, unused_marker_fields
from .core import Features
from .frontend.tracking import (CONFIRMED, Detections, detections_of, Motion,
                                observation_poses, STATES, TrackedScan, Tracker, View)

# landmarks.csv's columns: the observation in the sensor frame and the upper triangle of its
# (x, y, yaw) covariance.
LANDMARK_COLUMNS = ('stamp_s', 'id', 'kind', 'state', 'x_m', 'y_m', 'yaw_rad', 'cov_xx',
                    'cov_xy', 'cov_xyaw', 'cov_yy', 'cov_yyaw', 'cov_yawyaw', 'hits')
# Upper triangle of a 3x3 covariance, in the order of the columns: rows, columns.
_TRIANGLE = (np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2]))
# Landmark.msg's kind codes, corners first.
KIND_CORNER = 0
KIND_LINE = 1


def _labels(detections: Detections, tracked: TrackedScan):
    """Return (kind codes, ids, states, hits, ages) of every detection, corners first."""
    kinds = np.concatenate([np.full(len(detections.corner_pose), KIND_CORNER),
                            np.full(len(detections.line), KIND_LINE)])
    fields = [np.concatenate([getattr(tracked.corners, name), getattr(tracked.lines, name)])
              for name in ('ids', 'states', 'hits', 'age_scans')]
    return (kinds, *fields)


def landmark_array(detections: Detections, tracked: TrackedScan, header,
                   types: Optional[MessageTypes] = None):
    """
    Convert one scan's tracked detections to a LandmarkArray.

    :param detections: the scan's detections
    :param tracked: their tracks (from :meth:`~.frontend.tracking.Tracker.update`)
    :param header: the scan's header, a ``types.Header`` (shared, not copied)
    :param types: the message classes to build with (None: rclpy's)
    :return: the message (empty landmarks when the scan has none)
    """
    types = types or rclpy_types()
    Point, Quaternion = types.Point, types.Quaternion
    PoseWithCovariance, Pose = types.PoseWithCovariance, types.Pose
    poses, covariances = observation_poses(detections)
    kinds, ids, states, hits, ages = _labels(detections, tracked)
    half_yaw = 0.5 * poses[:, 2]
    landmarks = [
        types.Landmark(id=track, kind=kind, state=state, hits=count, age=age,
                       pose=PoseWithCovariance(
                           pose=Pose(position=Point(x=x, y=y, z=0.0),
                                     orientation=Quaternion(x=0.0, y=0.0, z=qz, w=qw)),
                           covariance=covariance))
        for track, kind, state, count, age, (x, y), qz, qw, covariance in zip(
            ids.tolist(), kinds.tolist(), states.tolist(), hits.tolist(), ages.tolist(),
            poses[:, :2].tolist(), np.sin(half_yaw).tolist(), np.cos(half_yaw).tolist(),
            pose_covariances(covariances))]
    return types.LandmarkArray(header=header, landmarks=landmarks)


def landmark_markers(detections: Detections, tracked: TrackedScan, header,
                     types: Optional[MessageTypes] = None, size_m: float = 0.06):
    """
    Label every detection of one scan with its track id, for RViz or Foxglove.

    A DELETEALL first (ids of earlier scans never linger), then one TEXT_VIEW_FACING marker per
    detection (namespace ``landmark_ids``), at its pose (a line's at its closest point): the
    id, green when confirmed, grey while tentative.

    :param detections: the scan's detections
    :param tracked: their tracks
    :param header: the scan's header
    :param types: the message classes (None: rclpy's)
    :param size_m: the labels' height, m
    :return: a MarkerArray
    """
    types = types or rclpy_types()
    Marker, Point, Pose, Quaternion = types.Marker, types.Point, types.Pose, types.Quaternion
    ColorRGBA, Vector3 = types.ColorRGBA, types.Vector3
    alike = dict(unused_marker_fields(types), header=header, points=[])
    upright = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    markers = [Marker(**alike, action=Marker.DELETEALL, ns='', id=0, type=Marker.ARROW,
                      pose=Pose(position=Point(x=0.0, y=0.0, z=0.0), orientation=upright),
                      scale=Vector3(x=0.0, y=0.0, z=0.0),
                      color=ColorRGBA(r=0.0, g=0.0, b=0.0, a=0.0), text='')]
    poses, _ = observation_poses(detections)
    _, ids, states, _, _ = _labels(detections, tracked)
    confirmed = ColorRGBA(r=0.2, g=1.0, b=0.2, a=1.0)
    tentative = ColorRGBA(r=0.6, g=0.6, b=0.6, a=1.0)
    for n, ((x, y, _), track, state) in enumerate(zip(poses.tolist(), ids.tolist(),
                                                      states.tolist())):
        markers.append(Marker(
            **alike, action=Marker.ADD, ns='landmark_ids', id=n, type=Marker.TEXT_VIEW_FACING,
            pose=Pose(position=Point(x=x, y=y, z=3.0 * size_m), orientation=upright),
            scale=Vector3(x=0.0, y=0.0, z=2.0 * size_m),
            color=confirmed if state == CONFIRMED else tentative, text=str(track)))
    return types.MarkerArray(markers=markers)


def landmark_rows(stamp_s: str, detections: Detections, tracked: TrackedScan) -> List[list]:
    """
    Return one scan's rows of landmarks.csv (LANDMARK_COLUMNS).

    :param stamp_s: the scan's stamp, s, as text (``sec.nanosec``)
    :param detections: the scan's detections
    :param tracked: their tracks
    :return: one row per detection, corners first
    """
    poses, covariances = observation_poses(detections)
    kinds, ids, states, hits, _ = _labels(detections, tracked)
    triangle = covariances[:, _TRIANGLE[0], _TRIANGLE[1]]
    return [[stamp_s, track, 'corner' if kind == KIND_CORNER else 'line', STATES[state],
             *pose, *terms, count]
            for track, kind, state, pose, terms, count in zip(
                ids.tolist(), kinds.tolist(), states.tolist(), poses.tolist(),
                triangle.tolist(), hits.tolist())]


class LandmarkStream:
    """
    Tracks the landmarks of consecutive scans of one sensor and converts them to messages.

    The sensor counts as still between scans, its unknown step of the given sigmas.
    """

    def __init__(self, step_sigma_m: float = 0.0, step_sigma_rad: float = 0.0):
        """
        Start with no tracks.

        :param step_sigma_m: the sigma of a step between scans in x and y, m
        :param step_sigma_rad: the sigma of a turn between scans, rad
        """
        self.tracker = Tracker()
        self.motion = Motion(np.zeros(3), np.diag([step_sigma_m ** 2, step_sigma_m ** 2,
                                                   step_sigma_rad ** 2]))

    def track(self, features: Features, scan, max_landmark_angle_sigma_rad: float
              ) -> Tuple[Detections, TrackedScan]:
        """
        Track one scan's landmarks.

        :param features: the scan's features (empty for a scan that could not be used)
        :param scan: the LaserScan (its ranges say which tracks it could have seen)
        :param max_landmark_angle_sigma_rad: the line landmark rule's bound, rad
        :return: (its detections, their tracks)
        """
        detections = detections_of(features, max_landmark_angle_sigma_rad)
        try:
            view: Optional[View] = View(float(scan.angle_min), float(scan.angle_increment),
                                        np.asarray(scan.ranges, dtype=float),
                                        float(scan.range_max))
        except (TypeError, ValueError):         # a malformed scan: every track counts in view
            view = None
        if view is not None and (not len(view.ranges_m) or not view.angle_increment_rad):
            view = None
        return detections, self.tracker.update(detections, self.motion, view)
