# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
feature_node's bridge publishers: each bridge asked for whose message package is installed.

The messages are built with rclpy's classes of that package (:mod:`.bridges`) and published
every scan, empty ones too. Topics (relative, remappable): ``landmark_detections``
(rtabmap_msgs/LandmarkDetections), ``landmark`` (cartographer_ros_msgs/LandmarkList, the topic
Cartographer subscribes; its tracking frame should be the laser's, as Cartographer does not
look the list's frame up in TF) and ``landmark_poses`` (geometry_msgs/PoseArray).
"""

from .bridges import (BRIDGES, cartographer_landmarks, load_bridges, pose_array,
                      rtabmap_detections)
from .conversions import copy_header, rclpy_types
from .params import ConfigError

# Bridge name -> (topic, builder, its message class).
TOPICS = {'rtabmap': ('landmark_detections', 'LandmarkDetections'),
          'cartographer': ('landmark', 'LandmarkList'),
          'pose_array': ('landmark_poses', 'PoseArray')}


def bridge_names(text: str) -> list:
    """
    Return the bridges a ``landmark_bridges`` parameter names.

    :param text: comma-separated names ('' for none)
    :return: the names, in order
    :raises ConfigError: naming an unknown bridge and the known ones
    """
    names = [name.strip() for name in text.split(',') if name.strip()]
    unknown = [name for name in names if name not in BRIDGES]
    if unknown:
        raise ConfigError(f'landmark_bridges: unknown {", ".join(unknown)}; choose among '
                          f'{", ".join(BRIDGES)}')
    return names


class BridgePublishers:
    """The publishers of the bridges that load."""

    def __init__(self, node, names_text: str):
        """
        Load the bridges and create their publishers.

        :param node: the rclpy node
        :param names_text: the ``landmark_bridges`` parameter
        """
        self._classes = load_bridges(bridge_names(names_text),
                                     node.get_logger().warning)
        self._publishers = {name: node.create_publisher(classes[TOPICS[name][1]],
                                                        TOPICS[name][0], 10)
                            for name, classes in self._classes.items()}

    @property
    def publishers(self) -> tuple:
        """
        Return the bridges' rclpy publishers, which the node destroys at cleanup.

        :return: one per bridge that loaded
        """
        return tuple(self._publishers.values())

    def publish(self, detections, tracked, scan_header) -> None:
        """
        Publish one scan's landmarks on every bridge.

        :param detections: the scan's detections
        :param tracked: their tracks
        :param scan_header: the scan's header (of any message classes)
        """
        if not self._publishers:
            return
        types = rclpy_types()
        header = copy_header(scan_header, types)
        for name, publisher in self._publishers.items():
            classes = self._classes[name]
            if name == 'rtabmap':
                message = rtabmap_detections(detections, tracked, header, types, classes)
            elif name == 'cartographer':
                message = cartographer_landmarks(detections, tracked, header, types, classes)
            else:
                message = pose_array(detections, header, types, classes)
            publisher.publish(message)
