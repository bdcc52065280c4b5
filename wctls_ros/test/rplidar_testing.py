# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Helpers shared by the RPLIDAR tests: the emulator and its scene's true ranges."""

import math

import numpy as np
from wctls_ros.rplidar.emulator.device import Faults, S1Device
from wctls_ros.rplidar.emulator.process import EmulatorProcess
from wctls_ros.rplidar.protocol import encode_express_scan
from wctls_ros.s1_emulator import SimulatedScene
from wctls_ros.simulation import cast_rays, load_floor_plan, NOISELESS, NoiseModel

# The emulator's default scene: the bundled plan seen from its own sensor pose.
WALLS, _ = load_floor_plan('environment_a').in_sensor_frame()
# The emulator turns 995/64 degrees per DenseBoost capsule of 40 samples of 108 us: 100.03 ms.
EMULATOR_TURN_S = 360.0 * 64 / 995 * 40 * 108e-6


def true_ranges(bearings_rad):
    """
    Return the noiseless ranges of the emulator's scene along laser-frame bearings.

    :param bearings_rad: bearings, rad, counter-clockwise (REP-103)
    :return: ranges, m
    """
    return cast_rays(WALLS, np.zeros(2), np.asarray(bearings_rad, dtype=float))


def _cross(a, b):
    """Return the z component of the cross product of 2-D vectors (last axis)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _critical_bearings(walls):
    """
    Return the bearings at which the range, as a function of bearing, can have a local extreme.

    Between wall ends and wall crossings the nearest wall stays the same, and the range along one
    wall falls only up to the foot of its perpendicular and rises after it. So over any bearing
    interval the range is extreme at the interval's ends, at a wall end (a corner's kink, or an
    occlusion edge, approached from either side), at a crossing or at a perpendicular's foot.

    :param walls: wall segments in the laser frame, shape (K, 4), m
    :return: bearings, rad
    """
    start, edge = walls[:, :2], walls[:, 2:] - walls[:, :2]
    foot = -np.einsum('ij,ij->i', start, edge) / np.einsum('ij,ij->i', edge, edge)
    feet = start + np.clip(foot, 0.0, 1.0)[:, None] * edge
    denominator = _cross(edge[:, None], edge[None])
    between = start[None] - start[:, None]
    with np.errstate(divide='ignore', invalid='ignore'):
        along = _cross(between, edge[None]) / denominator
        other = _cross(between, edge[:, None]) / denominator
    first, second = np.nonzero((along >= 0.0) & (along <= 1.0) & (other >= 0.0) & (other <= 1.0))
    crossings = start[first] + along[first, second, None] * edge[first]
    ends = walls.reshape(-1, 2)
    points = np.concatenate([ends, feet, crossings])
    bearings = np.arctan2(points[:, 1], points[:, 0])
    # An occlusion edge is a jump: take the range just before and just after it too.
    return np.concatenate([bearings, bearings - 1e-9, bearings + 1e-9])


_CRITICAL_BEARINGS = _critical_bearings(WALLS)
_CRITICAL_RANGES = true_ranges(_CRITICAL_BEARINGS)


def range_band(low_rad, high_rad):
    """
    Return the scene's smallest and largest range over bearing intervals, exactly.

    Sampling an interval at a few bearings is not enough: a wall corner pointing at the sensor
    is a sharp minimum of the range between two samples. The walls being straight, the extremes
    lie at the interval's ends or at one of the scene's critical bearings inside it.

    :param low_rad: interval starts, rad
    :param high_rad: interval ends (at most a turn above the starts), rad
    :return: (lowest, highest) range per interval, m
    """
    low_rad, high_rad = np.broadcast_arrays(np.asarray(low_rad, float),
                                            np.asarray(high_rad, float))
    ends = true_ranges(np.stack([low_rad, high_rad], axis=-1).ravel()).reshape(-1, 2)
    inside = (np.mod(_CRITICAL_BEARINGS - low_rad.reshape(-1, 1), 2.0 * np.pi)
              <= (high_rad - low_rad).reshape(-1, 1))
    lowest = np.where(inside, _CRITICAL_RANGES, np.inf).min(axis=1)
    highest = np.where(inside, _CRITICAL_RANGES, -np.inf).max(axis=1)
    return (np.minimum(ends.min(axis=1), lowest).reshape(low_rad.shape),
            np.maximum(ends.max(axis=1), highest).reshape(low_rad.shape))


def compensated_beam_bands():
    """
    Return the scene's range band of each beam of a 1080-beam (DenseBoost) compensated scan.

    Beam i is bin b = 1079 - i, holding the last sample with raw angle in [(b - 2) / 3,
    (b + 1) / 3) degrees; its laser bearing is pi - raw.

    :return: (lowest, highest) range per beam, m
    """
    raw_bin = 1079 - np.arange(1080)
    return range_band(math.pi - np.radians((raw_bin + 1) / 3),
                      math.pi - np.radians((raw_bin - 2) / 3))


def denseboost_stream(plan='environment_a', seconds=3.0, noisy=False, seed=0):
    """
    Return the bytes an emulated S1 streams in DenseBoost, without waiting for them.

    :param plan: bundled floor plan
    :param seconds: stream length, s
    :param noisy: the S1's datasheet noise, else exact ranges
    :param seed: random seed
    :return: the capsules' bytes (after the scan descriptor)
    """
    walls, _ = load_floor_plan(plan).in_sensor_frame()
    rng = np.random.default_rng(seed)
    scene = SimulatedScene(walls, NoiseModel() if noisy else NOISELESS, rng)
    device = S1Device(scene, Faults(), (1, 28), rng)
    device.receive(encode_express_scan(1), 0.0)
    # The device keeps at most 0.5 s of frames due: ask in steps.
    return b''.join(device.stream(t) for t in np.arange(0.1, seconds + 0.05, 0.1))


def start_emulator(directory, *options):
    """
    Start a noiseless emulator whose terminal is linked at ``directory/ttyS1``.

    :param directory: a pathlib.Path for the link
    :param options: more emulator options
    :return: the running :class:`EmulatorProcess` (a context manager)
    """
    return EmulatorProcess(['--noiseless', '--link', str(directory / 'ttyS1'), *options])
