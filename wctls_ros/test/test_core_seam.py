# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The seam of a full turn on real RPLIDAR C1 scans: a wall across it is one segment.

An RPLIDAR driver publishes one turn per scan, from where the head's rotation restarts: a wall
seen in that direction has its returns at both ends of the ranges array. The pipeline joins the
last beam of a full turn to the first (``full_turn`` in ``core.scan.scan_geometry``), so such a
wall must come out as one segment whose first beam index is larger than its last. What was
measured near the seam of these scans is in docs/sensors.md#the-seam-of-a-turn.
"""

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_lab.evaluation.scans import load_scans
from wctls_lab.evaluation.score_cli import node_config
from wctls_ros.core import extract_features

C1_SCANS = REAL_DATA / 'rplidar_c1_single_scans'
# The beams this close to the seam on either side (1.5 deg at the C1's 0.5 deg): when each side
# has at least two returns there, and all of them lie on one straight line within WALL_RMS_M,
# a wall certainly spans the seam.
SEAM_BEAMS = 3
WALL_RMS_M = 0.005


def walls_across_the_seam(scans):
    """
    Return the scans in which one straight wall spans the seam, judged from the raw returns.

    :param scans: the recording
    :return: (scan index, the beam indices next to the seam) per such scan
    """
    beam_count = scans.ranges.shape[1]
    beams = np.r_[beam_count - SEAM_BEAMS:beam_count, 0:SEAM_BEAMS]
    bearing = scans.angle_min + beams * scans.angle_increment
    found = []
    for k, ranges in enumerate(scans.ranges):
        valid = np.isfinite(ranges[beams])
        if min(valid[:SEAM_BEAMS].sum(), valid[SEAM_BEAMS:].sum()) < 2:
            continue
        near = ranges[beams][valid]
        xy = np.c_[near * np.cos(bearing[valid]), near * np.sin(bearing[valid])]
        across_line = np.linalg.svd(xy - xy.mean(axis=0), compute_uv=False)[1]
        if across_line / np.sqrt(valid.sum()) < WALL_RMS_M:
            found.append((k, beams[valid]))
    return found


@pytest.fixture(scope='module')
def c1_scans():
    pytest.importorskip('rosbags')
    return load_scans(C1_SCANS)


def test_a_wall_across_the_seam_of_a_real_scan_is_one_segment(c1_scans):
    config = node_config(sensor='rplidar_c1')
    spanned = walls_across_the_seam(c1_scans)
    assert len(spanned) >= 10            # the recording does show walls across its seam
    for k, beams in spanned:
        segments = extract_features(c1_scans.ranges[k], c1_scans.angle_min,
                                    c1_scans.angle_increment, config, c1_scans.range_min,
                                    c1_scans.range_max).segments
        ends = zip(segments.first_index, segments.last_index)
        holding = [(first, last) for first, last in ends
                   if first > last and all(b >= first or b <= last for b in beams)]
        assert len(holding) == 1, f'scan {k}: the wall across the seam is split'
