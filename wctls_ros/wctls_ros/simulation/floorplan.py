# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""2D floor plans: walls as polylines and boxes, loaded from YAML, with their true corners."""

from dataclasses import dataclass
from importlib import resources
import pathlib
from typing import Union

import numpy as np
import yaml

BUNDLED_PLANS = ('environment_a', 'environment_b')
# A vertex is a corner when its walls turn by more than this (straight joints are not corners).
_MIN_CORNER_TURN_RAD = np.radians(10.0)


@dataclass(frozen=True)
class FloorPlan:
    """
    A static 2D scene in plan coordinates (m, rad; x, y in the floor plane).

    :ivar name: short identifier
    :ivar description: what the scene represents
    :ivar walls_m: wall segments, shape (K, 4): x0, y0, x1, y1 in m
    :ivar corners_m: true corners (vertices where walls turn), shape (M, 2), m
    :ivar sensor_pose: default sensor pose (x m, y m, yaw rad) in plan coordinates
    """

    name: str
    description: str
    walls_m: np.ndarray
    corners_m: np.ndarray
    sensor_pose: tuple

    def in_sensor_frame(self, pose=None):
        """
        Return the walls and corners seen from a sensor pose, in the sensor's REP-103 frame.

        :param pose: (x m, y m, yaw rad) in plan coordinates; the plan's sensor pose if None
        :return: (walls (K, 4), corners (M, 2)) in the sensor frame, m
        """
        x, y, yaw = self.sensor_pose if pose is None else pose
        c, s = np.cos(yaw), np.sin(yaw)
        # plan -> sensor: R(yaw)^T (p - t); as row vectors p' = (p - t) R.
        rotation = np.array([[c, -s], [s, c]])
        origin = np.array([x, y])
        walls = self.walls_m.reshape(-1, 2, 2) - origin
        corners = self.corners_m - origin
        return (walls @ rotation).reshape(-1, 4), corners @ rotation


def _box_polygon(center, size, yaw_deg=0.0):
    """Return the four vertices of a rectangle, counter-clockwise."""
    half = np.asarray(size, dtype=float) / 2.0
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    yaw = np.radians(yaw_deg)
    rotation = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    return local @ rotation.T + np.asarray(center, dtype=float)


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


def floor_plan_from_dict(spec: dict) -> FloorPlan:
    """
    Build a floor plan from its YAML structure.

    Keys: ``name``, ``description``, ``sensor`` ({x, y, yaw_deg}), ``polylines`` (list of
    {points: [[x, y], ...], closed: bool}) and ``boxes`` (list of {center: [x, y],
    size: [w, h], yaw_deg}). All lengths in m.

    :param spec: the parsed YAML mapping
    :return: the floor plan
    :raises ValueError: on a malformed plan
    """
    walls, corners = [], []
    shapes = [(p['points'], bool(p.get('closed', False))) for p in spec.get('polylines', [])]
    shapes += [(_box_polygon(b['center'], b['size'], b.get('yaw_deg', 0.0)), True)
               for b in spec.get('boxes', [])]
    for points, closed in shapes:
        shape_walls, shape_corners = _polyline_walls_and_corners(points, closed)
        walls.append(shape_walls)
        corners.append(shape_corners)
    if not walls:
        raise ValueError(f'floor plan {spec.get("name")!r} has no walls')
    sensor = spec.get('sensor', {})
    return FloorPlan(
        name=str(spec.get('name', 'unnamed')),
        description=str(spec.get('description', '')).strip(),
        walls_m=np.vstack(walls),
        corners_m=np.vstack(corners),
        sensor_pose=(float(sensor.get('x', 0.0)), float(sensor.get('y', 0.0)),
                     float(np.radians(sensor.get('yaw_deg', 0.0)))),
    )


def load_floor_plan(name_or_path: Union[str, pathlib.Path]) -> FloorPlan:
    """
    Load a bundled floor plan by name or any floor plan YAML file by path.

    :param name_or_path: ``'environment_a'``, ``'environment_b'`` or a path to a YAML file
    :return: the floor plan
    :raises FileNotFoundError: when neither a bundled plan nor a file has that name
    """
    if str(name_or_path) in BUNDLED_PLANS:
        text = resources.files(__package__).joinpath(f'plans/{name_or_path}.yaml').read_text()
    else:
        path = pathlib.Path(name_or_path)
        if not path.is_file():
            raise FileNotFoundError(
                f'no floor plan {str(name_or_path)!r}: give one of {BUNDLED_PLANS} or a YAML path')
        text = path.read_text()
    return floor_plan_from_dict(yaml.safe_load(text))
