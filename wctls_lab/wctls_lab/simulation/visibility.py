# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Which true corners of a floor plan a sensor can see well enough to extract (numpy only)."""

import numpy as np

from wctls_rplidar.emulator.raycast import ray_hits

# A noiseless return lies on the wall it hit to within this distance, m.
_ON_WALL_M = 1e-6
# A corner is not occluded when the ray towards it ends this close to it, and a wall passes
# through it when its straight line passes this close, m (a corner on a bowed or rough wall lies
# on the wall's surface, a few mm off its straight line).
_UNOCCLUDED_M = 1e-2
# Two seen walls form a corner when they turn by more than 30 degrees.
_MIN_TURN_SIN = 0.5


def visible_corners(walls_m: np.ndarray, corners_m: np.ndarray, bearings_rad: np.ndarray,
                    min_points: int = 8, min_length_m: float = 0.15, max_gap_m: float = 0.1,
                    max_range_m: float = 40.0, min_incidence_cos: float = 0.17, *,
                    circles_m: np.ndarray = None, silent: np.ndarray = None,
                    wall_of: np.ndarray = None) -> np.ndarray:
    """
    Return which true corners a sensor at the origin sees with both of their walls.

    A corner counts as visible when the ray towards it is not blocked, and each of the two walls
    that meet there gets at least ``min_points`` noiseless returns spanning ``min_length_m`` at
    an incidence no more grazing than ``arccos(min_incidence_cos)`` (80 degrees by default) in
    one run of neighbouring beams from the corner, the nearest within ``max_gap_m`` of it. The
    run ends at the first beam that does not return usably from that wall: one shadowed by
    something nearer, one on a silent piece, or one too grazing; returns beyond such a gap are
    another piece of the wall, which an extractor sees as a separate segment. A
    corner formed by a free-standing edge (one wall hidden) is not visible. Cylinders (clutter,
    walkers' legs) block rays; silent pieces (dark, glass) return nothing; collinear pieces of one
    wall count together. This is the ground truth an extractor can be held to: what it could
    possibly find.

    :param walls_m: wall segments in the sensor frame, shape (K, 4), m
    :param corners_m: true corners in the sensor frame, shape (M, 2), m
    :param bearings_rad: the scan's beam bearings, shape (N,), rad
    :param min_points: returns needed on each wall near the corner
    :param min_length_m: extent the returns on each wall must span, m
    :param max_gap_m: largest distance from the corner to the nearest return on each wall, m
    :param max_range_m: the sensor's largest range, m
    :param min_incidence_cos: smallest cosine between a beam and the wall normal that counts
    :param circles_m: cylinders that block rays, shape (C, 3): x, y, radius in m (default none)
    :param silent: which wall pieces return nothing, shape (K,) (default none)
    :param wall_of: the straight wall each piece belongs to, shape (K,) (default: its own)
    :return: boolean, shape (M,)
    """
    walls = np.asarray(walls_m, dtype=float).reshape(-1, 4)
    corners = np.asarray(corners_m, dtype=float).reshape(-1, 2)
    bearings = np.asarray(bearings_rad, dtype=float).ravel()
    circles = np.zeros((0, 3)) if circles_m is None else np.asarray(circles_m, dtype=float)
    ranges = ray_hits(walls, circles, np.zeros(2), bearings).range_m
    hit = np.isfinite(ranges) & (ranges <= max_range_m)
    direction = np.column_stack([np.cos(bearings), np.sin(bearings)])
    points = np.full((bearings.size, 2), np.inf)                          # (N, 2), beam order
    points[hit] = ranges[hit, None] * direction[hit]
    start, edge = walls[:, :2], walls[:, 2:] - walls[:, :2]
    length = np.hypot(edge[:, 0], edge[:, 1])
    normal = np.column_stack([-edge[:, 1], edge[:, 0]]) / length[:, None]
    # Which wall each return lies on (distance to the wall's line and within its extent).
    with np.errstate(invalid='ignore'):
        along = np.einsum('pki,ki->pk', points[:, None, :] - start, edge) / length ** 2
        across = np.abs(np.einsum('pki,ki->pk', points[:, None, :] - start, normal))
    on_wall = hit[:, None] & (across < _ON_WALL_M) & (along >= -1e-9) & (along <= 1.0 + 1e-9)
    incidence_ok = np.abs(direction @ normal.T) >= min_incidence_cos
    usable = on_wall & incidence_ok                                    # (N, K)
    if silent is not None:
        usable &= ~np.asarray(silent, dtype=bool)
    full_turn = bearings.size > 1 and abs(
        (bearings[-1] - bearings[0]) * bearings.size / (bearings.size - 1)) >= 2.0 * np.pi - 1e-6

    group = np.arange(len(walls)) if wall_of is None else np.asarray(wall_of)

    corner_range = np.hypot(corners[:, 0], corners[:, 1])
    towards = ray_hits(walls, circles, np.zeros(2), np.arctan2(corners[:, 1], corners[:, 0])
                       ).range_m
    unoccluded = (towards >= corner_range - _UNOCCLUDED_M) & (corner_range <= max_range_m)
    visible = np.zeros(len(corners), dtype=bool)
    for m in np.flatnonzero(unoccluded):
        # Walls through the corner: those ending there and any it lies on (e.g. a cabinet's
        # side meets the room wall its back stands against).
        relative = corners[m] - start
        t = np.clip(np.einsum('ki,ki->k', relative, edge) / length ** 2, 0.0, 1.0)
        through = np.hypot(*(relative - t[:, None] * edge).T) < _UNOCCLUDED_M
        distance = np.hypot(*(points - corners[m]).T)
        seen = []
        for wall in np.unique(group[through]):
            run = _run_from_corner(usable[:, group == wall].any(axis=1), distance, full_turn)
            if run.size and distance[run].min() <= max_gap_m and run.size >= min_points and (
                    np.ptp(distance[run]) >= min_length_m):
                k = np.flatnonzero(through & (group == wall))[0]
                seen.append(np.arctan2(edge[k, 1], edge[k, 0]))
        turns = np.abs(np.sin(np.subtract.outer(seen, seen)))
        visible[m] = bool((turns > _MIN_TURN_SIN).any())
    return visible


def _run_from_corner(on_wall: np.ndarray, distance_m: np.ndarray, full_turn: bool) -> np.ndarray:
    """
    Return the beams of the unbroken run of a wall's returns that starts nearest the corner.

    :param on_wall: whether each beam returns usably from the wall, shape (N,), beam order
    :param distance_m: each beam's return's distance from the corner, shape (N,), m (inf: none)
    :param full_turn: the beams close a full turn (the last neighbours the first)
    :return: beam indices of the run, shape (R,); empty when no beam returns from the wall
    """
    if not on_wall.any():
        return np.zeros(0, dtype=int)
    nearest = int(np.argmin(np.where(on_wall, distance_m, np.inf)))
    count = on_wall.size
    if full_turn and on_wall.all():
        return np.arange(count)
    beams = [nearest]
    for step in (-1, 1):
        index = nearest + step
        while (full_turn or 0 <= index < count) and on_wall[index % count]:
            beams.append(index % count)
            index += step
    return np.array(sorted(beams))
