# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
process_bag --tracks: the landmark tracker over a bag's scans, in bag order.

Each scan's corners and line landmarks (extracted wherever process_bag extracts them) go
through one :class:`~wctls_ros.frontend.tracking.Tracker` here, in order. The motion between
scans comes from a pose file (``stamp_s,x_m,y_m,yaw_rad``, the robot's pose; the laser's
offset on the robot composed in), each step given a stated sigma; without one the sensor is
taken as still. Writes, per scan, a wctls_msgs/LandmarkArray on ``/landmarks`` into the output
bag (empty ones too), the ids as markers on ``/landmark_markers`` and the rows of
``landmarks.csv`` beside ``corners.csv``.
"""

import csv
from dataclasses import dataclass
import math
from typing import Optional

import numpy as np

from .bag_io import BagError
from ..frontend.frames import relative_step
from ..frontend.poses import load_poses, PoseError, poses_at
from ..frontend.tracking import Detections, Motion, Tracker, View
from ..landmark_messages import (landmark_array, LANDMARK_COLUMNS, landmark_markers,
                                 landmark_rows)
from ..outputs import LANDMARK_MARKERS, LANDMARKS

LANDMARKS_CSV = 'landmarks.csv'


@dataclass(frozen=True)
class TrackOptions:
    """
    How the tracker learns the motion.

    :ivar poses: rows of stamp s, x m, y m, yaw rad of the robot (:func:`load_poses`), or None
        for a still sensor
    :ivar laser_offset: the laser's pose on the robot (x m, y m, yaw rad)
    :ivar step_sigma_m: the sigma of each step's dx and dy, m
    :ivar step_sigma_rad: the sigma of each step's dyaw, rad
    """

    poses: Optional[np.ndarray] = None
    laser_offset: tuple = (0.0, 0.0, 0.0)
    step_sigma_m: float = 0.0
    step_sigma_rad: float = 0.0

    @staticmethod
    def from_arguments(poses_file, laser_offset_deg, step_sigma_deg) -> 'TrackOptions':
        """
        Return the options of the command line.

        :param poses_file: the pose file, or None
        :param laser_offset_deg: x m, y m, yaw deg of the laser on the robot
        :param step_sigma_deg: sigma of a step's dx and dy (m) and of its dyaw (deg), or None
            for the defaults: 2 cm and 1 deg with poses, 0 without
        :return: the options
        :raises BagError: for a pose file that cannot be read, or a negative sigma
        """
        try:
            poses = load_poses(poses_file) if poses_file is not None else None
        except PoseError as error:
            raise BagError(str(error)) from error
        if step_sigma_deg is None:
            step_sigma_deg = (0.02, 1.0) if poses is not None else (0.0, 0.0)
        if min(step_sigma_deg) < 0.0 or not all(map(math.isfinite, step_sigma_deg)):
            raise BagError(f'--step-sigma takes two sigmas >= 0, got {step_sigma_deg}')
        x, y, yaw_deg = laser_offset_deg
        return TrackOptions(poses, (x, y, math.radians(yaw_deg)), step_sigma_deg[0],
                            math.radians(step_sigma_deg[1]))


class BagTracks:
    """Tracks the scans of one bag; writes /landmarks and landmarks.csv as it goes."""

    def __init__(self, writer, options: TrackOptions, types):
        """
        Open landmarks.csv beside the output bag.

        :param writer: the output's BagWriter
        :param options: the motion's source
        :param types: the message types to build with (rosbags')
        """
        self._writer, self._options, self._types = writer, options, types
        self._tracker = Tracker()
        self._pose = None
        self._stream = writer.sidecar(LANDMARKS_CSV).open('w', newline='')
        self._csv = csv.writer(self._stream)
        self._csv.writerow(LANDMARK_COLUMNS)

    def close(self) -> None:
        """Close landmarks.csv."""
        self._stream.close()

    def _motion(self, stamp_s: float) -> Motion:
        """Return the step since the previous scan (still without poses)."""
        options = self._options
        if options.poses is None:
            return Motion(np.zeros(3), np.diag([options.step_sigma_m ** 2] * 2
                                               + [options.step_sigma_rad ** 2]))
        pose = poses_at(options.poses, np.array([stamp_s]), options.laser_offset)[0]
        if not np.isfinite(pose).all():
            raise BagError(f'the poses cover {options.poses[0, 0]:.3f}-'
                           f'{options.poses[-1, 0]:.3f} s, not the scan at {stamp_s:.3f} s')
        before, self._pose = self._pose, pose
        if before is None:
            return Motion.still()
        return Motion(relative_step(before, pose),
                      np.diag([options.step_sigma_m ** 2] * 2 + [options.step_sigma_rad ** 2]))

    def add(self, log_time_ns: int, stamp_and_frame: tuple, detections: Detections,
            view: View) -> None:
        """
        Track one scan; write its LandmarkArray and its rows.

        :param log_time_ns: its log time, ns
        :param stamp_and_frame: its header's stamp (sec, nanosec) and frame_id
        :param detections: its corners and line landmarks
        :param view: what it could see
        """
        sec, nanosec, frame_id = stamp_and_frame
        types = self._types
        header = types.Header(stamp=types.Time(sec=sec, nanosec=nanosec), frame_id=frame_id)
        stamp = f'{sec}.{nanosec:09d}'
        tracked = self._tracker.update(detections, self._motion(float(stamp)), view)
        message = landmark_array(detections, tracked, header, types)
        self._writer.write_serialized(LANDMARKS.in_bag, LANDMARKS.type_name, log_time_ns,
                                      types.serialize(message))
        self._writer.write_serialized(LANDMARK_MARKERS.in_bag, LANDMARK_MARKERS.type_name,
                                      log_time_ns,
                                      types.serialize(landmark_markers(detections, tracked,
                                                                       header, types)))
        self._csv.writerows(landmark_rows(stamp, detections, tracked))
