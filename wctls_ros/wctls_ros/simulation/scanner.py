# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""An RPLIDAR S1-like scan simulator with a documented, seeded noise model."""

from dataclasses import dataclass
import math

import numpy as np

from .raycast import cast_rays

S1_BEAMS_PER_TURN = 1080          # sllidar_ros2's angle-compensated DenseBoost output at 10 Hz
S1_RANGE_SIGMA_M = 0.05           # datasheet depth accuracy the paper uses
S1_BEARING_SIGMA_RAD = math.radians(0.391)   # datasheet angular resolution the paper uses


@dataclass(frozen=True)
class NoiseModel:
    """
    Measurement noise of a simulated 2D LiDAR.

    For a beam at nominal bearing theta the simulator casts the ray at ``theta + d_theta`` and
    reports ``r + d_r + offset`` at the nominal bearing, with

    - ``d_theta ~ N(0, bearing_sigma_rad^2)``, independent per beam;
    - ``d_r ~ N(0, range_sigma_m^2 + (range_sigma_per_m * r)^2)``, independent per beam;
    - ``offset ~ N(0, common_range_offset_sigma_m^2)``, one draw per scan shared by all beams;
    - with ``dropout_probability`` a beam returns nothing (+inf, REP-117);
    - ranges outside [min_range_m, max_range_m] or rays that hit nothing are +inf.

    :ivar range_sigma_m: range noise std, m
    :ivar bearing_sigma_rad: bearing noise std, rad
    :ivar range_sigma_per_m: range noise std growing with the range, m per m
    :ivar common_range_offset_sigma_m: std of a per-scan range offset common to all beams, m
    :ivar dropout_probability: chance that a beam returns nothing
    :ivar min_range_m: closest measurable range, m
    :ivar max_range_m: farthest measurable range, m
    """

    range_sigma_m: float = S1_RANGE_SIGMA_M
    bearing_sigma_rad: float = S1_BEARING_SIGMA_RAD
    range_sigma_per_m: float = 0.0
    common_range_offset_sigma_m: float = 0.0
    dropout_probability: float = 0.0
    min_range_m: float = 0.05
    max_range_m: float = 40.0

    def __post_init__(self):
        for name in ('range_sigma_m', 'bearing_sigma_rad', 'range_sigma_per_m',
                     'common_range_offset_sigma_m', 'min_range_m'):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)}')
        if not 0.0 <= self.dropout_probability < 1.0:
            raise ValueError(f'dropout_probability must be in [0, 1), got '
                             f'{self.dropout_probability}')
        if not self.max_range_m > self.min_range_m:
            raise ValueError('max_range_m must exceed min_range_m')


NOISELESS = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0)


def full_turn_bearings(n_beams: int = S1_BEAMS_PER_TURN):
    """
    Return the beam geometry of a full-turn scan the way sllidar_ros2 publishes it.

    :param n_beams: number of beams, >= 2
    :return: (angle_min rad, angle_increment rad, bearings rad of shape (n_beams,)):
        -pi to +pi inclusive, increment 2 pi / (n_beams - 1)
    """
    increment = 2.0 * math.pi / (n_beams - 1)
    return -math.pi, increment, -math.pi + increment * np.arange(n_beams)


def simulate_ranges(walls_m: np.ndarray, bearings_rad: np.ndarray, noise: NoiseModel,
                    rng: np.random.Generator) -> np.ndarray:
    """
    Simulate one scan from a sensor at the origin of the walls' frame.

    :param walls_m: wall segments in the sensor frame, shape (K, 4), m
    :param bearings_rad: nominal beam bearings, shape (N,), rad
    :param noise: the noise model
    :param rng: random generator (seed it for repeatable scans)
    :return: measured ranges, shape (N,), m; +inf for no return
    """
    bearings = np.asarray(bearings_rad, dtype=float)
    true_bearings = bearings + rng.normal(0.0, noise.bearing_sigma_rad, bearings.shape)
    ranges = cast_rays(walls_m, np.zeros(2), true_bearings)
    hit = np.isfinite(ranges)
    sigma = np.hypot(noise.range_sigma_m, noise.range_sigma_per_m * np.where(hit, ranges, 0.0))
    offset = rng.normal(0.0, noise.common_range_offset_sigma_m)
    with np.errstate(invalid='ignore'):
        ranges = ranges + rng.normal(0.0, 1.0, bearings.shape) * sigma + offset
    dropped = rng.random(bearings.shape) < noise.dropout_probability
    out_of_range = ~((ranges >= noise.min_range_m) & (ranges <= noise.max_range_m))
    ranges[dropped | out_of_range] = np.inf
    return ranges
