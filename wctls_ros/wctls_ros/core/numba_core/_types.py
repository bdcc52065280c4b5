# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The numba types of the pipeline's arguments, for the kernels' ``@jit(ahead=...)`` declarations.

Exactly the types the pipeline passes (numba compiles a kernel once per tuple of argument
types): C-contiguous arrays, 64-bit numbers, and the records of :mod:`..records` with the types
of their fields. Making them compiles nothing.
"""

from numba import types

from ..records import (AlongWall, BeamGrid, CornerEndRule, EndWindow, Lines, Noise, Returns,
                       Segments, Settings, WallAtCorner, Walls)

REAL, INTEGER, FLAG = types.float64, types.intp, types.boolean
VALUES, INDICES, FLAGS = REAL[::1], INTEGER[::1], FLAG[::1]
# The ranges of a scan as the caller hands them: numpy's read-only view of its cos and sin.
READ_ONLY_VALUES = types.Array(REAL, 1, 'C', readonly=True)
ROWS, STACKS = REAL[:, ::1], REAL[:, :, ::1]         # (K, m) and (K, m, m) float arrays
_record = types.BaseTuple.from_types                 # (field types, NamedTuple class)
SETTINGS = _record(tuple({int: INTEGER, float: REAL, bool: FLAG}[kind]
                         for kind in Settings.__annotations__.values()), Settings)
NOISE = _record((REAL, REAL, REAL), Noise)
GRID = _record((INTEGER, REAL, FLAG), BeamGrid)
RETURNS = _record((INDICES, VALUES, VALUES, VALUES, VALUES), Returns)
SEGMENTS = _record((INDICES, INDICES, INDICES), Segments)
LINES = _record((VALUES, VALUES), Lines)
WALLS = _record((VALUES, VALUES, STACKS, ROWS, STACKS, ROWS, ROWS, ROWS, INDICES, INDICES, INDICES,
                 VALUES), Walls)
RULE = _record((REAL, REAL, INTEGER, REAL), CornerEndRule)
WINDOW = _record((VALUES, VALUES, VALUES, VALUES, FLAGS, INTEGER), EndWindow)
WALL = _record((REAL,) * 8, WallAtCorner)
PLACED = _record((VALUES, VALUES, FLAGS), AlongWall)
