# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Bridges: a scan's tracked landmarks in the messages of RTAB-Map, Cartographer and simple EKFs.

Each builds from one scan's detections and their tracks (:mod:`.frontend.tracking`), in the
scan's frame with its header, with the message classes it is given (rclpy's of the installed
package, :func:`bridge_classes`, or any with the same fields), and every scan, empty ones too:

- **rtabmap_msgs/LandmarkDetections** (:func:`rtabmap_detections`): the corners, each a
  LandmarkDetection with ``id`` (> 0; RTAB-Map drops the others), ``landmark_frame_id``
  ``corner_<id>``, ``size`` 0 (no tag) and the corner's pose with covariance. RTAB-Map
  (rtabmap_conversions ``landmarksFromROS``) reads ``id``, ``header.frame_id`` and
  ``header.stamp`` (to move the pose into its base frame), ``pose.pose``, ``pose.covariance``
  (its default variances instead when the first term is not > 0) and ``size``; it takes the
  6x6 as the landmark link's covariance, so z, roll and pitch, which a 2D scan does not
  observe, get UNOBSERVED_VARIANCE rather than 0. Lines have no pose of full rank: left out.
- **cartographer_ros_msgs/LandmarkList** (:func:`cartographer_landmarks`, on ``landmark``):
  the corners, each a LandmarkEntry of the list's ``landmark`` field with ``id`` the track id
  as text, ``tracking_from_landmark_transform`` the corner's pose in Cartographer's tracking
  frame (the laser's mount on it composed in), and the weights Cartographer multiplies the
  residuals by: ``translation_weight`` 1 / sqrt(largest eigenvalue of the position
  covariance) and ``rotation_weight`` 1 / sigma_yaw (1/m and 1/rad: conservative, one weight
  per residual block). Jazzy's cartographer_ros (``ToLandmarkData``) reads ``header.stamp``
  and every entry's four fields; it does not look ``header.frame_id`` up in TF, hence the
  mount.
- **geometry_msgs/PoseArray** (:func:`pose_array`): every detection's pose (corners, then line
  landmarks as their closest point and normal angle), in the LandmarkArray's order; it has no
  ids or covariances.

