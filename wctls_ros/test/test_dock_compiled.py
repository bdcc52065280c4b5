# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The compiled dock detector against the numpy one: its starts, and its fit start by start.

The numpy steps of :func:`~wctls_ros.frontend.dock.find_docks` (the starts from the corners, the
pairs of segments and one segment alone, and :func:`~wctls_ros.frontend.dock.fit_returns`) are the
specification; their compiled twins (``core/numba_core/dock.py``), which find_docks runs whenever
the compiled core serves, must give the same starts within 1e-9 relative, every start (and a one
segment's fit made again from its pose) the same outcome (a fit or none), the same counts of
returns per face and past each end, and the pose, covariance, reach, spacing, own opening angle,
bends and chi2 within 1e-9 relative; and so find_docks the same docks. On the scans where it
matters: S1-like scans of environment A lived in with the example dock from 0.3 to 3 m and 30 deg
either side of its axis, a V of the dock's angle with a face too long, the same scans cut to a 180
deg field of view (a window at the scan's edge) and with the faces' flatness set and no residual
scaling (the covariance's other terms); and the first scans of every shipped real recording (no
dock: starts that fail on every test).

Skipped only where numba is not installed (the stock-install venv).
"""

from dataclasses import replace
import math

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_lab.evaluation.scans import load_json_scans, load_scans
from wctls_lab.simulation import (floor_plan_from_dict, full_turn_bearings, SENSOR_MODELS,
                                  simulate_scan)
from wctls_ros.core import extract_features, runtime
from wctls_ros.frontend import dock
from wctls_ros.frontend.dock import dock_returns, DockShape, find_docks, fit_returns
from wctls_ros.params import defaults, FEATURE_NODE, feature_settings

pytest.importorskip('numba')

RELATIVE = 1e-9
S1 = feature_settings(defaults(FEATURE_NODE, 'rplidar_s1')).config
APEX = np.array([4.45, 1.6])          # the dock's apex in environment A, its axis along +x
FIELDS = ('pose', 'covariance', 'returns', 'reach_m', 'spacing_m', 'past_end',
          'opening_angle_rad', 'bends', 'chi2')


def outline(shape, apex=APEX):
    """Return a dock's closed outline in the plan: right tip, apex, left tip, back corners."""
    half = shape.opening_angle_rad / 2.0
    right = apex + shape.right_face_m * np.array([-math.cos(half), -math.sin(half)])
    left = apex + shape.left_face_m * np.array([-math.cos(half), math.sin(half)])
    return [right.tolist(), apex.tolist(), left.tolist(), [4.5, float(left[1])],
            [4.5, float(right[1])]]


def simulated(shape, apex=APEX, scans=6, variant=None):
    """Yield (features, returns) of S1-like scans of environment A lived in with a V in it."""
    plan = floor_plan_from_dict({'name': 'dock_compiled', 'base': 'environment_a_cluttered',
                                 'polylines': [{'closed': True, 'points': outline(shape, apex)}]})
    rng = np.random.default_rng(46)
    angle_min, increment, bearings = full_turn_bearings()
    for distance in (0.3, 0.5, 1.0, 2.0, 3.0):
        for view in (-30, 0, 30):
            direction = math.radians(view)
            pose = (apex[0] - distance * math.cos(direction),
                    apex[1] - distance * math.sin(direction), direction)
            for t in range(scans):
                ranges = simulate_scan(plan.scene(pose, 0.1 * t), bearings,
                                       SENSOR_MODELS['s1_like'], rng)
                first = 0
                if variant == 'half_turn':     # 180 deg ahead: the window meets the edge
                    first, ranges = len(ranges) // 4, ranges[len(ranges) // 4:-len(ranges) // 4]
                features = extract_features(ranges, angle_min + first * increment, increment,
                                            S1)
                returns = dock_returns(ranges, angle_min + first * increment, increment, S1,
                                       features.range_sigma_m)
                if variant == 'flat_faces':
                    returns = replace(returns, flatness_sigma_m=0.005, residual_scaling=False)
                yield features, returns


def recorded():
    """Yield (features, returns) of the first 40 scans of every shipped real recording."""
    presets = {'sick': 'sick_lms1xx', 'lms111': 'sick_lms1xx', 'mrpt': 'sick_lms1xx',
               'urg': 'hokuyo_urg04lx', 'tuw': 'hokuyo_urg04lx'}
    paths = sorted(REAL_DATA.glob('*/*.mcap')) + sorted(
        (REAL_DATA / 'lms111_building').glob('*.json'))
    assert paths
    for path in paths:
        preset = next((preset for prefix, preset in presets.items()
                       if path.parent.name.startswith(prefix)), 'generic')
        config = feature_settings(defaults(FEATURE_NODE, preset)).config
        scans = load_json_scans(path) if path.suffix == '.json' else load_scans(path, limit=40)
        for ranges in scans.ranges[:40]:
            features = extract_features(ranges, scans.angle_min, scans.angle_increment, config)
            yield features, dock_returns(ranges, scans.angle_min, scans.angle_increment, config,
                                         features.range_sigma_m)


CASES = {
    'dock': lambda: (simulated(DockShape()), DockShape()),
    'dock_half_turn': lambda: (simulated(DockShape(), variant='half_turn'), DockShape()),
    'dock_flat_faces': lambda: (simulated(DockShape(), variant='flat_faces'), DockShape()),
    'face_too_long': lambda: (simulated(DockShape(right_face_m=0.6), APEX + [0.0, -0.35]),
                              DockShape()),
    'real_recordings': lambda: (recorded(), DockShape()),
}


@pytest.fixture(scope='module')
def compiled_core():
    """Make the compiled core serve (loaded, or compiled, now); return the dock's kernel."""
    kernels = runtime.compiled_kernels('dock', True)
    assert kernels is not None, runtime.status()
    return kernels


def assert_close(compiled, reference, what):
    """Hold values to the reference within RELATIVE of its largest magnitude."""
    compiled, reference = np.asarray(compiled, dtype=float), np.asarray(reference, dtype=float)
    assert compiled.shape == reference.shape, what
    assert np.array_equal(np.isnan(compiled), np.isnan(reference)), what
    assert np.array_equal(np.isinf(compiled), np.isinf(reference)), what
    finite = np.isfinite(reference)
    if finite.any():
        scale = float(np.abs(reference[finite]).max())
        error = float(np.abs(compiled[finite] - reference[finite]).max())
        assert error <= RELATIVE * scale, (what, error / max(scale, 1e-300))


@pytest.mark.parametrize('case', CASES)
def test_the_compiled_fit_gives_the_numpy_ones_fits_and_docks(case, compiled_core):
    scans, shape = CASES[case]()
    fits = nones = docks = pairs = singles = 0
    for k, (features, returns) in enumerate(scans):
        tried: set = set()
        starts = (dock._corner_starts(features.segments, features.corners, shape, tried)
                  + dock._segment_pair_starts(features.segments, shape, returns.full_turn,
                                              tried))
        arrays = dock._twin_arrays(features.segments, features.corners)
        twins = (compiled_core.corner_starts(*arrays, dock._shape_tuple(shape)).tolist()
                 + compiled_core.segment_pair_starts(*arrays[:6], dock._shape_tuple(shape),
                                                     returns.full_turn).tolist())
        assert len(twins) == len(starts), (case, k)
        if starts:
            assert_close(twins, starts, (case, k, 'starts'))
        pairs += len(starts) - len(dock._corner_starts(features.segments, features.corners,
                                                       shape, set()))
        # The starts of one segment alone, and their fits made again from their own poses.
        single = dock._segment_starts(features.segments, returns, shape)
        single_twins = compiled_core.segment_starts(
            arrays[3], np.ascontiguousarray(features.segments.num_points, dtype=np.int64),
            *dock._twin_returns(returns)[:6], dock._shape_tuple(shape)).tolist()
        assert len(single_twins) == len(single), (case, k)
        if single:
            assert_close(single_twins, single, (case, k, 'one segment starts'))
        singles += len(single)
        for start, refit in [(start, False) for start in starts] + [(start, True)
                                                                    for start in single]:
            for _ in range(2 if refit else 1):
                ours = fit_returns(returns, start, shape, compiled=True)
                theirs = fit_returns(returns, start, shape, compiled=False)
                assert (ours is None) == (theirs is None), (case, k, start)
                if theirs is None:
                    nones += 1
                    break
                fits += 1
                assert ours.returns == theirs.returns and ours.past_end == theirs.past_end
                for name in FIELDS:
                    assert_close(getattr(ours, name), getattr(theirs, name), (case, k, name))
                start = tuple(theirs.pose.tolist())
        ours = find_docks(features.segments, features.corners, shape, returns, compiled=True)
        theirs = find_docks(features.segments, features.corners, shape, returns,
                            compiled=False)
        assert len(ours) == len(theirs), (case, k)
        for a, b in zip(ours, theirs):
            assert_close(a.vector, b.vector, (case, k, 'dock pose'))
            assert_close(a.covariance, b.covariance, (case, k, 'dock covariance'))
            assert_close(a.misfit, b.misfit, (case, k, 'misfit'))
        docks += len(theirs)
    # Each case exercises the fit: starts that give a fit, and (but for the dock seen whole)
    # docks found or refused.
    assert fits >= 10 and pairs >= 1, (fits, nones, pairs)
    if case == 'dock':
        assert singles >= 10, singles            # at 0.3 m one face often has no segment
    if case.startswith('dock'):
        assert docks >= 40
    else:
        assert nones + fits > docks


def test_find_docks_runs_the_compiled_fit_while_the_compiled_core_serves(compiled_core,
                                                                         monkeypatch):
    calls = []
    fit = compiled_core.fit_returns
    monkeypatch.setattr(compiled_core, 'fit_returns', lambda *args: calls.append(1) or fit(*args))
    features, returns = next((features, returns) for features, returns
                             in simulated(DockShape(), scans=1)
                             if find_docks(features.segments, features.corners, DockShape(),
                                           returns, compiled=False))
    assert not calls
    assert find_docks(features.segments, features.corners, DockShape(), returns)
    assert calls
