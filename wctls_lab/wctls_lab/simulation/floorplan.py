# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
2D floor plans loaded from YAML: walls, their true corners and surfaces, clutter, walkers.

A plan is static structure (polylines and boxes: the walls and furniture a map should hold,
whose turning vertices are the true corners), surfaces of wall pieces (bowed, rough, dark),
clutter (small boxes and cylinders such as chair and table legs: they occlude and reflect but
their corners are not landmarks) and walkers (people crossing the room, their legs moving every
scan). YAML keys, all lengths in m and angles in degrees::

    name: my_room
    description: what the scene represents
    base: environment_a          # optional: start from a bundled plan (or a YAML path relative
                                 # to this file) and add what follows to it
    sensor: {x: 2.2, y: 1.25, yaw_deg: 0.0}
    polylines:
      - {closed: true, points: [[0, 0], [4.5, 0], [4.5, 2.5], [0, 2.5]]}
    boxes:
      - {center: [2.1, 0.7], size: [0.25, 0.25], yaw_deg: 45}
    surfaces:                    # a piece of one wall, from one point on it to another
      - {from: [1.1, 0.0], to: [2.6, 0.0], bow_m: 0.004, roughness_m: 0.002,
         roughness_length_m: 0.1, dropout: 0.2, seed: 7}
      - {from: [0.0, 0.6], to: [0.0, 1.4], dark: true}          # glass: no return at all
    clutter:
      - {cylinder: [1.2, 0.8], radius_m: 0.012}                 # a chair leg
      - {box: [2.9, 1.6], size: [0.04, 0.04], yaw_deg: 0}       # a table leg
    walkers:
      - {path: [[0.8, 0.6], [3.6, 1.9]], speed_m_s: 1.0, leg_radius_m: 0.055,
         hip_width_m: 0.2, step_m: 0.6, start_m: 0.0}