Only the confirmed tracks go to RTAB-Map and Cartographer (``confirmed_only``): a back end
keeps every landmark it is given.
"""

import importlib
import math
from typing import Dict

import numpy as np

from .conversions import pose_covariances
from .frontend.frames import to_world_points
from .frontend.tracking import CONFIRMED, Detections, observation_poses, TrackedScan

# The variance given to what a 2D scan does not observe (z m^2, roll and pitch rad^2).
UNOBSERVED_VARIANCE = 1e6
# Bridge name -> (message package, the classes it builds with).
BRIDGES = {
    'rtabmap': ('rtabmap_msgs', ('LandmarkDetections', 'LandmarkDetection')),
    'cartographer': ('cartographer_ros_msgs', ('LandmarkList', 'LandmarkEntry')),
    'pose_array': ('geometry_msgs', ('PoseArray',)),
}
_UNOBSERVED = (2, 3, 4)


def bridge_classes(name: str) -> Dict[str, type]:
    """
    Import a bridge's message classes from the installed package.

    :param name: a key of BRIDGES
    :return: class name -> class
    :raises ImportError: with the package to install when it is not installed
    """
    package, names = BRIDGES[name]
    try:
        module = importlib.import_module(f'{package}.msg')
    except ImportError as error:
        raise ImportError(f'the {name} bridge needs {package}: sudo apt install '
                          f'ros-jazzy-{package.replace("_", "-")}') from error
    return {kind: getattr(module, kind) for kind in names}


def _corner_rows(detections: Detections, tracked: TrackedScan, confirmed_only: bool):
    """Return the corners to bridge: (ids, poses (K, 3), covariances (K, 3, 3))."""
    keep = (tracked.corners.states == CONFIRMED) if confirmed_only else np.ones(
        len(tracked.corners.ids), dtype=bool)
    return (tracked.corners.ids[keep], detections.corner_pose[keep],
            detections.corner_cov[keep])


def _pose(types, x: float, y: float, yaw: float):
    """Return a geometry_msgs Pose in the plane."""
    return types.Pose(position=types.Point(x=x, y=y, z=0.0),
                      orientation=types.Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * yaw),
                                                   w=math.cos(0.5 * yaw)))


def rtabmap_detections(detections: Detections, tracked: TrackedScan, header, types,
                       classes: Dict[str, type], confirmed_only: bool = True):
    """
    Build RTAB-Map's LandmarkDetections of one scan.

    :param detections: the scan's detections
    :param tracked: their tracks
    :param header: the scan's header
    :param types: the geometry_msgs classes (:class:`~.conversions.MessageTypes`)
    :param classes: LandmarkDetections and LandmarkDetection (:func:`bridge_classes`)
    :param confirmed_only: bridge the confirmed tracks only
    :return: the message
    """
    ids, poses, covariances = _corner_rows(detections, tracked, confirmed_only)
    full = pose_covariances(covariances).reshape(-1, 6, 6)
    full[:, _UNOBSERVED, _UNOBSERVED] = UNOBSERVED_VARIANCE
    detection = classes['LandmarkDetection']
    return classes['LandmarkDetections'](header=header, landmarks=[
        detection(header=header, landmark_frame_id=f'corner_{track}', id=track, size=0.0,
                  pose=types.PoseWithCovariance(pose=_pose(types, x, y, yaw),
                                                covariance=covariance))
        for track, (x, y, yaw), covariance in zip(ids.tolist(), poses.tolist(),
                                                  full.reshape(-1, 36))])


def cartographer_weights(covariances: np.ndarray):
    """
    Return Cartographer's translation and rotation weights of corner covariances.

    :param covariances: (x, y, yaw) covariances, shape (K, 3, 3)
    :return: (translation weights 1/m, rotation weights 1/rad), each shape (K,)
    """
    largest = np.linalg.eigvalsh(covariances[:, :2, :2])[:, -1]
    return 1.0 / np.sqrt(largest), 1.0 / np.sqrt(covariances[:, 2, 2])


def cartographer_landmarks(detections: Detections, tracked: TrackedScan, header, types,
                           classes: Dict[str, type], tracking_from_sensor=(0.0, 0.0, 0.0),
                           confirmed_only: bool = True):
    """
    Build Cartographer's LandmarkList of one scan.

    :param detections: the scan's detections
    :param tracked: their tracks
    :param header: the scan's header
    :param types: the geometry_msgs classes
    :param classes: LandmarkList and LandmarkEntry (:func:`bridge_classes`)
    :param tracking_from_sensor: the laser's pose in the tracking frame (x m, y m, yaw rad)
    :param confirmed_only: bridge the confirmed tracks only
    :return: the message
    """
    ids, poses, covariances = _corner_rows(detections, tracked, confirmed_only)
    translation, rotation = cartographer_weights(covariances)   # a turn keeps the eigenvalues
    mount = np.asarray(tracking_from_sensor, dtype=float)
    poses = np.column_stack([to_world_points(poses[:, :2], mount), poses[:, 2] + mount[2]])
    entry = classes['LandmarkEntry']
    return classes['LandmarkList'](header=header, landmark=[
        entry(id=str(track), tracking_from_landmark_transform=_pose(types, x, y, yaw),
              translation_weight=t, rotation_weight=r)
        for track, (x, y, yaw), t, r in zip(ids.tolist(), poses.tolist(), translation.tolist(),
                                            rotation.tolist())])


def pose_array(detections: Detections, header, types, classes: Dict[str, type]):
    """
    Build a PoseArray of every detection of one scan (corners, then line landmarks).

    :param detections: the scan's detections
    :param header: the scan's header
    :param types: the geometry_msgs classes
    :param classes: PoseArray (:func:`bridge_classes`)
    :return: the message
    """
    poses, _ = observation_poses(detections)
    return classes['PoseArray'](header=header, poses=[_pose(types, x, y, yaw)
                                                      for x, y, yaw in poses.tolist()])


def load_bridges(names, log_missing) -> Dict[str, Dict[str, type]]:
    """
    Import the classes of the bridges asked for; a missing package leaves its bridge out.

    :param names: bridge names (keys of BRIDGES)
    :param log_missing: called with one line for each bridge left out
    :return: name -> classes, for the bridges that load
    """
    loaded = {}
    for name in names:
        try:
            loaded[name] = bridge_classes(name)
        except ImportError as error:
            log_missing(f'{error}; the {name} bridge is off')
    return loaded
