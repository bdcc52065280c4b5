# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
An RPLIDAR S1-like scan simulator with a documented, seeded sensor model.

Besides range and bearing noise the model knows what real scanners do that clean geometry does
not: mixed pixels at range discontinuities (a beam of finite divergence straddling the edge of a
nearer surface returns a range between the two: the "veils" SICK and Hokuyo scans show behind
every edge), dropouts (at a rate, and on dark or glass surfaces of the scene), how a driver
reports "no return" (+inf per REP-117, 0, or the maximum range), a per-scan common-mode range
offset, and the bearing quantisation of sllidar_ros2's ``angle_compensate`` binning. Every
addition defaults to off, so the default model gives the same scans it always gave.
"""

from dataclasses import dataclass
import math

import numpy as np
from wctls_rplidar.emulator.raycast import cast_rays, ray_hits

from .scene import Scene

S1_BEAMS_PER_TURN = 1080          # sllidar_ros2's angle-compensated DenseBoost output at 10 Hz
S1_RANGE_SIGMA_M = 0.05           # datasheet depth accuracy the paper uses
S1_BEARING_SIGMA_RAD = math.radians(0.391)   # datasheet angular resolution the paper uses


# What a driver writes for a beam without a return: +inf (REP-117, sllidar_ros2), 0 (below
# range_min: what the SICK and Hokuyo drivers of the recordings in data/ write) or the maximum
# range itself (which REP-117 cannot tell from a real return at that range).
NO_RETURN_VALUES = ('inf', 'zero', 'max')
# Sub-rays sampled across the footprint of a beam with divergence (odd: one is the centre).
FOOTPRINT_RAYS = 9
# A surface's shape moves a return by its displacement / cos(incidence), with the incidence
# capped here: the first-order shift of a plane grows without bound at grazing incidence.
_MAX_SHIFT_INCIDENCE_COS = math.cos(math.radians(80.0))


@dataclass(frozen=True)
class NoiseModel:
    """
    Measurement model of a simulated 2D LiDAR.

    For a beam at nominal bearing theta the simulator casts rays around ``theta + d_theta`` and
    reports ``r + d_r + offset`` at the nominal bearing, with

    - ``d_theta ~ N(0, bearing_sigma_rad^2) + U(-q/2, q/2)``, independent per beam, q =
      ``bearing_quantum_rad``: the sample's true bearing anywhere within the bin it is
      published in (sllidar_ros2's ``angle_compensate`` puts DenseBoost samples into 1/3 deg
      bins; the sawtooth of real sample phases is approximated by independent draws);
    - r: with ``beam_divergence_rad`` = 0 the range of the ray at ``theta + d_theta``; with a
      divergence, the footprint is sampled by FOOTPRINT_RAYS sub-rays evenly spread over the
      divergence (a top-hat beam): when every echoing sub-ray hits the surface the centre hits,
      r is the centre's range; otherwise (a mixed pixel) r is the mean range of the echoing
      sub-rays, i.e. the ranges weighted by the footprint fraction on each surface, and when
      less than half of the footprint echoes there is no return;
    - a surface's bow and roughness shift r by their displacement over the cosine of the
      incidence (capped at 80 deg);
    - ``d_r ~ N(0, range_sigma_m^2 + (range_sigma_per_m * r)^2)``, independent per beam;
    - ``offset ~ N(0, common_range_sigma_m^2)``, one draw per scan shared by all beams;
    - a beam returns nothing with probability ``dropout_probability`` (combined with the
      dropout of the surface its centre hits; dark and glass surfaces never echo);
    - ranges outside [min_range_m, max_range_m] or without echo return nothing, written as
      ``no_return`` says: 'inf' (+inf, REP-117), 'zero' (0.0) or 'max' (max_range_m).

    :ivar range_sigma_m: range noise std, m
    :ivar bearing_sigma_rad: bearing noise std, rad
    :ivar range_sigma_per_m: range noise std growing with the range, m per m
    :ivar common_range_sigma_m: std of a per-scan range offset common to all beams, m
    :ivar dropout_probability: chance that a beam returns nothing
    :ivar min_range_m: closest measurable range, m
    :ivar max_range_m: farthest measurable range, m
    :ivar beam_divergence_rad: full angle of the beam footprint, rad (0: an ideal ray)
    :ivar bearing_quantum_rad: width of the bins bearings are published in, rad (0: exact)
    :ivar no_return: how a beam without a return is written: 'inf', 'zero' or 'max'
    """

    range_sigma_m: float = S1_RANGE_SIGMA_M
    bearing_sigma_rad: float = S1_BEARING_SIGMA_RAD
    range_sigma_per_m: float = 0.0
    common_range_sigma_m: float = 0.0
    dropout_probability: float = 0.0
    min_range_m: float = 0.05
    max_range_m: float = 40.0
    beam_divergence_rad: float = 0.0
    bearing_quantum_rad: float = 0.0
    no_return: str = 'inf'

    def __post_init__(self):
        for name in ('range_sigma_m', 'bearing_sigma_rad', 'range_sigma_per_m',
                     'common_range_sigma_m', 'min_range_m'):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)}')
        for name in ('beam_divergence_rad', 'bearing_quantum_rad'):
            if not 0.0 <= getattr(self, name) <= 0.1:
                raise ValueError(f'{name} must be in [0, 0.1] rad, got {getattr(self, name)}')
        if not 0.0 <= self.dropout_probability < 1.0:
            raise ValueError(f'dropout_probability must be in [0, 1), got '
                             f'{self.dropout_probability}')
        if not self.max_range_m > self.min_range_m:
            raise ValueError('max_range_m must exceed min_range_m')
        if self.no_return not in NO_RETURN_VALUES:
            raise ValueError(f'no_return must be one of {NO_RETURN_VALUES}, got '
                             f'{self.no_return!r}')

    def describe(self) -> str:
        """
        Return the noise the corner covariances are computed with, in readable units.

        :return: e.g. 'range 50.00 mm, bearing 0.391 deg, common-mode range offset 0.00 mm'
        """
        return (f'range {1e3 * self.range_sigma_m:.2f} mm, bearing '
                f'{math.degrees(self.bearing_sigma_rad):.3f} deg, common-mode range offset '
                f'{1e3 * self.common_range_sigma_m:.2f} mm')

    @property
    def no_return_m(self) -> float:
        """
        Return the value written for a beam without a return.

        :return: +inf, 0.0 or max_range_m, m
        """
        return {'inf': math.inf, 'zero': 0.0, 'max': self.max_range_m}[self.no_return]


NOISELESS = NoiseModel(range_sigma_m=0.0, bearing_sigma_rad=0.0)
# The sensor models the tools name (simulate --sensor): the datasheet figures as noise (the
# paper's reading), a quiet S1 (1 cm, 0.05 deg), and an S1 as we expect a real one to look;
# docs/results/score.md gives the reasons for every number of 's1_like'.
SENSOR_MODELS = {
    'datasheet': NoiseModel(),
    '1cm': NoiseModel(range_sigma_m=0.01, bearing_sigma_rad=math.radians(0.05)),
    's1_like': NoiseModel(range_sigma_m=0.02, bearing_sigma_rad=math.radians(0.05),
                          common_range_sigma_m=0.001, dropout_probability=0.01,
                          beam_divergence_rad=math.radians(0.4),
                          bearing_quantum_rad=math.radians(1.0 / 3.0)),
}


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
    Simulate one scan of plain walls from a sensor at the origin of the walls' frame.

    :param walls_m: wall segments in the sensor frame, shape (K, 4), m
    :param bearings_rad: nominal beam bearings, shape (N,), rad
    :param noise: the sensor model
    :param rng: random generator (seed it for repeatable scans)
    :return: measured ranges, shape (N,), m; ``noise.no_return_m`` for no return
    """
    return simulate_scan(Scene.of_walls(walls_m), bearings_rad, noise, rng)