A surface's bow (sagitta at its middle) is positive towards the left of the direction from
``from`` to ``to``; its roughness is a fixed smooth random profile (RMS ``roughness_m``,
correlation length ``roughness_length_m``, drawn with ``seed``; default: the surface's number),
identical in every scan. Shapes may touch but should not overlap: the true corners are their
turning vertices, and a vertex without free space around it is not one.
"""

from dataclasses import dataclass
from importlib import resources
import math
import pathlib
from typing import Optional, Tuple, Union

import numpy as np
from wctls_ros.plain_yaml import load_without_aliases
import yaml

from .scene import roughness_profile, Scene, Surfaces, Walker

BUNDLED_PLANS = ('environment_a', 'environment_b', 'environment_a_cluttered',
                 'environment_b_cluttered')
# Seen from the free space: 'inside' = concave (a room's corner), 'outside' = convex (a box's).
CORNER_KINDS = ('inside', 'outside')
# A vertex is a corner when its walls turn by more than this (straight joints are not corners).
_MIN_CORNER_TURN_RAD = np.radians(10.0)
# A point lies on a wall when it is this close to it, m.
_ON_WALL_M = 1e-3
# Free space around a corner is probed this far from it, m.
_PROBE_M = 1e-4
# Bounds on a plan: a small YAML file must not make the loader allocate without limit.
_MAX_TEXT_CHARS = 1_000_000
_MAX_SHAPES = 1000
_MAX_POINTS = 10_000
_MAX_WALLS = 20_000
_MAX_ITEMS = 2000
_MAX_WALKERS = 20
_MAX_BASE_DEPTH = 4
_MAX_COORDINATE_M = 1e4
_KEYS = ('name', 'description', 'base', 'sensor', 'polylines', 'boxes', 'surfaces', 'clutter',
         'walkers')
_LISTS = ('polylines', 'boxes', 'surfaces', 'clutter', 'walkers')


@dataclass(frozen=True)
class FloorPlan:
    """
    A 2D scene in plan coordinates (m, rad; x, y in the floor plane).

    :ivar name: short identifier
    :ivar description: what the scene represents
    :ivar walls_m: wall pieces (structure and clutter boxes), shape (K, 4): x0, y0, x1, y1 in m
    :ivar corners_m: true corners (turning vertices of the structure), shape (M, 2), m
    :ivar sensor_pose: default sensor pose (x m, y m, yaw rad) in plan coordinates
    :ivar corner_kinds: 'inside' or 'outside' for each true corner, length M
    :ivar surfaces: the surface of each wall piece (K of them)
    :ivar cylinders_m: clutter cylinders, shape (C, 3): x, y, radius in m
    :ivar walkers: people walking through the scene
    """

    name: str
    description: str
    walls_m: np.ndarray
    corners_m: np.ndarray
    sensor_pose: tuple
    corner_kinds: Tuple[str, ...]
    surfaces: Surfaces
    cylinders_m: np.ndarray
    walkers: Tuple[Walker, ...]

    def in_sensor_frame(self, pose=None):
        """
        Return the walls and corners seen from a sensor pose, in the sensor's REP-103 frame.

        :param pose: (x m, y m, yaw rad) in plan coordinates; the plan's sensor pose if None
        :return: (walls (K, 4), corners (M, 2)) in the sensor frame, m
        """
        walls = self.to_sensor_frame(self.walls_m.reshape(-1, 2), pose).reshape(-1, 4)
        return walls, self.to_sensor_frame(self.corners_m, pose)

    def to_sensor_frame(self, points_m: np.ndarray, pose=None) -> np.ndarray:
        """
        Return plan points in the frame of a sensor at a pose.

        :param points_m: shape (P, 2), m, plan coordinates
        :param pose: (x m, y m, yaw rad) in plan coordinates; the plan's sensor pose if None
        :return: shape (P, 2), m, sensor frame
        """
        x, y, yaw = self.sensor_pose if pose is None else pose
        c, s = np.cos(yaw), np.sin(yaw)
        # plan -> sensor: R(yaw)^T (p - t); as row vectors p' = (p - t) R.
        return (np.asarray(points_m, dtype=float) - np.array([x, y])) @ np.array([[c, -s],
                                                                                 [s, c]])

    def scene(self, pose=None, time_s: float = 0.0) -> Scene:
        """
        Return what a sensor at a pose sees at a time (walkers move), in its frame.

        :param pose: (x m, y m, yaw rad) in plan coordinates; the plan's sensor pose if None
        :param time_s: time since the start of the recording, s
        :return: the scene
        """
        walls, _ = self.in_sensor_frame(pose)
        circles = np.vstack([self.cylinders_m] + [w.legs_m(time_s) for w in self.walkers])
        circles[:, :2] = self.to_sensor_frame(circles[:, :2], pose)
        return Scene(walls, self.surfaces, circles)


def _fail(plan: str, where: str, message: str):
    raise ValueError(f'floor plan {plan!r}: {where}: {message}')


def _number(value, plan: str, where: str, low: float = -_MAX_COORDINATE_M,
            high: float = _MAX_COORDINATE_M, open_low: bool = False) -> float:
    """Return a real number within [low, high] (or (low, high]), or fail with the reason."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        _fail(plan, where, f'expected a number, got {value!r}')
    value = float(value)
    if not (low < value if open_low else low <= value) or not value <= high:
        _fail(plan, where, f'{value!r} is outside {"(" if open_low else "["}{low:g}, {high:g}]')
    return value


def _points(value, plan: str, where: str, minimum: int, maximum: int) -> np.ndarray:
    """Return a list of [x, y] points as an (n, 2) array, or fail with the reason."""
    if not isinstance(value, (list, tuple)) or not minimum <= len(value) <= maximum:
        _fail(plan, where, f'expected a list of {minimum} to {maximum} [x, y] points')
    rows = []
    for k, point in enumerate(value):
        if not isinstance(point, (list, tuple)) or len(point) != 2:
            _fail(plan, f'{where}[{k}]', f'expected [x, y], got {point!r}')
        rows.append([_number(c, plan, f'{where}[{k}]') for c in point])
    return np.array(rows, dtype=float).reshape(-1, 2)


def _mapping(value, plan: str, where: str, keys: tuple) -> dict:
    """Return a mapping with only known keys, or fail with the reason."""
    if not isinstance(value, dict):
        _fail(plan, where, f'expected a mapping, got {type(value).__name__}')
    unknown = sorted(str(k) for k in value if k not in keys)
    if unknown:
        _fail(plan, where, f'unknown keys {unknown}; known: {list(keys)}')
    return value


def _box_polygon(center, size, yaw_deg=0.0):
    """Return the four vertices of a rectangle, counter-clockwise."""
    half = np.asarray(size, dtype=float) / 2.0
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    yaw = np.radians(yaw_deg)
    rotation = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    return local @ rotation.T + np.asarray(center, dtype=float)


def _box(item: dict, plan: str, where: str, center_key: str) -> np.ndarray:
    """Return the vertices of a box given by its centre, size and yaw."""
    center = _points([item.get(center_key)], plan, f'{where}.{center_key}', 1, 1)[0]
    size = item.get('size')
    if not isinstance(size, (list, tuple)) or len(size) != 2:
        _fail(plan, f'{where}.size', f'expected [width, height], got {size!r}')
    size = [_number(v, plan, f'{where}.size', 0.0, 1e3, open_low=True) for v in size]
    return _box_polygon(center, size, _number(item.get('yaw_deg', 0.0), plan,
                                              f'{where}.yaw_deg', -360.0, 360.0))


def _polyline_walls_and_corners(points, closed):
    """Return the wall segments and the turning vertices of a polyline."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) < 2:
        raise ValueError(f'a wall polyline needs at least 2 points, got {len(points)}')
    ends = np.roll(points, -1, axis=0) if closed else points[1:]
    starts = points if closed else points[:-1]
    walls = np.hstack([starts, ends])
    directions = ends - starts
    headings = np.arctan2(directions[:, 1], directions[:, 0])
    if closed:
        turns = headings - np.roll(headings, 1)
        vertices = points
    else:
        turns = headings[1:] - headings[:-1]
        vertices = points[1:-1]
    turns = np.abs(np.angle(np.exp(1j * turns)))
    return walls, vertices[turns > _MIN_CORNER_TURN_RAD]


def _inside_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Return which points lie inside a closed polygon (crossing number), shape (P,)."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    x, y = points[:, 0:1], points[:, 1:2]
    straddles = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide='ignore', invalid='ignore'):
        crossing_x = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (np.sum(straddles & (x < crossing_x), axis=1) % 2) == 1


def _corner_kinds(corners: np.ndarray, walls: np.ndarray, solids, sensor_xy: np.ndarray):
    """
    Classify each corner by the free space around it.

    The walls through a corner cut the plane around it into sectors; a sector is free when its
    middle, just off the corner, lies in no solid. One free sector narrower than 180 deg makes
    an inside corner, wider an outside one; where thin walls leave several free sectors the one
    facing the sensor counts.

    :return: (kinds, keep): the kind of each corner, and False for a corner with no free space
    """
    kinds, keep = [], []
    start, edge = walls[:, :2], walls[:, 2:] - walls[:, :2]
    length_sq = np.einsum('ki,ki->k', edge, edge)
    for corner in corners:
        t = np.clip(np.einsum('ki,ki->k', corner - start, edge) / length_sq, 0.0, 1.0)
        through = np.hypot(*(corner - start - t[:, None] * edge).T) < _ON_WALL_M
        directions = np.concatenate([
            edge[through & (t < 1.0 - 1e-9)], -edge[through & (t > 1e-9)]])
        angles = np.unique(np.round(np.arctan2(directions[:, 1], directions[:, 0]), 9))
        widths = np.mod(np.roll(angles, -1) - angles, 2.0 * math.pi)
        widths[widths == 0.0] = 2.0 * math.pi
        middles = angles + widths / 2.0
        probes = corner + _PROBE_M * np.column_stack([np.cos(middles), np.sin(middles)])
        solid = np.zeros(len(probes), dtype=bool)
        for polygon, solid_inside in solids:
            solid |= _inside_polygon(probes, polygon) == solid_inside
        free = np.flatnonzero(~solid)
        keep.append(free.size > 0)
        if free.size > 1:
            towards = math.atan2(*(sensor_xy - corner)[::-1])
            offset = np.mod(towards - angles[free], 2.0 * math.pi)
            facing = free[offset < widths[free]]
            free = facing if facing.size else free[np.argmax(widths[free])][None]
        kinds.append('inside' if free.size and widths[free[0]] < math.pi else 'outside')
    return kinds, np.array(keep, dtype=bool)


def _split_surfaces(walls: np.ndarray, specs: list, plan: str):
    """Split the walls into pieces where surfaces are given and return (pieces, Surfaces)."""
    pieces = [list(w) for w in walls]
    wall_of = list(range(len(walls)))
    properties = [None] * len(walls)
    for n, item in enumerate(specs):
        where = f'surfaces[{n}]'
        item = _mapping(item, plan, where, ('from', 'to', 'bow_m', 'roughness_m',
                                            'roughness_length_m', 'dropout', 'dark', 'seed'))
        ends = _points([item.get('from'), item.get('to')], plan, f'{where}.from/to', 2, 2)
        if np.hypot(*(ends[1] - ends[0])) < 10 * _ON_WALL_M:
            _fail(plan, where, 'from and to must be at least 1 cm apart')
        array = np.array(pieces)
        start, edge = array[:, :2], array[:, 2:] - array[:, :2]
        length_sq = np.einsum('ki,ki->k', edge, edge)
        s = np.einsum('pki,ki->pk', ends[:, None, :] - start, edge) / length_sq    # (2, K)
        off = np.hypot(*(ends[:, None, :] - start - s[..., None] * edge).transpose(2, 0, 1))
        on = np.all((off < _ON_WALL_M) & (s > -1e-9) & (s < 1.0 + 1e-9), axis=0)
        if not on.any():
            _fail(plan, where, f'{ends.tolist()} do not both lie on one wall (or one piece of '
                  'a wall another surface left)')
        k = int(np.flatnonzero(on)[0])
        if properties[k] is not None:
            _fail(plan, where, f'overlaps surfaces[{properties[k][0]}]')
        if 'dark' in item and 'dropout' in item:
            _fail(plan, where, "give either 'dark' or 'dropout', not both")
        if not isinstance(item.get('dark', False), bool):
            _fail(plan, f'{where}.dark', f'expected true or false, got {item["dark"]!r}')
        dropout = (1.0 if item.get('dark', False)
                   else _number(item.get('dropout', 0.0), plan, f'{where}.dropout', 0.0, 1.0))
        seed = item.get('seed', n)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            _fail(plan, f'{where}.seed', f'expected an integer >= 0, got {seed!r}')
        surface = (n, dropout, _number(item.get('bow_m', 0.0), plan, f'{where}.bow_m', -1.0, 1.0),
                   _number(item.get('roughness_m', 0.0), plan, f'{where}.roughness_m', 0.0, 0.1),
                   _number(item.get('roughness_length_m', 0.1), plan,
                           f'{where}.roughness_length_m', 1e-3, 100.0), seed)
        lo, hi = sorted(s[:, k])
        p0, p1 = np.array(pieces[k][:2]), np.array(pieces[k][2:])
        a, b = (p0 + np.outer(s[:, k], p1 - p0))          # both ends, on the wall's line
        split = [(list(p0) + list(p0 + lo * (p1 - p0)), None) if lo > 1e-9 else None,
                 (list(a) + list(b), surface),
                 (list(p0 + hi * (p1 - p0)) + list(p1), None) if hi < 1.0 - 1e-9 else None]
        split = [piece for piece in split if piece is not None]
        pieces[k:k + 1] = [piece for piece, _ in split]
        properties[k:k + 1] = [prop for _, prop in split]
        wall_of[k:k + 1] = [wall_of[k]] * len(split)
    if len(pieces) > _MAX_WALLS:
        _fail(plan, 'surfaces', f'more than {_MAX_WALLS} wall pieces')
    return np.array(pieces, dtype=float).reshape(-1, 4), _surfaces(pieces, properties, wall_of)


def _surfaces(pieces: list, properties: list, wall_of: list) -> Surfaces:
    """Build the Surfaces of the pieces from their (number, dropout, bow, rms, l, seed)."""
    plain = Surfaces.plain(len(pieces))
    dropout, bow = plain.dropout.copy(), plain.bow_m.copy()
    amplitude, wavenumber = plain.amplitude_m.copy(), plain.wavenumber.copy()
    phase, offset = plain.phase.copy(), plain.offset_m.copy()
    for k, surface in enumerate(properties):
        if surface is None:
            continue
        _, dropout[k], bow[k], rms, correlation_length, seed = surface
        if rms > 0.0:
            length = math.hypot(pieces[k][2] - pieces[k][0], pieces[k][3] - pieces[k][1])
            amplitude[k], wavenumber[k], phase[k], offset[k] = roughness_profile(
                rms, correlation_length, length, np.random.default_rng(seed))
    return Surfaces(dropout, bow, amplitude, wavenumber, phase, offset,
                    np.array(wall_of, dtype=np.intp))


def _clutter(specs: list, plan: str):
    """Return the clutter's cylinders (C, 3) and box walls (B, 4)."""
    cylinders, walls = [], []
    for n, item in enumerate(specs):
        where = f'clutter[{n}]'
        if isinstance(item, dict) and 'cylinder' in item:
            item = _mapping(item, plan, where, ('cylinder', 'radius_m'))
            center = _points([item['cylinder']], plan, f'{where}.cylinder', 1, 1)[0]
            radius = _number(item.get('radius_m'), plan, f'{where}.radius_m', 0.0, 10.0,
                             open_low=True)
            cylinders.append([center[0], center[1], radius])
        elif isinstance(item, dict) and 'box' in item:
            item = _mapping(item, plan, where, ('box', 'size', 'yaw_deg'))
            walls.append(_polyline_walls_and_corners(_box(item, plan, where, 'box'), True)[0])
        else:
            _fail(plan, where, 'expected {cylinder: [x, y], radius_m: r} or {box: [x, y], '
                  f'size: [w, h], yaw_deg: a}}, got {item!r}')
    return (np.array(cylinders, dtype=float).reshape(-1, 3),
            np.vstack(walls) if walls else np.zeros((0, 4)))


def _walkers(specs: list, plan: str) -> Tuple[Walker, ...]:
    """Return the walkers of a plan."""
    walkers = []
    for n, item in enumerate(specs):
        where = f'walkers[{n}]'
        item = _mapping(item, plan, where, ('path', 'speed_m_s', 'leg_radius_m', 'hip_width_m',
                                            'step_m', 'start_m'))
        path = _points(item.get('path'), plan, f'{where}.path', 2, 1000)
        if np.any(np.hypot(*np.diff(path, axis=0).T) < 0.01):
            _fail(plan, f'{where}.path', 'consecutive points must be at least 1 cm apart')
        walkers.append(Walker(
            path,
            _number(item.get('speed_m_s', 1.0), plan, f'{where}.speed_m_s', 0.0, 5.0, True),
            _number(item.get('leg_radius_m', 0.055), plan, f'{where}.leg_radius_m', 0.0, 0.5,
                    True),
            _number(item.get('hip_width_m', 0.2), plan, f'{where}.hip_width_m', 0.0, 2.0),
            _number(item.get('step_m', 0.6), plan, f'{where}.step_m', 0.0, 3.0, True),
            _number(item.get('start_m', 0.0), plan, f'{where}.start_m', 0.0)))
    return tuple(walkers)


def _resolved(spec, folder: Optional[pathlib.Path], depth: int = 0) -> dict:
    """Return the plan's mapping with its base plan's items merged in (recursively)."""
    name = str(spec.get('name', 'unnamed')) if isinstance(spec, dict) else 'unnamed'
    spec = _mapping(spec, name, 'plan', _KEYS)
    for key in _LISTS:
        if not isinstance(spec.get(key, []), list) or len(spec.get(key, [])) > _MAX_ITEMS:
            _fail(name, key, f'expected a list of at most {_MAX_ITEMS} items')
    if 'base' not in spec:
        return spec
    if depth >= _MAX_BASE_DEPTH:
        _fail(name, 'base', f'more than {_MAX_BASE_DEPTH} levels of base plans')
    base_text, base_folder = _plan_text(str(spec['base']), folder)
    base = _resolved(_parse(base_text, str(spec['base'])), base_folder, depth + 1)
    merged = {key: base.get(key, []) + spec.get(key, []) for key in _LISTS}
    for key in ('name', 'description', 'sensor'):
        if key in spec or key in base:
            merged[key] = spec.get(key, base.get(key))
    return merged


def floor_plan_from_dict(spec: dict, folder: Optional[pathlib.Path] = None) -> FloorPlan:
    """
    Build a floor plan from its YAML structure (keys: see the module's documentation).

    :param spec: the parsed YAML mapping
    :param folder: where a ``base`` given as a relative path is looked up (default: cwd)
    :return: the floor plan
    :raises ValueError: on a malformed plan, with where and why
    """
    spec = _resolved(spec, folder)
    name = str(spec.get('name', 'unnamed'))
    sensor = _mapping(spec.get('sensor', {}), name, 'sensor', ('x', 'y', 'yaw_deg'))
    sensor_pose = (_number(sensor.get('x', 0.0), name, 'sensor.x'),
                   _number(sensor.get('y', 0.0), name, 'sensor.y'),
                   math.radians(_number(sensor.get('yaw_deg', 0.0), name, 'sensor.yaw_deg',
                                        -360.0, 360.0)))
    shapes = []
    for n, item in enumerate(spec.get('polylines', [])):
        item = _mapping(item, name, f'polylines[{n}]', ('points', 'closed'))
        shapes.append((_points(item.get('points'), name, f'polylines[{n}].points', 2,
                               _MAX_POINTS), bool(item.get('closed', False))))
    for n, item in enumerate(spec.get('boxes', [])):
        item = _mapping(item, name, f'boxes[{n}]', ('center', 'size', 'yaw_deg'))
        shapes.append((_box(item, name, f'boxes[{n}]', 'center'), True))
    if not shapes:
        raise ValueError(f'floor plan {name!r} has no walls')
    if len(shapes) > _MAX_SHAPES or sum(len(p) for p, _ in shapes) > _MAX_WALLS:
        _fail(name, 'polylines/boxes', f'more than {_MAX_SHAPES} shapes or {_MAX_WALLS} points')
    walls, corners = [], []
    for points, closed in shapes:
        shape_walls, shape_corners = _polyline_walls_and_corners(points, closed)
        walls.append(shape_walls)
        corners.append(shape_corners)
    walls, corners = np.vstack(walls), np.vstack(corners)
    sensor_xy = np.array(sensor_pose[:2])
    solids = [(points, not _inside_polygon(sensor_xy[None], points)[0])
              for points, closed in shapes if closed]
    kinds, keep = _corner_kinds(corners, walls, solids, sensor_xy)
    cylinders, clutter_walls = _clutter(spec.get('clutter', []), name)
    pieces, surfaces = _split_surfaces(np.vstack([walls, clutter_walls]),
                                       spec.get('surfaces', []), name)
    return FloorPlan(
        name=name,
        description=str(spec.get('description', '')).strip(),
        walls_m=pieces,
        corners_m=_on_surfaces(corners[keep], pieces, surfaces),
        sensor_pose=sensor_pose,
        corner_kinds=tuple(k for k, kept in zip(kinds, keep) if kept),
        surfaces=surfaces,
        cylinders_m=cylinders,
        walkers=_walkers(spec.get('walkers', []), name),
    )


def _on_surfaces(corners: np.ndarray, pieces: np.ndarray, surfaces: Surfaces) -> np.ndarray:
    """
    Move each corner inside a bowed or rough wall piece onto that piece's surface.

    Another wall meeting a bowed wall in the middle (a panel, a cabinet) meets its surface,
    not the straight line between its ends: the true corner is there.

    :param corners: corners on the straight walls, shape (M, 2), m
    :param pieces: wall pieces, shape (K, 4), m
    :param surfaces: their surfaces
    :return: the corners where the walls really meet, shape (M, 2), m
    """
    if not surfaces.shaped or not len(corners):
        return corners
    start, edge = pieces[:, :2], pieces[:, 2:] - pieces[:, :2]
    length = np.hypot(edge[:, 0], edge[:, 1])
    relative = corners[:, None, :] - start[None]
    along = np.einsum('mki,ki->mk', relative, edge) / length ** 2
    across = (edge[:, 0] * relative[..., 1] - edge[:, 1] * relative[..., 0]) / length
    shaped = (surfaces.bow_m != 0.0) | (surfaces.amplitude_m != 0.0).any(axis=1)
    inside = (np.abs(across) < _ON_WALL_M) & (along > 1e-9) & (along < 1.0 - 1e-9) & shaped
    moved = corners.copy()
    for m, k in zip(*np.nonzero(inside)):
        shift = surfaces.displacement_m(np.array([k]), along[m, k:k + 1], length[k:k + 1])[0]
        moved[m] += shift * np.array([-edge[k, 1], edge[k, 0]]) / length[k]
    return moved


def _plan_text(name_or_path: str, folder: Optional[pathlib.Path] = None):
    """Return the YAML text of a bundled plan or a plan file, and the folder it came from."""
    if name_or_path in BUNDLED_PLANS:
        text = resources.files(__package__).joinpath(f'plans/{name_or_path}.yaml').read_text()
        return text, None
    path = pathlib.Path(name_or_path)
    if folder is not None and not path.is_absolute():
        path = folder / path
    if not path.is_file():
        raise FileNotFoundError(
            f'no floor plan {name_or_path!r}: give one of {BUNDLED_PLANS} or a YAML path')
    if path.stat().st_size > _MAX_TEXT_CHARS:
        raise ValueError(f'floor plan {path} is larger than {_MAX_TEXT_CHARS} bytes')
    try:
        return path.read_text(), path.parent
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f'cannot read floor plan {path}: {error}') from error


def _parse(text: str, source: str) -> dict:
    """Parse a plan's YAML text into its mapping."""
    try:
        spec = load_without_aliases(text)
    except yaml.YAMLError as error:
        raise ValueError(f'floor plan {source}: not valid YAML: '
                         f'{str(error).splitlines()[0]}') from error
    if not isinstance(spec, dict):
        raise ValueError(f'floor plan {source}: expected a mapping of plan keys')
    return spec


def load_floor_plan(name_or_path: Union[str, pathlib.Path]) -> FloorPlan:
    """
    Load a bundled floor plan by name or any floor plan YAML file by path.

    :param name_or_path: a name in :data:`BUNDLED_PLANS` or a path to a YAML file
    :return: the floor plan
    :raises FileNotFoundError: when neither a bundled plan nor a file has that name
    :raises ValueError: on a malformed plan, with where and why
    """
    text, folder = _plan_text(str(name_or_path))
    return floor_plan_from_dict(_parse(text, str(name_or_path)), folder)
