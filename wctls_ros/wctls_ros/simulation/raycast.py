# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Exact 2D ray casting against wall segments (numpy only)."""

import numpy as np

# Rays grazing a wall at less than this |sin(angle)| do not hit it (their hit point is
# ill-conditioned and a real beam would not return from such a surface).
_GRAZING_SIN = 1e-9


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
    walls = np.asarray(walls_m, dtype=float).reshape(-1, 4)
    bearings = np.asarray(bearings_rad, dtype=float).ravel()
    origin = np.asarray(origin_m, dtype=float).reshape(2)
    ranges = np.full(bearings.shape, np.inf)
    if walls.size == 0 or bearings.size == 0:
        return ranges
    start = walls[:, :2] - origin                      # (K, 2), wall start relative to origin
    edge = walls[:, 2:] - walls[:, :2]                 # (K, 2)
    edge_length = np.hypot(edge[:, 0], edge[:, 1])
    for lo in range(0, bearings.size, chunk):
        dx = np.cos(bearings[lo:lo + chunk])[:, None]  # (n, 1)
        dy = np.sin(bearings[lo:lo + chunk])[:, None]
        denom = dx * edge[:, 1] - dy * edge[:, 0]      # cross(d, e), (n, K)
        t_num = start[:, 0] * edge[:, 1] - start[:, 1] * edge[:, 0]   # cross(p, e), (K,)
        s_num = start[:, 0] * dy - start[:, 1] * dx    # cross(p, d), (n, K)
        valid = np.abs(denom) > _GRAZING_SIN * edge_length
        with np.errstate(divide='ignore', invalid='ignore'):
            t = t_num / denom
            s = s_num / denom
        hit = valid & (t > 0.0) & (s >= 0.0) & (s <= 1.0)
        ranges[lo:lo + chunk] = np.where(hit, t, np.inf).min(axis=1)
    return ranges
