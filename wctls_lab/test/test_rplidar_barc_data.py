# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The moving RPLIDAR recording of data/rplidar_barc_moving: its scans, poses and laser mount agree.

The scans come from SLAMTEC's ``rplidar_ros`` driver on a car whose poses an external tracking
system gives (data/rplidar_barc_moving/ORIGIN.md). Placed with poses.csv and laser_mount.yaml,
each scan lies on the one five scans before (0.4 m away) to 41 mm (median of the per-pair median
nearest-point distance); the laser turned by 180 deg puts them 420 mm apart, so a pose file or a
mount that no longer matches the scans fails here.
"""

import math

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_lab.evaluation import load_scans
from wctls_lab.evaluation.poses import load_poses, poses_at
import yaml

RECORDING = REAL_DATA / 'rplidar_barc_moving'
# Scans compared with the one this many scans before: 0.4 m of driving.
STEP = 5


@pytest.fixture(scope='module')
def scans():
    return load_scans(RECORDING)


@pytest.fixture(scope='module')
def poses():
    return load_poses(RECORDING / 'poses.csv')


@pytest.fixture(scope='module')
def mount():
    document = yaml.safe_load((RECORDING / 'laser_mount.yaml').read_text())
    return document['x_m'], document['y_m'], document['yaw_rad']


def world_points(ranges, bearings, sensor_pose):
    """
    Return one scan's returns in the poses' frame.

    :param ranges: the scan's usable ranges, m
    :param bearings: their bearings, rad
    :param sensor_pose: the sensor's pose at the scan (x m, y m, yaw rad)
    :return: shape (N, 2), m
    """
    x, y, yaw = sensor_pose
    return np.column_stack([x + ranges * np.cos(bearings + yaw),
                            y + ranges * np.sin(bearings + yaw)])


def median_gap_m(scans, poses, mount):
    """Return the median over scan pairs STEP apart of their median nearest-point distance, m."""
    sensor = poses_at(poses, scans.stamps_ns * 1e-9, mount)
    valid = scans.valid()
    clouds = [world_points(scans.ranges[k][valid[k]], scans.bearings[valid[k]], sensor[k])
              for k in range(len(scans.ranges))]
    gaps = []
    for before, after in zip(clouds, clouds[STEP:]):
        distances = np.linalg.norm(after[:, None, :] - before[None, :, :], axis=2)
        gaps.append(np.median(distances.min(axis=1)))
    return float(np.median(gaps))


def test_the_scans_are_the_drivers_360_bins_each_with_a_pose(scans, poses):
    assert scans.ranges.shape == (338, 360)
    assert math.degrees(scans.angle_min) == pytest.approx(-179.0, abs=1e-4)
    assert math.degrees(scans.angle_increment) == pytest.approx(1.0, abs=1e-6)
    assert (scans.range_min, scans.range_max) == pytest.approx((0.15, 8.0))
    np.testing.assert_allclose(poses[:, 0], scans.stamps_ns * 1e-9, rtol=0.0, atol=1e-6)
    assert np.isfinite(poses_at(poses, scans.stamps_ns * 1e-9)).all()


def test_the_laser_mount_puts_each_scan_on_the_scans_before_it(scans, poses, mount):
    assert median_gap_m(scans, poses, mount) < 0.05
    x, y, yaw = mount
    assert median_gap_m(scans, poses, (x, y, yaw + math.pi)) > 0.3
