# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Any beam density: one room gives the same segments and corners from 360 to 100 000 beams.

The rules that count returns (the breakpoint allowance, the IEPF noise threshold, the end
trims' and the corner test's windows) were tuned at 1080 beams per turn; at finer spacings they
keep their meaning per degree (:func:`wctls_ros.core.scan.beam_density`). Before that, a 1 cm
noise model broke the walls of a 34 560-beam scan into pieces below the minimum length (7 of
its 14 segments left, no corner) and of a 100 000-beam scan into nothing.
"""

import math

import numpy as np
import pytest
from wctls_lab.simulation import NoiseModel, simulate_recording
from wctls_lab.simulation.floorplan import floor_plan_from_dict
from wctls_ros.core import FeatureConfig
from wctls_ros.core.numba_core.pipeline import extract_features as compiled
from wctls_ros.core.numpy_core.pipeline import extract_features as in_numpy
from wctls_ros.core.scan import beam_density

pytestmark = pytest.mark.slow

# A room whose every wall has at least 20 returns at 360 beams (1 deg): a 5 x 4 m box with a
# 1 x 1 m notch and a 0.6 m pillar square to the walls (a pillar seen at a grazing angle shows
# a sliver of its corner to a dense scan only, a real difference), the sensor off the middle.
ROOM = floor_plan_from_dict({
    'name': 'density_room', 'description': 'box room with a notch and a pillar',
    'sensor': {'x': 2.2, 'y': 1.7, 'yaw_deg': 10.0},
    'polylines': [{'closed': True, 'points': [[0.0, 0.0], [5.0, 0.0], [5.0, 3.0], [4.0, 3.0],
                                              [4.0, 4.0], [0.0, 4.0]]}],
    'boxes': [{'center': [1.0, 1.0], 'size': [0.6, 0.6], 'yaw_deg': 0.0}]})
BEAMS = (360, 1080, 4320, 34560, 100000)
# 1 cm of range noise and no model error: the decisions rest on the density rules alone.
CONFIG = FeatureConfig(range_sigma_m=0.01, bearing_sigma_rad=0.0, iepf_threshold_m=0.04)


def _features(extract, beams: int):
    recording = simulate_recording(ROOM, NoiseModel(range_sigma_m=0.01, bearing_sigma_rad=0.0),
                                   1, seed=3, beams=beams)
    found = extract(recording.ranges[0], recording.angle_min, recording.angle_increment, CONFIG)
    return found, recording.corners_m[0]


@pytest.mark.parametrize('extract', [compiled, in_numpy], ids=['compiled', 'numpy'])
def test_the_same_room_gives_the_same_features_at_every_density(extract):
    counts, corners = [], []
    for beams in BEAMS:
        found, truth = _features(extract, beams)
        counts.append((len(found.segments.angle_rad), len(found.corners.yaw_rad)))
        corners.append(found.corners.xy_m)
        # Every corner reported is a true one, within 3 cm (the 1 cm noise at 1-4 m).
        nearest = np.min(np.linalg.norm(found.corners.xy_m[:, None] - truth[None], axis=2), axis=1)
        assert np.all(nearest < 0.03), (beams, nearest)
    assert len(set(counts)) == 1, dict(zip(BEAMS, counts))
    segments, found_corners = counts[0]
    assert segments >= 8 and found_corners >= 6          # the room's walls and the pillar's
    for beams, xy in zip(BEAMS[1:], corners[1:]):
        assert np.allclose(np.sort(xy, axis=0), np.sort(corners[0], axis=0), atol=0.03), beams


def test_the_rules_stay_as_tuned_up_to_1080_beams_and_grow_beyond():
    for beams in (360, 1080):
        assert beam_density(2.0 * math.pi / (beams - 1), beams) == (1.0, 3.0, 8, 40)
    dense = beam_density(2.0 * math.pi / 99999, 100000)
    assert dense.finer == pytest.approx(92.6, abs=0.1)
    assert (dense.end_window, dense.corner_window) == (741, 3704)
    # Noise beyond the allowance: 3.4 % of neighbour pairs at the tuned spacing, f^2 times
    # fewer at f times the returns.
    tail = math.erfc(dense.breakpoint_sigmas / 2.0) / math.erfc(3.0 / 2.0)
    assert tail == pytest.approx(dense.finer ** -2, rel=1e-6)
    # A spacing of 1e-20 rad counts as at most as many times finer as the scan has beams.
    assert beam_density(1e-20, 10).finer == 10.0
