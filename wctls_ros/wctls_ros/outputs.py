# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The topics wctls_ros reads and writes, with their message types: one table for every reader.

feature_node and odometry_node publish on these names (relative, so they follow the node's
namespace and remappings), ``process_bag`` writes its output bags with them (absolute: a bag
has no namespace), the demo subscribes to them, and feature_node checks the type hashes of
exactly the types it builds with rosbags' classes (:func:`codec_types`). Pure Python: no rclpy
import; a node turns a type name into its class with :func:`message_class`.
"""

import importlib
from typing import Iterable, NamedTuple, Tuple


class Topic(NamedTuple):
    """
    A topic of ours.

    :ivar name: its name relative to the node's namespace (``corners``)
    :ivar type_name: its ROS message type (``wctls_msgs/msg/CornerArray``)
    """

    name: str
    type_name: str

    @property
    def in_bag(self) -> str:
        """Name the topic in a bag written by the bag tools (``/corners``)."""
        return f'/{self.name}'


SCAN = Topic('scan', 'sensor_msgs/msg/LaserScan')
CORNERS = Topic('corners', 'wctls_msgs/msg/CornerArray')
LINES = Topic('lines', 'wctls_msgs/msg/LineSegmentArray')
MARKERS = Topic('markers', 'visualization_msgs/msg/MarkerArray')
LANDMARKS = Topic('landmarks', 'wctls_msgs/msg/LandmarkArray')
LANDMARK_MARKERS = Topic('landmark_markers', 'visualization_msgs/msg/MarkerArray')
DOCK_POSE = Topic('detected_dock_pose', 'geometry_msgs/msg/PoseStamped')
DOCK_POSE_WITH_COVARIANCE = Topic('detected_dock_pose_with_covariance',
                                  'geometry_msgs/msg/PoseWithCovarianceStamped')
ODOMETRY = Topic('odom', 'nav_msgs/msg/Odometry')

# What feature_node publishes with the codec's message classes: the features of every scan,
# the landmarks with their ids (publish_landmarks), the dock (dock_enabled).
FEATURES = (CORNERS, LINES, MARKERS)
LANDMARK_OUTPUTS = (LANDMARKS, LANDMARK_MARKERS)
DOCK_OUTPUTS = (DOCK_POSE, DOCK_POSE_WITH_COVARIANCE)


def codec_types(published: Iterable[Topic]) -> Tuple[str, ...]:
    """
    Return the message types a node decodes or builds with the codec's classes, sorted.

    The scan it reads and every topic it publishes so: the types whose definitions must be the
    ROS install's for rosbags' classes to be used
    (:func:`wctls_ros.conversions.mismatched_types`).

    :param published: the topics the node publishes with the codec's classes
    :return: the ROS type names
    """
    return tuple(sorted({SCAN.type_name, *(topic.type_name for topic in published)}))


def message_class(type_name: str) -> type:
    """
    Return the rclpy message class of a ROS type name (imported now).

    :param type_name: e.g. ``wctls_msgs/msg/CornerArray``
    :return: the class, e.g. ``wctls_msgs.msg.CornerArray``
    """
    package, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)