def simulate_scan(scene: Scene, bearings_rad: np.ndarray, noise: NoiseModel,
                  rng: np.random.Generator) -> np.ndarray:
    """
    Simulate one scan of a scene from a sensor at the origin of its frame.

    :param scene: what the sensor sees, in its frame
    :param bearings_rad: nominal beam bearings, shape (N,), rad
    :param noise: the sensor model
    :param rng: random generator (seed it for repeatable scans)
    :return: measured ranges, shape (N,), m; ``noise.no_return_m`` for no return
    """
    bearings = np.asarray(bearings_rad, dtype=float)
    true_bearings = bearings + rng.normal(0.0, noise.bearing_sigma_rad, bearings.shape)
    if noise.bearing_quantum_rad > 0.0:
        true_bearings += noise.bearing_quantum_rad * rng.uniform(-0.5, 0.5, bearings.shape)
    ranges, piece = _footprint_ranges(scene, true_bearings, noise.beam_divergence_rad)
    hit = np.isfinite(ranges)
    sigma = np.hypot(noise.range_sigma_m, noise.range_sigma_per_m * np.where(hit, ranges, 0.0))
    offset = rng.normal(0.0, noise.common_range_sigma_m)
    with np.errstate(invalid='ignore'):
        ranges = ranges + rng.normal(0.0, 1.0, bearings.shape) * sigma + offset
    draw = rng.random(bearings.shape)
    surface_dropout = np.zeros(bearings.shape)
    on_wall = (piece >= 0) & (piece < len(scene.walls_m))
    surface_dropout[on_wall] = scene.surfaces.dropout[piece[on_wall]]
    # Independent causes: the beam survives both the sensor's and the surface's dropout.
    chance = np.where(surface_dropout > 0.0,
                      1.0 - (1.0 - noise.dropout_probability) * (1.0 - surface_dropout),
                      noise.dropout_probability)
    dropped = draw < chance
    out_of_range = ~((ranges >= noise.min_range_m) & (ranges <= noise.max_range_m))
    ranges[dropped | out_of_range] = noise.no_return_m
    return ranges


