# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``simulate``: write a ROS 2 bag of RPLIDAR S1-like scans of a floor plan, and its truth.

Examples::

    simulate environment_a out/env_a --scans 100 --range-sigma 0.05 --bearing-sigma-deg 0.391
    simulate environment_b_cluttered out/env_b --sensor s1_like
    simulate environment_a out/env_a_veils --sensor 1cm --beam-divergence-deg 0.4

The scans have sllidar_ros2's geometry (1080 beams, -pi..pi, increment 2 pi / 1079, +inf for
no return, range_min 0.05 m, range_max 40 m, frame 'laser', stamps at 10 Hz) on ``/scan``. The
bag folder also gets ``truth.yaml``: the plan's true corners in the sensor frame, their kinds
and which of them each scan can see (the format of :mod:`.truth`; ``score`` reads it).

Exit status 0, or 2 with one line ``simulate: error: ...`` on a bad option, plan or output
(nothing is written then).
"""

import argparse
import dataclasses
import math
import pathlib
import sys

import numpy as np
from wctls_ros.cli import bounded, Parser, USER_ERROR, UserError
from wctls_ros.extras import explains_missing_extras

from .truth import TRUTH_FILE, truth_from_recording, truth_to_yaml
from ..simulation import (BUNDLED_PLANS, load_floor_plan, NO_RETURN_VALUES, NoiseModel,
                          S1_BEAMS_PER_TURN, SCAN_PERIOD_S, SENSOR_MODELS, simulate_recording)

START_NS = 1_700_000_000 * 10 ** 9         # a fixed start stamp keeps seeded bags identical
# The first line of the truth.yaml simulate writes: how --force knows a bag folder is its own.
TRUTH_HEADER = 'True corners of the simulated scans beside this file (wctls_ros simulate).'


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
                        beams: int = S1_BEAMS_PER_TURN, overwrite: bool = False):
    """
    Simulate scans of a floor plan and write them to an mcap bag, with truth.yaml inside.

    The bag folder appears complete, truth.yaml included, or not at all.

    :param path: the bag to create (must not exist)
    :param plan_name: a bundled plan name or a YAML path
    :param noise: the noise model
    :param count: number of scans
    :param seed: random seed
    :param velocity: sensor motion (m/s, m/s, rad/s); zero for a still sensor
    :param pose: sensor pose (x m, y m, yaw rad); the plan's if None
    :param topic: the LaserScan topic
    :param beams: beams per turn
    :param overwrite: replace an existing bag folder (check first that it may go:
        :func:`refuse_to_replace`)
    :return: the simulated Recording
    :raises ValueError: for a count below 1
    :raises wctls_ros.bags.BagError: when the bag exists (and not overwrite) or cannot be written
    """
    from wctls_ros.bags import BagWriter
    if count < 1:
        raise ValueError(f'the number of scans must be at least 1, got {count}')
    plan = load_floor_plan(plan_name)
    recording = simulate_recording(plan, noise, count, seed, pose, velocity, beams)
    description = (f'{count} scans of {plan.name} (seed {seed}), sensor model {noise}, '
                   f'first pose {tuple(float(v) for v in recording.poses[0])}, velocity '
                   f'{tuple(velocity)}')
    truth = truth_from_recording(recording, 'laser', description)
    with BagWriter(path, overwrite=overwrite) as bag:
        for t, ranges in enumerate(recording.ranges):
            stamp = START_NS + int(round(t * SCAN_PERIOD_S * 1e9))
            bag.write(topic, stamp, laser_scan(ranges, recording.angle_min,
                                               recording.angle_increment, stamp, noise))
        bag.sidecar(TRUTH_FILE).write_text(truth_to_yaml(truth, TRUTH_HEADER))
    return recording


def refuse_to_replace(out: pathlib.Path, force: bool) -> None:
    """
    Refuse an output that exists, unless --force may replace it: a bag folder simulate wrote.

    :param out: the bag folder to write
    :param force: --force was given
    :raises UserError: with the reason, when the output must not be written
    """
    if not out.exists() and not out.is_symlink():
        return
    if not force:
        raise UserError(f'{out} exists: refusing to overwrite it (--force replaces a bag '
                        'folder simulate wrote)')
    own = {'metadata.yaml', f'{out.name}.mcap', TRUTH_FILE}
    try:
        names = {path.name for path in out.iterdir()}
        with open(out / TRUTH_FILE) as truth:
            first_line = truth.readline().strip()
    except OSError:
        names, first_line = set(), ''
    if names != own or first_line != f'# {TRUTH_HEADER}':
        raise UserError(f'--force refused: {out} is not a bag folder simulate wrote (only '
                        f'{", ".join(sorted(own))}, with its truth): remove it yourself or '
                        'choose another folder')


def parser() -> argparse.ArgumentParser:
    """
    Return the command-line parser.

    :return: the parser
    """
    p = Parser(
        prog='simulate', description='Write a ROS 2 mcap bag of simulated RPLIDAR S1 scans of '
        'a floor plan (noise model: wctls_lab.simulation.NoiseModel), with truth.yaml (the true '
        'corners) inside.', epilog='Exit status: 0 done; 2 a user error (bad option, plan or '
        'output), with one line on stderr and nothing written.')
    p.add_argument('plan', help=f"bundled plan ({', '.join(BUNDLED_PLANS)}) or YAML path")
    p.add_argument('out', help='bag folder to create (must not exist unless --force)')
    p.add_argument('--scans', type=bounded(int, 1), default=100,
                   help='number of scans, at 10 Hz (default: %(default)s)')
    p.add_argument('--seed', type=int, default=0, help='random seed (default: %(default)s)')
    p.add_argument('--sensor', choices=sorted(SENSOR_MODELS), default='datasheet',
                   help='sensor model preset, refined by the options below (datasheet: 5 cm, '
                   '0.391 deg; 1cm: 1 cm, 0.05 deg; s1_like: 2 cm, 0.05 deg + 1/3 deg bins, '
                   '0.4 deg divergence, 1 %% dropouts, 1 mm common offset; see '
                   'docs/results/score.md) (default: %(default)s)')
    # Every sensor option refines the preset; left out, the preset's value stands.
    p.add_argument('--range-sigma', type=float, default=None,
                   help="range noise std, m (default: the preset's)")
    p.add_argument('--bearing-sigma-deg', type=float, default=None,
                   help="bearing noise std, deg (default: the preset's)")
    p.add_argument('--range-sigma-per-m', type=float, default=None,
                   help="range noise std growing with range, m per m (default: the preset's)")
    p.add_argument('--common-range-sigma', type=float, default=None,
                   help='std of a per-scan range offset shared by all beams, m (default: the '
                   "preset's)")
    p.add_argument('--dropout', type=float, default=None,
                   help="probability of a lost return (default: the preset's)")
    p.add_argument('--beam-divergence-deg', type=float, default=None,
                   help='full angle of the beam footprint, deg: mixed pixels at range '
                   "discontinuities (0: an ideal ray) (default: the preset's)")
    p.add_argument('--bearing-quantum-deg', type=float, default=None,
                   help="publish bearings in bins this wide, deg (sllidar's angle_compensate: "
                   "1/3 = 0.3333; 0: exact) (default: the preset's)")
    p.add_argument('--no-return', choices=NO_RETURN_VALUES, default=None,
                   help='how a beam without a return is written: inf (REP-117), zero, or max '
                   "(the maximum range) (default: the preset's)")
    p.add_argument('--velocity', type=float, nargs=3, default=(0.0, 0.0, 0.0),
                   metavar=('VX', 'VY', 'WZ'),
                   help='move the sensor (m/s, m/s, rad/s in plan axes): a bag that '
                   'evaluate must refuse (default: still)')
    p.add_argument('--pose', type=float, nargs=3, default=None, metavar=('X', 'Y', 'YAW_DEG'),
                   help="sensor pose in plan coordinates (default: the plan's)")
    p.add_argument('--topic', default='/scan', help='LaserScan topic (default: %(default)s)')
    p.add_argument('-f', '--force', action='store_true',
                   help='replace an existing bag folder that simulate wrote (default: refuse)')
    return p


def sensor_model(args) -> NoiseModel:
    """
    Return the sensor model of the command line: the preset with the options given over it.

    :param args: the parsed arguments
    :return: the model
    :raises ValueError: on values the model refuses
    """
    given = {'range_sigma_m': args.range_sigma,
             'bearing_sigma_rad': _radians(args.bearing_sigma_deg),
             'range_sigma_per_m': args.range_sigma_per_m,
             'common_range_sigma_m': args.common_range_sigma,
             'dropout_probability': args.dropout,
             'beam_divergence_rad': _radians(args.beam_divergence_deg),
             'bearing_quantum_rad': _radians(args.bearing_quantum_deg),
             'no_return': args.no_return}
    return dataclasses.replace(SENSOR_MODELS[args.sensor],
                               **{k: v for k, v in given.items() if v is not None})


def _radians(degrees):
    return None if degrees is None else math.radians(degrees)


@explains_missing_extras('simulate')
def main(argv=None) -> int:
    """
    Run the command.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status: 0, or 2 on a user error (one line on stderr, nothing written)
    """
    args = parser().parse_args(argv)
    from wctls_ros.bags import BagError
    try:
        noise = sensor_model(args)
        pose = None if args.pose is None else (args.pose[0], args.pose[1],
                                               math.radians(args.pose[2]))
        refuse_to_replace(pathlib.Path(args.out), args.force)
        write_simulated_bag(args.out, args.plan, noise, args.scans, args.seed,
                            tuple(args.velocity), pose, args.topic, overwrite=args.force)
    except (BagError, OSError, ValueError) as error:
        message = ' '.join(str(error).split()) or type(error).__name__
        print(f'simulate: error: {message}', file=sys.stderr)
        return USER_ERROR
    print(f'simulate: wrote {args.scans} scans of {args.plan} to {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
