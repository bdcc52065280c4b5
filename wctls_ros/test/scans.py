# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""LaserScan messages of simulated rooms for the node tests."""

import math

import numpy as np
from sensor_msgs.msg import LaserScan
from wctls_lab.simulation import (floor_plan_from_dict, full_turn_bearings, NoiseModel,
                                  simulate_ranges)

ROOM = {'name': 'room', 'polylines': [
    {'closed': True, 'points': [[0.0, 0.0], [4.5, 0.0], [4.5, 2.5], [0.0, 2.5]]}],
    'boxes': [{'center': [2.6, 2.0], 'size': [0.4, 0.4]}]}
ROOM_POSE = (1.6, 1.1, 0.3)
NOISE = NoiseModel(range_sigma_m=0.01, bearing_sigma_rad=math.radians(0.05))
NODE_PARAMETERS = {'range_sigma_m': 0.01, 'bearing_sigma_deg': 0.05}


def room_truth():
    """Return the true corners the sensor sees in ROOM: 4 room corners and 1 box corner."""
    _, corners = floor_plan_from_dict(ROOM).in_sensor_frame(ROOM_POSE)
    box = corners[4:]
    return np.vstack([corners[:4], box[np.argmin(np.hypot(*box.T))]])


def room_scan_message(seed=0, beams=1080, frame_id='laser', stamp=(1700000000, 5)):
    """Return a full-turn LaserScan of ROOM with sllidar_ros2's geometry."""
    walls, _ = floor_plan_from_dict(ROOM).in_sensor_frame(ROOM_POSE)
    angle_min, increment, bearings = full_turn_bearings(beams)
    ranges = simulate_ranges(walls, bearings, NOISE, np.random.default_rng(seed))
    scan = LaserScan(angle_min=angle_min, angle_max=angle_min + (beams - 1) * increment,
                     angle_increment=increment, time_increment=1e-4, scan_time=0.1,
                     range_min=0.05, range_max=40.0, ranges=ranges.astype(np.float32))
    scan.header.frame_id = frame_id
    scan.header.stamp.sec, scan.header.stamp.nanosec = stamp
    return scan