def _footprint_ranges(scene: Scene, bearings: np.ndarray, divergence_rad: float):
    """
    Return each beam's noiseless range over its footprint and the surface its centre hits.

    :return: (ranges (N,) m, +inf without echo; surface index (N,) as in RayHits)
    """
    count = FOOTPRINT_RAYS if divergence_rad > 0.0 else 1
    if (count == 1 and not len(scene.circles_m) and not np.any(scene.surfaces.dropout)
            and not scene.surfaces.shaped):
        # Plain walls and an ideal ray (the emulator's every capsule): no hit details needed.
        return (cast_rays(scene.walls_m, np.zeros(2), bearings),
                np.full(bearings.shape, -1, dtype=np.intp))
    offsets = divergence_rad * ((np.arange(count) + 0.5) / count - 0.5)
    rays = (bearings[:, None] + offsets).ravel()
    hits = ray_hits(scene.walls_m, scene.circles_m, np.zeros(2), rays)
    ranges = hits.range_m
    on_wall = (hits.surface >= 0) & (hits.surface < len(scene.walls_m))
    if scene.surfaces.shaped and on_wall.any():
        ranges = ranges.copy()
        ranges[on_wall] += _surface_shift(scene, hits.surface[on_wall], hits.along[on_wall],
                                          rays[on_wall])
    dark = np.zeros(rays.shape, dtype=bool)
    dark[on_wall] = scene.surfaces.dropout[hits.surface[on_wall]] >= 1.0
    echo = (np.isfinite(ranges) & ~dark).reshape(-1, count)
    ranges = ranges.reshape(-1, count)
    surface = hits.surface.reshape(-1, count)
    centre = count // 2
    one_surface = echo[:, centre] & np.all(~echo | (surface == surface[:, centre:centre + 1]),
                                           axis=1)
    echoes = echo.sum(axis=1)
    with np.errstate(invalid='ignore', divide='ignore'):
        mixed = np.where(echo, ranges, 0.0).sum(axis=1) / echoes
    out = np.where(one_surface, ranges[:, centre],
                   np.where(2 * echoes >= count, mixed, np.inf))
    return out, surface[:, centre]


def _surface_shift(scene: Scene, piece: np.ndarray, along: np.ndarray,
                   bearings: np.ndarray) -> np.ndarray:
    """Return how far each wall hit moves along its ray because of the surface's shape, m."""
    walls = scene.walls_m[piece]
    edge = walls[:, 2:] - walls[:, :2]
    length = np.hypot(edge[:, 0], edge[:, 1])
    # cos of the angle between the ray and the piece's left normal (-e_y, e_x) / |e|.
    cosine = (-np.cos(bearings) * edge[:, 1] + np.sin(bearings) * edge[:, 0]) / length
    cosine = np.copysign(np.maximum(np.abs(cosine), _MAX_SHIFT_INCIDENCE_COS), cosine)
    return scene.surfaces.displacement_m(piece, along, length) / cosine
