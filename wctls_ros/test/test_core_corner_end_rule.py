# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The stages of the corner end rule (docs/derivation.md#corners), each on hand-computed cases.

Both cores have the same stages by the same names: the compiled one per corner, the numpy one
over every corner at once (here one corner). Each case runs in both.
"""

import math

import numpy as np
import pytest
from wctls_ros.core import SegmentSet
from wctls_ros.core.numpy_core import corners as numpy_corners
from wctls_ros.core.records import (AlongWall, CornerEndRule, EndWindow, Noise, SegmentArrays,
                                    WallAtCorner)

compiled = pytest.importorskip('wctls_ros.core.numba_core.corners')

# 1 cm of range noise and no bearing noise: every return's position noise is 1 cm.
NOISE = Noise(0.01, 0.0, 0.01)
# 3 sigma plus 1 cm; four returns between two walls at most; runs tested against 4 sigma.
RULE = CornerEndRule(3.0, 0.01, 4, 4.0)
CORES = ['numba', 'numpy']
UNBATCHED = (Noise, CornerEndRule)


def batched(value):
    """Return one corner's value as the numpy core's over one corner: a leading axis of 1."""
    if isinstance(value, UNBATCHED):
        return value
    if isinstance(value, tuple):
        return type(value)(*(np.asarray(field)[None] for field in value))
    return np.asarray(value)[None]


def stage(core: str, name: str, *arguments):
    """Run one stage of the rule on one corner in a core; return its result for that corner."""
    if core == 'numba':
        return getattr(compiled, name)(*arguments)
    return getattr(numpy_corners, name)(*(batched(value) for value in arguments))[0]


def window(x, y, in_window=None) -> EndWindow:
    """Return an end window of returns at (x, y), 1 cm of noise each, all between the walls."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    sigma = np.full(x.size, 0.01)
    inside = np.ones(x.size, bool) if in_window is None else np.asarray(in_window, bool)
    return EndWindow(x, y, sigma, RULE.sigmas * sigma + RULE.floor_m, inside, RULE.window)


def placed(in_front, along, on_line) -> AlongWall:
    """Return a window's returns placed with respect to a wall."""
    return AlongWall(np.asarray(in_front, dtype=float), np.asarray(along, dtype=float),
                     np.asarray(on_line, bool))


def flags(*values) -> np.ndarray:
    """Return a boolean array."""
    return np.array(values, bool)


# A wall along y = 1 whose returns run from x = -1 to 0.8, its corner at (1, 1): seen from
# there its inside lies along -x. Tolerance along it 3 * 2 cm + 1 cm.
WALL = WallAtCorner(0.0, 1.0, 1.0, -1.0, 0.0, 0.02, 0.02, 0.07)


@pytest.mark.parametrize('core', CORES)
def test_a_wall_at_its_corner_points_inward_with_the_corners_spread_and_the_beam_spacing(core):
    angle, radius = np.array([math.pi / 2, 0.0]), np.array([1.0, 1.0])
    start, end = np.array([[-1.0, 1.0], [1.0, 3.0]]), np.array([[0.8, 1.0], [1.0, 1.2]])
    covariance = np.diag([0.02 ** 2, 0.01 ** 2, 0.0])
    walls = SegmentSet.filled(2, angle_rad=angle, radius_m=radius, start_xy_m=start,
                              end_xy_m=end)                   # all wall_at_corner reads
    if core == 'numba':
        def at(wall, corner):
            return compiled.wall_at_corner(SegmentArrays(**vars(walls)), wall, *corner,
                                           covariance, 0.01, RULE)
    else:
        def at(wall, corner):
            found = numpy_corners.wall_at_corner(walls, np.array([wall]), np.array([corner]),
                                                 covariance[None], 0.01, RULE)
            return WallAtCorner(*(float(field[0]) for field in found))

    # The corner (1, 1) seen at 45 deg to the wall y = 1: the beams 0.01 rad apart hit it
    # sqrt(2) * 0.01 / cos(45 deg) = 2 cm apart; the corner spreads 2 cm along x.
    first = at(0, (1.0, 1.0))
    assert (first.inward_x, first.inward_y) == pytest.approx((-1.0, 0.0), abs=1e-12)
    assert first.along_sigma_m == pytest.approx(0.02)
    assert first.spacing_m == pytest.approx(0.02)
    assert first.tolerance_m == pytest.approx(3.0 * 0.02 + 0.01)
    # The wall x = 1, its returns above the corner, spreads 1 cm along y.
    second = at(1, (1.0, 1.0))
    assert (second.inward_x, second.inward_y) == pytest.approx((0.0, 1.0), abs=1e-12)
    assert second.along_sigma_m == pytest.approx(0.01)
    # Nearly along the beam (incidence 1 / 2000) the spacing is held at 1000 times the step.
    grazing = at(1, (1.0, 2000.0))
    assert grazing.spacing_m == pytest.approx(math.hypot(1.0, 2000.0) * 0.01 / 1e-3)


