# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Exact 2D ray casting against wall segments and circles (numpy only)."""

from dataclasses import dataclass

import numpy as np

# Rays grazing a wall at less than this |sin(angle)| do not hit it (their hit point is
# ill-conditioned and a real beam would not return from such a surface).
_GRAZING_SIN = 1e-9


@dataclass(frozen=True)
class RayHits:
    """
    What each ray hits first.

    :ivar range_m: distance to the hit, shape (N,), m; ``inf`` where a ray hits nothing
    :ivar surface: index of the surface hit, shape (N,): ``k`` for wall k, ``K + c`` for circle
        c (K walls), -1 for nothing
    :ivar along: position of the hit along its wall as a fraction of the wall from its first
        end point (0) to its second (1), shape (N,); NaN on circles and misses
    """

    range_m: np.ndarray
    surface: np.ndarray
    along: np.ndarray


def cast_rays(walls_m: np.ndarray, origin_m: np.ndarray, bearings_rad: np.ndarray,
              chunk: int = 4096) -> np.ndarray:
    """
    Return the distance from ``origin_m`` to the first wall along each bearing.

    :param walls_m: wall segments, shape (K, 4): x0, y0, x1, y1 in m
    :param origin_m: ray origin, shape (2,), m, same frame as the walls
    :param bearings_rad: ray directions, shape (N,), rad, counter-clockwise from +x
    :param chunk: rays handled per vectorised block (bounds memory to chunk * K)
    :return: ranges, shape (N,), m; ``inf`` where a ray hits nothing
    """
    walls, origin, bearings = _inputs(walls_m, origin_m, bearings_rad)
    ranges = np.full(bearings.shape, np.inf)
    if walls.size == 0:
        return ranges
    for lo in range(0, bearings.size, chunk):
        ranges[lo:lo + chunk] = _wall_distances(walls, origin, bearings[lo:lo + chunk])[0].min(
            axis=1)
    return ranges


def _inputs(walls_m, origin_m, bearings_rad):
    """Return the walls (K, 4), the origin (2,) and the bearings (N,) as float arrays."""
    return (np.asarray(walls_m, dtype=float).reshape(-1, 4),
            np.asarray(origin_m, dtype=float).reshape(2),
            np.asarray(bearings_rad, dtype=float).ravel())


def _wall_distances(walls: np.ndarray, origin: np.ndarray, bearings: np.ndarray):
    """Return each ray's distance to each wall (inf: missed) and the hit's fraction along it."""
    start = walls[:, :2] - origin                      # (K, 2), wall start relative to origin
    edge = walls[:, 2:] - walls[:, :2]                 # (K, 2)
    edge_length = np.hypot(edge[:, 0], edge[:, 1])
    dx = np.cos(bearings)[:, None]                     # (n, 1)
    dy = np.sin(bearings)[:, None]
    denom = dx * edge[:, 1] - dy * edge[:, 0]          # cross(d, e), (n, K)
    t_num = start[:, 0] * edge[:, 1] - start[:, 1] * edge[:, 0]   # cross(p, e), (K,)
    s_num = start[:, 0] * dy - start[:, 1] * dx        # cross(p, d), (n, K)
    valid = np.abs(denom) > _GRAZING_SIN * edge_length
    with np.errstate(divide='ignore', invalid='ignore'):
        t = t_num / denom
        s = s_num / denom
    hit = valid & (t > 0.0) & (s >= 0.0) & (s <= 1.0)
    return np.where(hit, t, np.inf), s


def ray_hits(walls_m: np.ndarray, circles_m: np.ndarray, origin_m: np.ndarray,
             bearings_rad: np.ndarray, chunk: int = 4096) -> RayHits:
    """
    Return the first wall or circle each ray from ``origin_m`` hits, and where.

    A ray that starts inside a circle hits it where it leaves it.

    :param walls_m: wall segments, shape (K, 4): x0, y0, x1, y1 in m
    :param circles_m: circles (cylinders seen from above), shape (C, 3): x, y, radius in m
    :param origin_m: ray origin, shape (2,), m, same frame as the walls
    :param bearings_rad: ray directions, shape (N,), rad, counter-clockwise from +x
    :param chunk: rays handled per vectorised block (bounds memory to chunk * (K + C))
    :return: the hits
    """
    walls, origin, bearings = _inputs(walls_m, origin_m, bearings_rad)
    circles = np.asarray(circles_m, dtype=float).reshape(-1, 3)
    ranges = np.full(bearings.shape, np.inf)
    surface = np.full(bearings.shape, -1, dtype=np.intp)
    along = np.full(bearings.shape, np.nan)
    if bearings.size == 0 or walls.size + circles.size == 0:
        return RayHits(ranges, surface, along)
    centre = circles[:, :2] - origin                   # (C, 2)
    for lo in range(0, bearings.size, chunk):
        part = bearings[lo:lo + chunk]
        distance, s = _wall_distances(walls, origin, part)
        if len(circles):
            distance = np.hstack([distance, _circle_distances(
                centre, circles[:, 2], np.cos(part)[:, None], np.sin(part)[:, None])])
        rows = np.arange(distance.shape[0])
        first = np.argmin(distance, axis=1)
        ranges[lo:lo + chunk] = distance[rows, first]
        found = np.isfinite(ranges[lo:lo + chunk])
        surface[lo:lo + chunk] = np.where(found, first, -1)
        on_wall = found & (first < len(walls))
        along[lo:lo + chunk][on_wall] = s[rows[on_wall], first[on_wall]]
    return RayHits(ranges, surface, along)


def _circle_distances(centre: np.ndarray, radius: np.ndarray, dx: np.ndarray, dy: np.ndarray):
    """Return the distance along each ray (n, 1) to each circle (C,), inf when missed, (n, C)."""
    projection = dx * centre[:, 0] + dy * centre[:, 1]                 # (n, C)
    closest_sq = centre[:, 0] ** 2 + centre[:, 1] ** 2 - projection ** 2
    half_chord_sq = radius ** 2 - closest_sq
    half_chord = np.sqrt(np.maximum(half_chord_sq, 0.0))
    near, far = projection - half_chord, projection + half_chord
    distance = np.where(near > 0.0, near, far)
    return np.where((half_chord_sq >= 0.0) & (distance > 0.0), distance, np.inf)
