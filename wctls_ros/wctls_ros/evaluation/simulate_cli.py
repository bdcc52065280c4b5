# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``simulate``: write a ROS 2 bag of RPLIDAR S1-like scans of a floor plan.

Example::

    simulate environment_a out/env_a --scans 100 --range-sigma 0.05 --bearing-sigma-deg 0.391

The scans have sllidar_ros2's geometry (1080 beams, -pi..pi, increment 2 pi / 1079, +inf for
no return, range_min 0.05 m, range_max 40 m, frame 'laser', stamps at 10 Hz) on ``/scan``.
"""

import argparse
import math
import sys

import numpy as np

from ..simulation import (load_floor_plan, NoiseModel, S1_BEAMS_PER_TURN, SCAN_PERIOD_S,
                          simulate_recording)

START_NS = 1_700_000_000 * 10 ** 9         # a fixed start stamp keeps seeded bags identical


def laser_scan(ranges: np.ndarray, angle_min: float, angle_increment: float, stamp_ns: int,
               noise: NoiseModel, frame_id: str = 'laser'):
    """
    Build a sensor_msgs/LaserScan the way sllidar_ros2 fills it.

    :param ranges: shape (N,), m; +inf for no return
    :param angle_min: bearing of beam 0, rad
    :param angle_increment: bearing step, rad
    :param stamp_ns: header stamp, ns
    :param noise: the noise model (its range limits go into the message)
    :param frame_id: the header's frame
    :return: an rclpy LaserScan message
    """
    from sensor_msgs.msg import LaserScan
    count = len(ranges)
    scan = LaserScan(angle_min=angle_min, angle_max=angle_min + (count - 1) * angle_increment,
                     angle_increment=angle_increment, scan_time=SCAN_PERIOD_S,
                     time_increment=SCAN_PERIOD_S / count, range_min=noise.min_range_m,
                     range_max=noise.max_range_m, ranges=ranges.astype(np.float32))
    scan.header.frame_id = frame_id
    scan.header.stamp.sec, scan.header.stamp.nanosec = divmod(int(stamp_ns), 10 ** 9)
    return scan


def write_simulated_bag(path, plan_name: str, noise: NoiseModel, count: int, seed: int = 0,
                        velocity=(0.0, 0.0, 0.0), pose=None, topic: str = '/scan',
                        beams: int = S1_BEAMS_PER_TURN):
    """
    Simulate scans of a floor plan and write them to an mcap bag.

    :param path: the bag to create (must not exist)
    :param plan_name: a bundled plan name or a YAML path
    :param noise: the noise model
    :param count: number of scans
    :param seed: random seed
    :param velocity: sensor motion (m/s, m/s, rad/s); zero for a still sensor
    :param pose: sensor pose (x m, y m, yaw rad); the plan's if None
    :param topic: the LaserScan topic
    :param beams: beams per turn
    :return: the simulated Recording
    :raises wctls_ros.bags.BagError: when the bag exists or cannot be written
    """
    from ..bags import BagWriter
    plan = load_floor_plan(plan_name)
    recording = simulate_recording(plan, noise, count, seed, pose, velocity, beams)
    with BagWriter(path) as bag:
        for t, ranges in enumerate(recording.ranges):
            stamp = START_NS + int(round(t * SCAN_PERIOD_S * 1e9))
            bag.write(topic, stamp, laser_scan(ranges, recording.angle_min,
                                               recording.angle_increment, stamp, noise))
    return recording


def parser() -> argparse.ArgumentParser:
    """
    Return the command-line parser.

    :return: the parser
    """
    p = argparse.ArgumentParser(
        prog='simulate', description='Write a ROS 2 mcap bag of simulated RPLIDAR S1 scans of '
        'a floor plan (noise model: wctls_ros.simulation.NoiseModel).')
    p.add_argument('plan', help="bundled plan ('environment_a', 'environment_b') or YAML path")
    p.add_argument('out', help='bag folder to create')
    p.add_argument('--scans', type=int, default=100, help='number of scans (10 Hz)')
    p.add_argument('--seed', type=int, default=0, help='random seed')
    p.add_argument('--range-sigma', type=float, default=0.05, help='range noise std, m')
    p.add_argument('--bearing-sigma-deg', type=float, default=0.391,
                   help='bearing noise std, deg')
    p.add_argument('--range-sigma-per-m', type=float, default=0.0,
                   help='range noise std growing with range, m per m')
    p.add_argument('--common-range-sigma', type=float, default=0.0,
                   help='std of a per-scan range offset shared by all beams, m')
    p.add_argument('--dropout', type=float, default=0.0, help='probability of a lost return')
    p.add_argument('--velocity', type=float, nargs=3, default=(0.0, 0.0, 0.0),
                   metavar=('VX', 'VY', 'WZ'),
                   help='move the sensor (m/s, m/s, rad/s in plan axes): a bag that '
                   'evaluate must refuse')
    p.add_argument('--pose', type=float, nargs=3, default=None, metavar=('X', 'Y', 'YAW_DEG'),
                   help="sensor pose in plan coordinates (default: the plan's)")
    p.add_argument('--topic', default='/scan', help='LaserScan topic')
    return p


def main(argv=None) -> int:
    """
    Run the command.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status
    """
    args = parser().parse_args(argv)
    from ..bags import BagError
    try:
        noise = NoiseModel(range_sigma_m=args.range_sigma,
                           bearing_sigma_rad=math.radians(args.bearing_sigma_deg),
                           range_sigma_per_m=args.range_sigma_per_m,
                           common_range_offset_sigma_m=args.common_range_sigma,
                           dropout_probability=args.dropout)
        pose = None if args.pose is None else (args.pose[0], args.pose[1],
                                               math.radians(args.pose[2]))
        write_simulated_bag(args.out, args.plan, noise, args.scans, args.seed,
                            tuple(args.velocity), pose, args.topic)
    except (BagError, FileNotFoundError, ValueError) as error:
        print(f'simulate: {error}', file=sys.stderr)
        return 1
    print(f'simulate: wrote {args.scans} scans of {args.plan} to {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