@pytest.mark.parametrize('core', CORES)
def test_the_corner_zone_is_the_corners_noise_over_the_walls_sine_plus_a_beam(core):
    other = WallAtCorner(1.0, 0.0, 1.0, 0.0, 1.0, 0.01, 0.03, 0.04)
    # Perpendicular walls: 3 hypot(1 cm, 2 cm) + 1 cm + the smaller spacing, 2 cm.
    zone = 3.0 * math.hypot(0.01, 0.02) + 0.01 + 0.02                   # 8.7 cm
    near = window([1.0 - zone + 0.005, 1.0 - zone - 0.005, 1.0, 1.0, 1.0, 1.0],
                  [1.0, 1.0, 1.0 + zone - 0.005, 1.0 + zone + 0.005, 1.0, 1.01],
                  in_window=[1, 1, 1, 1, 1, 0])
    at_corner = stage(core, 'corner_zone', near, 1.0, 1.0, WALL, other, NOISE, RULE)
    assert at_corner.tolist() == [True, False, True, False, True, False]
    # Walls at 60 deg: the lines stay within the noise of each other 1 / sin 60 deg farther.
    slanted = WallAtCorner(math.cos(math.radians(30)), math.sin(math.radians(30)), 1.0, 0.0,
                           1.0, 0.01, 0.03, 0.04)
    wider = 3.0 * math.hypot(0.01, 0.02) / math.sin(math.radians(60)) + 0.01 + 0.02
    assert wider > zone + 0.008
    at_corner = stage(core, 'corner_zone', window([1.0 - zone - 0.005], [1.0]), 1.0, 1.0,
                      WALL, slanted, NOISE, RULE)
    assert at_corner.tolist() == [True]


@pytest.mark.parametrize('core', CORES)
@pytest.mark.parametrize('offset_sigmas, dropped', [(3.5, True), (2.5, False)])
def test_a_run_a_wall_claims_in_front_of_its_line_together_is_an_object_not_the_wall(
        core, offset_sigmas, dropped):
    # Returns 1 and 2 lie on the wall's line but 3.5 sigma in front of it each: together
    # 7 / sqrt(2) = 4.9 sigma > 4, an object before the wall's end; at 2.5 sigma each,
    # 3.5 < 4, the wall itself. The facing end (0) is the wall's own whatever its offset; a
    # return past the corner's tolerance (3) is not claimed beyond the segment.
    offset = offset_sigmas * 0.01
    returns = window(np.zeros(6), np.zeros(6))
    on_wall = placed([offset, offset, offset, offset, 0.0, 0.0], [0.5, 0.3, 0.2, -0.1, 0.0, 0.0],
                     [1, 1, 1, 1, 0, 0])
    on_line = stage(core, 'without_object_in_front', returns, WALL, on_wall, flags(*[0] * 6),
                    RULE)
    assert on_line.tolist() == [True, not dropped, not dropped, True, False, False]
    # Without the run test (run_sigmas 0) the wall claims them all.
    unruled = stage(core, 'without_object_in_front', returns, WALL, on_wall, flags(*[0] * 6),
                    RULE._replace(run_sigmas=0.0))
    assert unruled.tolist() == [True, True, True, True, False, False]


