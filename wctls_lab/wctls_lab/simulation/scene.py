# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
What a scan sees at one instant: walls with their surfaces, cylinders, walking people.

Static properties of the scene live here (the floor plan builds them from YAML); the sensor's
own properties (noise, beam divergence, dropouts) live in :class:`~.scanner.NoiseModel`.
"""

from dataclasses import dataclass
import math

import numpy as np

from .visibility import visible_corners

# Random cosines summed into a wall's roughness profile.
ROUGHNESS_TERMS = 32
# Pieces that drop at least this share of their beams give the visibility rule no returns.
_SILENT_DROPOUT = 0.5


@dataclass(frozen=True)
class Surfaces:
    """
    The surface of every wall piece: how it reflects and how far it departs from a straight line.

    A piece's surface lies at ``displacement(x)`` from its straight line along the piece's left
    normal (left of the direction from its first end point to its second), x the distance from
    its first end point (m):

    - a bow: ``4 bow_m s (1 - s)``, s = x / length: a parabola with sagitta ``bow_m`` at the
      middle and 0 at the ends;
    - a fixed roughness profile, the same in every scan:
      ``sum_j amplitude_j cos(wavenumber_j x + phase_j) - offset``, built by the floor plan as a
      smooth random profile with a given RMS and correlation length.

    :ivar dropout: probability that a beam hitting the piece returns nothing, shape (K,);
        1 for a dark or glass piece
    :ivar bow_m: sagitta of the bow, shape (K,), m (positive: towards the left normal)
    :ivar amplitude_m: roughness cosine amplitudes, shape (K, J), m (0 for a smooth piece)
    :ivar wavenumber: roughness cosine wavenumbers, shape (K, J), rad/m
    :ivar phase: roughness cosine phases, shape (K, J), rad
    :ivar offset_m: mean of the roughness profile over the piece, removed, shape (K,), m
    :ivar wall_of: index of the straight wall each piece belongs to, shape (K,) (pieces of one
        wall are collinear and meet end to end)
    """

    dropout: np.ndarray
    bow_m: np.ndarray
    amplitude_m: np.ndarray
    wavenumber: np.ndarray
    phase: np.ndarray
    offset_m: np.ndarray
    wall_of: np.ndarray

    def __len__(self):
        return len(self.dropout)

    @staticmethod
    def plain(count: int) -> 'Surfaces':
        """
        Return straight, smooth, fully reflecting surfaces for ``count`` walls of their own.

        :param count: number of walls
        :return: the surfaces
        """
        zeros = np.zeros((count, ROUGHNESS_TERMS))
        return Surfaces(np.zeros(count), np.zeros(count), zeros, zeros, zeros, np.zeros(count),
                        np.arange(count))

    @property
    def shaped(self) -> bool:
        """
        Tell whether any piece is bowed or rough.

        :return: True when some piece departs from its straight line
        """
        return bool(np.any(self.bow_m != 0.0) or np.any(self.amplitude_m != 0.0))

    def select(self, pieces: np.ndarray) -> 'Surfaces':
        """
        Return the surfaces of some pieces.

        :param pieces: indices or a boolean mask over the pieces
        :return: the selected surfaces
        """
        return Surfaces(self.dropout[pieces], self.bow_m[pieces], self.amplitude_m[pieces],
                        self.wavenumber[pieces], self.phase[pieces], self.offset_m[pieces],
                        self.wall_of[pieces])

    def displacement_m(self, piece: np.ndarray, along: np.ndarray,
                       length_m: np.ndarray) -> np.ndarray:
        """
        Return the surface's departure from the straight piece at some points along it.

        :param piece: piece index of each point, shape (n,)
        :param along: position along the piece as a fraction from its first end point, (n,)
        :param length_m: length of each point's piece, shape (n,), m
        :return: displacement along the piece's left normal, shape (n,), m
        """
        x = along * length_m
        rough = np.einsum('nj,nj->n', self.amplitude_m[piece],
                          np.cos(self.wavenumber[piece] * x[:, None] + self.phase[piece]))
        return 4.0 * self.bow_m[piece] * along * (1.0 - along) + rough - self.offset_m[piece]


def roughness_profile(rms_m: float, correlation_length_m: float, length_m: float,
                      rng: np.random.Generator):
    """
    Draw a smooth random roughness profile for a piece of wall.

    A sum of random cosines with normally distributed wavenumbers (std 1 / correlation length)
    approximates a stationary Gaussian process with covariance exp(-d^2 / (2 l^2)); its samples
    on a fine grid over the piece are then shifted to mean 0 and scaled to the given RMS.

    :param rms_m: root mean square of the profile over the piece, m
    :param correlation_length_m: correlation length l, m (> 0)
    :param length_m: the piece's length, m (> 0)
    :param rng: random generator (seeded per piece: the profile is part of the scene)
    :return: (amplitude (J,) m, wavenumber (J,) rad/m, phase (J,) rad, offset m)
    """
    wavenumber = rng.normal(0.0, 1.0 / correlation_length_m, ROUGHNESS_TERMS)
    phase = rng.uniform(0.0, 2.0 * math.pi, ROUGHNESS_TERMS)
    # Eight samples per correlation length resolve the profile; the bounds keep it cheap.
    samples = int(np.clip(8.0 * length_m / correlation_length_m, 256, 16384))
    x = np.linspace(0.0, length_m, samples)
    raw = np.cos(np.outer(x, wavenumber) + phase).sum(axis=1)
    spread = float(np.std(raw))
    scale = rms_m / spread if spread > 0.0 else 0.0
    return np.full(ROUGHNESS_TERMS, scale), wavenumber, phase, float(np.mean(raw)) * scale


@dataclass(frozen=True)
class Walker:
    """
    A person walking back and forth along a path, seen as two leg cylinders.

    The body moves along the path at ``speed_m_s``, turning back at either end. The legs stand
    ``hip_width_m`` apart across the direction of walking and swing along it in opposite phase,
    each ``step_m / 2`` ahead of and behind the body, one gait cycle per two steps: at 10 Hz the
    legs move between every two scans.

    :ivar path_m: the path's points in plan coordinates, shape (P, 2), m (P >= 2)
    :ivar speed_m_s: walking speed, m/s
    :ivar leg_radius_m: radius of each leg, m
    :ivar hip_width_m: distance between the legs' centres across the path, m
    :ivar step_m: length of one step, m
    :ivar start_m: distance along the path at time 0, m
    """

    path_m: np.ndarray
    speed_m_s: float = 1.0
    leg_radius_m: float = 0.055
    hip_width_m: float = 0.2
    step_m: float = 0.6
    start_m: float = 0.0

    def legs_m(self, time_s: float) -> np.ndarray:
        """
        Return the two leg cylinders at a time.

        :param time_s: time since the start of the recording, s
        :return: shape (2, 3): x, y, radius in plan coordinates, m
        """
        edges = np.diff(self.path_m, axis=0)
        lengths = np.hypot(edges[:, 0], edges[:, 1])
        reached = np.concatenate([[0.0], np.cumsum(lengths)])      # path length at each point
        total = float(reached[-1])
        travelled = (self.start_m + self.speed_m_s * time_s) % (2.0 * total)
        backwards = travelled > total
        position = 2.0 * total - travelled if backwards else travelled
        k = int(np.clip(np.searchsorted(reached, position, side='right') - 1, 0,
                        len(lengths) - 1))
        direction = edges[k] / lengths[k]
        body = self.path_m[k] + (position - reached[k]) * direction
        heading = -direction if backwards else direction
        left = np.array([-heading[1], heading[0]])
        phase = math.pi * self.speed_m_s * time_s / self.step_m     # a cycle per two steps
        swing = 0.5 * self.step_m * math.sin(phase)
        legs = [body + side * 0.5 * self.hip_width_m * left + side * swing * heading
                for side in (1.0, -1.0)]
        return np.column_stack([np.array(legs), np.full(2, self.leg_radius_m)])


@dataclass(frozen=True)
class Scene:
    """
    Everything one scan sees, in the sensor's REP-103 frame.

    :ivar walls_m: wall pieces, shape (K, 4): x0, y0, x1, y1 in m
    :ivar surfaces: the pieces' surfaces (K of them)
    :ivar circles_m: cylinders (clutter, walkers' legs), shape (C, 3): x, y, radius in m
    """

    walls_m: np.ndarray
    surfaces: Surfaces
    circles_m: np.ndarray

    @staticmethod
    def of_walls(walls_m: np.ndarray) -> 'Scene':
        """
        Return a scene of plain walls and nothing else.

        :param walls_m: wall segments, shape (K, 4), m
        :return: the scene
        """
        walls = np.asarray(walls_m, dtype=float).reshape(-1, 4)
        return Scene(walls, Surfaces.plain(len(walls)), np.zeros((0, 3)))

    def visible(self, corners_m: np.ndarray, bearings_rad: np.ndarray) -> np.ndarray:
        """
        Return which true corners the sensor sees well enough to extract (see visible_corners).

        Cylinders block rays; pieces that drop at least half of their beams count as silent.

        :param corners_m: true corners in the sensor frame, shape (M, 2), m
        :param bearings_rad: the scan's beam bearings, shape (N,), rad
        :return: boolean, shape (M,)
        """
        return visible_corners(self.walls_m, corners_m, bearings_rad, circles_m=self.circles_m,
                               silent=self.surfaces.dropout >= _SILENT_DROPOUT,
                               wall_of=self.surfaces.wall_of)
