# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
process_bag --odometry: the odometry of every scan, into the output bag and ``odometry.csv``.

The scans' landmarks go through :class:`~wctls_ros.frontend.odometry.Odometry` in bag order
(the features may come from worker processes; the odometry runs here, one scan after the
other). Each scan gives a nav_msgs/Odometry on ``/odom`` (frame ``odom``, child the robot's
frame, or the scan's own without a mount) and one row of ``odometry.csv``:
``stamp_s,x_m,y_m,yaw_rad``, the pose's covariance (upper triangle of x, y, yaw), the step
from the previous scan in the previous scan's frame ``dx_m,dy_m,dyaw_rad`` with its
covariance, and the status (tracking, degenerate, prior, reinitialized).
"""

import csv
import math
import pathlib
from typing import NamedTuple, Optional, Sequence, Tuple

import numpy as np

from .bag_io import BagError, BagWriter, typestore
from ..frontend.frames import Landmarks
from ..frontend.odometry import Odometry, OdometryConfig, OdometryUpdate, on_robot
from ..odometry_messages import odometry_message, ODOMETRY_TYPES
from ..outputs import ODOMETRY

ODOMETRY_CSV = 'odometry.csv'
ODOMETRY_TOPIC = ODOMETRY.in_bag
ODOMETRY_COLUMNS = (
    'stamp_s', 'x_m', 'y_m', 'yaw_rad', 'cov_xx', 'cov_xy', 'cov_xyaw', 'cov_yy', 'cov_yyaw',
    'cov_yawyaw', 'dx_m', 'dy_m', 'dyaw_rad', 'dcov_xx', 'dcov_xy', 'dcov_xyaw', 'dcov_yy',
    'dcov_yyaw', 'dcov_yawyaw', 'status')
_UPPER = np.triu_indices(3)


def odometry_row(update: OdometryUpdate) -> list:
    """
    Return one scan's row of odometry.csv.

    :param update: the scan's odometry
    :return: the values in the order of ODOMETRY_COLUMNS
    """
    return ([f'{update.stamp_s:.9f}'] + [f'{v:.9g}' for v in update.pose]
            + [f'{v:.9g}' for v in update.pose_covariance[_UPPER]]
            + [f'{v:.9g}' for v in update.step]
            + [f'{v:.9g}' for v in update.step_covariance[_UPPER]] + [update.status])


def read_mount(text: str) -> Tuple[float, float, float]:
    """
    Read a laser mount from a YAML file such as the recordings' ``laser_mount.yaml``.

    :param text: the file's text (keys x_m, y_m, yaw_rad; others ignored)
    :return: (x m, y m, yaw rad)
    :raises ValueError: when a key is missing or not a number
    """
    import yaml
    document = yaml.safe_load(text)
    try:
        values = tuple(float(document[key]) for key in ('x_m', 'y_m', 'yaw_rad'))
    except (TypeError, KeyError, ValueError) as error:
        raise ValueError(f'a laser mount needs the numbers x_m, y_m and yaw_rad ({error})') \
            from error
    if not all(math.isfinite(v) for v in values):
        raise ValueError('a laser mount must be finite')
    return values


class OdometryOutput(NamedTuple):
    """
    What process_bag's odometry is asked for.

    :ivar config: the odometry's settings
    :ivar mount: the laser's pose on the robot (x m, y m, yaw rad), or None for the laser's
        own odometry
    """

    config: OdometryConfig
    mount: Optional[Tuple[float, float, float]]


def odometry_request(wanted: bool, mount: Optional[Sequence[str]]) -> Optional[OdometryOutput]:
    """
    Return the odometry the command line asks for.

    :param wanted: --odometry was given
    :param mount: the words of --laser-mount (three numbers m, m, deg, or one YAML file), or
        None
    :return: the request, or None without --odometry
    :raises BagError: on a mount without --odometry, or one that cannot be read
    """
    if not wanted:
        if mount is not None:
            raise BagError('--laser-mount needs --odometry')
        return None
    if mount is None:
        return OdometryOutput(OdometryConfig(), None)
    try:
        if len(mount) == 1:
            return OdometryOutput(OdometryConfig(), read_mount(pathlib.Path(mount[0]).read_text()))
        x, y, yaw_deg = (float(word) for word in mount)
    except OSError as error:
        raise BagError(f'--laser-mount: cannot read {mount[0]}: {error.strerror}') from error
    except ValueError as error:
        raise BagError('--laser-mount takes X_M Y_M YAW_DEG or one YAML file with x_m, y_m and '
                       f'yaw_rad ({error})') from error
    if not all(math.isfinite(v) for v in (x, y, yaw_deg)):
        raise BagError('--laser-mount must be finite')
    return OdometryOutput(OdometryConfig(), (x, y, math.radians(yaw_deg)))


class OdometryTable:
    """Runs the odometry over a bag's scans and writes its messages and ``odometry.csv``."""

    def __init__(self, writer: BagWriter, config: OdometryConfig,
                 mount: Optional[Tuple[float, float, float]]):
        """
        Prepare the output.

        :param writer: the output bag (odometry.csv goes into its folder)
        :param config: the odometry's settings
        :param mount: the laser's pose on the robot (x m, y m, yaw rad): the robot's odometry
            in frame base_link; None: the laser's own, in the scan's frame
        """
        self._writer = writer
        self._mount = np.asarray(mount if mount is not None else (0.0, 0.0, 0.0), dtype=float)
        self._robot = mount is not None
        self._odometry = Odometry(config, tuple(self._mount))
        store = typestore()
        self._classes = {name: store.types[name] for name in ODOMETRY_TYPES}
        self._header = store.types['std_msgs/msg/Header']
        self._path: pathlib.Path = writer.sidecar(ODOMETRY_CSV)
        self.statuses: dict = {}

    def __enter__(self) -> 'OdometryTable':
        self._file = self._path.open('w', newline='')
        self._csv = csv.writer(self._file)
        self._csv.writerow(ODOMETRY_COLUMNS)
        return self

    def add(self, log_time_ns: int, header, landmarks: Landmarks) -> None:
        """
        Take one scan.

        :param log_time_ns: its log time, ns
        :param header: its header (rosbags' type)
        :param landmarks: its landmarks
        """
        stamp_s = int(header.stamp.sec) + 1e-9 * int(header.stamp.nanosec)
        laser = self._odometry.update(stamp_s, landmarks)
        update = on_robot(laser, self._mount)
        self.statuses[update.status] = self.statuses.get(update.status, 0) + 1
        self._csv.writerow(odometry_row(update))
        child = 'base_link' if self._robot else str(header.frame_id)
        self._writer.write(ODOMETRY_TOPIC, log_time_ns, odometry_message(
            self._classes, update, self._header(stamp=header.stamp, frame_id='odom'), child))

    def __exit__(self, kind, value, traceback):
        self._file.close()
        return False