@pytest.mark.parametrize('core', CORES)
def test_a_return_on_one_wall_alone_past_the_corner_means_that_wall_goes_on(core):
    other = WallAtCorner(1.0, 0.0, 1.0, 0.0, 1.0, 0.01, 0.03, 0.04)
    on_first, on_neither = flags(1, 0, 0), flags(0, 0, 0)
    nowhere = placed([0.0] * 3, [0.0] * 3, [0] * 3)

    def goes_on(along, first_on_line=on_first, second_on_line=on_neither,
                at_corner=flags(0, 0, 0)):
        return bool(stage(core, 'goes_on', WALL, other, placed([0.0] * 3, along, [0] * 3),
                          nowhere, first_on_line, second_on_line, at_corner))

    # 8 cm past the corner along the first wall, beyond its 7 cm tolerance: it goes on.
    assert goes_on([-0.08, 0.0, 0.0])
    # 6 cm past: within the tolerance.
    assert not goes_on([-0.06, 0.0, 0.0])
    # On both lines (where they cross), or in the corner zone: no wall's alone.
    assert not goes_on([-0.08, 0.0, 0.0], second_on_line=on_first)
    assert not goes_on([-0.08, 0.0, 0.0], at_corner=on_first)


@pytest.mark.parametrize('core', CORES)
def test_only_an_occluder_outside_the_reaches_leaves_the_view_between_the_walls_open(core):
    returns = window(np.zeros(6), np.zeros(6))
    behind = placed([-1.0] * 6, [0.0] * 6, [0] * 6)
    in_front = placed([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.0] * 6, [0] * 6)
    no_corner = flags(*[0] * 6)

    def blocked(first_here, second_here, first=behind, second=behind):
        return bool(stage(core, 'blocked', returns, WALL, WALL, first, second, flags(*first_here),
                          flags(*second_here), no_corner))

    # The walls reach 0-1 and 4-5: returns 2 and 3 between the reaches interrupt the view.
    assert blocked([1, 1, 0, 0, 0, 0], [0, 0, 0, 0, 1, 1])
    assert not blocked([1, 1, 1, 1, 0, 0], [0, 0, 0, 0, 1, 1])
    # The first wall goes on at 3 beyond return 2: 2 lies before its reach, allowed when it is
    # in front of both lines (a leg before the wall), not when it lies behind them.
    assert not blocked([1, 1, 0, 1, 0, 0], [0, 0, 0, 0, 1, 1], in_front, in_front)
    assert blocked([1, 1, 0, 1, 0, 0], [0, 0, 0, 0, 1, 1])
    # An occluder between the reaches blocks.
    assert blocked([1, 1, 0, 0, 0, 0], [0, 0, 0, 0, 1, 1], in_front, in_front)


@pytest.mark.parametrize('core', CORES)
def test_how_far_a_wall_stops_short_of_the_corner_is_counted_in_beams(core):
    # The nearest return of the wall that reaches the corner lies 15 cm into the wall: 8 cm
    # beyond its 7 cm tolerance, 4 beams of 2 cm.
    along = placed([0.0] * 4, [0.5, 0.3, 0.15, 0.1], [1, 1, 1, 0])

    def short(on_line, here):
        return float(stage(core, 'short_of_corner', WALL, along, flags(*on_line), flags(*here)))

    assert short([1, 1, 1, 0], [1, 1, 1, 1]) == pytest.approx(4.0)
    # A return in the corner zone but off the line does not count as the wall's own.
    assert short([1, 1, 1, 0], [1, 1, 1, 1]) == short([1, 1, 1, 0], [1, 1, 1, 0])
    # Its nearest return within the tolerance: not short at all.
    near = placed([0.0] * 2, [0.5, 0.06], [1, 1])
    assert float(stage(core, 'short_of_corner', WALL, near, flags(1, 1), flags(1, 1))) == 0.0
    assert short([0, 0, 0, 0], [1, 1, 1, 1]) == math.inf
