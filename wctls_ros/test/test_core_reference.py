# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The fast, batched fits and corner propagation against the slow, plain reference_fits.py.

Both are written from docs/derivation.md, independently: the reference evaluates the paper's
Jacobians (7), (15), (D9), (23) and (D11)-(D16) return by return, the core the projected form of
(D5)-(D7) over whole scans. They must agree to 1e-9 relative on random walls (near and far, head-on
and grazing, 2 to 300 returns) and on the segments and corners of real recordings.
"""

import math

from conftest import REAL_DATA
import numpy as np
import pytest
import reference_fits
from wctls_ros.core import extract_features, find_corners, segment_returns
from wctls_ros.core.numba_core.lines import fit_lines

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

METHODS = ('utls', 'wtls', 'wctls', 'ml')
RELATIVE = 1e-9
RANGE_SIGMA = 0.01
BEARING_SIGMA = math.radians(0.1)


def assert_close_vector(fast, reference):
    fast, reference = np.asarray(fast, dtype=float), np.asarray(reference, dtype=float)
    assert np.max(np.abs(fast - reference)) <= RELATIVE * np.max(np.abs(reference))


def assert_close_covariance(fast, reference):
    # Each entry against the geometric mean of its row's and column's variances: the scale of
    # a correlation, so that a near-zero covariance is not compared to itself.
    fast, reference = np.asarray(fast), np.asarray(reference)
    scale = np.sqrt(np.outer(np.diag(reference), np.diag(reference)))
    assert np.all(np.abs(fast - reference) <= RELATIVE * scale + 1e-300)


def assert_same_angle(fast, reference):
    assert abs(math.remainder(fast - reference, 2.0 * math.pi)) <= RELATIVE


def random_segments(rng, count):
    """Return (rho, theta) of `count` noisy walls of random pose, extent and return count."""
    segments = []
    for _ in range(count):
        angle = rng.uniform(-math.pi, math.pi)
        radius = rng.uniform(0.2, 6.0)
        first = rng.uniform(-85.0, 80.0)
        last = min(first + rng.uniform(1.0, 120.0), 86.0)
        n = int(rng.integers(2, 300))
        incidence = np.radians(np.linspace(first, last, n))
        rho = radius / np.cos(incidence) + rng.normal(0.0, RANGE_SIGMA, n)
        theta = angle + incidence + rng.normal(0.0, BEARING_SIGMA, n)
        segments.append((rho, theta))
    return segments


def compare_fits(segments, method, range_sigma, bearing_sigma):
    counts = np.array([len(rho) for rho, _ in segments])
    returns = segment_returns(np.concatenate([rho for rho, _ in segments]),
                              np.concatenate([theta for _, theta in segments]),
                              np.cumsum(counts) - counts, counts)
    fits = fit_lines(method, returns, range_sigma, bearing_sigma)
    for k, (rho, theta) in enumerate(segments):
        line, covariance, angle, radius, normal, offset, normal_offset = reference_fits.fit(
            method, rho, theta, range_sigma, bearing_sigma)
        assert_close_vector(fits.line[k], line)
        assert_close_covariance(fits.line_covariance[k], covariance)
        assert_same_angle(fits.angle_rad[k], angle)
        assert abs(fits.radius_m[k] - radius) <= RELATIVE * radius
        assert_close_covariance(fits.normal_covariance[k], normal)
        assert_close_vector(fits.line_offset_jacobian[k], offset)
        assert_close_vector(fits.normal_offset_jacobian[k], normal_offset)
    return fits


@pytest.mark.parametrize('method', METHODS)
def test_fits_equal_the_plain_reference_on_random_walls(method):
    rng = np.random.default_rng(11)
    compare_fits(random_segments(rng, 150), method, RANGE_SIGMA, BEARING_SIGMA)
    compare_fits(random_segments(rng, 20), method, RANGE_SIGMA, 0.0)     # no bearing term


def test_the_reference_differs_when_the_fast_code_is_wrong():
    # The comparison can fail: a covariance computed with a bearing sigma 1 % off is caught.
    rho, theta = random_segments(np.random.default_rng(2), 1)[0]
    reference = reference_fits.fit('wtls', rho, theta, RANGE_SIGMA, BEARING_SIGMA)
    returns = segment_returns(rho, theta, [0], [len(rho)])
    fits = fit_lines('wtls', returns, RANGE_SIGMA, 1.01 * BEARING_SIGMA)
    with pytest.raises(AssertionError):
        assert_close_covariance(fits.normal_covariance[0], reference[4])


def compare_corners(segments, method, common_range_sigma):
    fits = compare_fits(segments, method, RANGE_SIGMA, BEARING_SIGMA)
    middles = np.array([[np.mean(rho * np.cos(theta)), np.mean(rho * np.sin(theta))]
                        for rho, theta in segments])
    first = np.arange(0, len(segments) - 1, 2)
    corners = find_corners(fits.line, fits.line_covariance, middles, middles, first, first + 1,
                           math.radians(20.0), fits.line_offset_jacobian, common_range_sigma)
    assert len(corners) > 0
    for k in range(len(corners)):
        i, j = corners.first_segment[k], corners.second_segment[k]
        x, y, yaw, opening, covariance = reference_fits.corner(
            fits.line[i], fits.line_covariance[i], fits.line_offset_jacobian[i],
            fits.line[j], fits.line_covariance[j], fits.line_offset_jacobian[j],
            middles[i], middles[j], common_range_sigma)
        assert_close_vector(corners.xy_m[k], [x, y])
        assert_same_angle(corners.yaw_rad[k], yaw)
        assert abs(corners.opening_angle_rad[k] - opening) <= RELATIVE * opening
        assert_close_covariance(corners.covariance[k], covariance)


@pytest.mark.parametrize('method', METHODS)
def test_corners_equal_the_plain_reference_on_random_wall_pairs(method):
    rng = np.random.default_rng(5)
    compare_corners(random_segments(rng, 120), method, 0.0)
    compare_corners(random_segments(rng, 120), method, 0.002)


def real_segments(path, scans, config):
    """Return the returns of every segment the pipeline finds in the first `scans` scans."""
    from wctls_lab.evaluation.score_cli import load_recording
    recording = load_recording(path, None)
    segments = []
    for ranges in recording.ranges[:scans]:
        features = extract_features(ranges, recording.angle_min, recording.angle_increment,
                                    config, recording.range_min, recording.range_max)
        bearings = recording.angle_min + recording.angle_increment * np.arange(len(ranges))
        valid = (np.isfinite(ranges) & (ranges >= max(recording.range_min, config.range_min_m))
                 & (ranges <= min(recording.range_max, config.range_max_m)))
        for segment in features.segments:
            beams = np.arange(segment.first_index, segment.last_index + 1)
            beams = beams[valid[beams]]
            if len(beams) == segment.num_points:      # not across the seam of a full turn
                segments.append((ranges[beams].astype(float), bearings[beams]))
    return segments


@pytest.mark.parametrize('recording', ['sick_lms111_static', 'sick_lms1xx_static',
                                       'urg04lx_office', 'lms111_building'])
@pytest.mark.parametrize('method', METHODS)
def test_fits_and_corners_equal_the_plain_reference_on_real_segments(recording, method):
    pytest.importorskip('rosbags.highlevel')
    from wctls_lab.evaluation.score_cli import node_config
    segments = real_segments(REAL_DATA / recording, 6, node_config())
    assert len(segments) >= 10
    compare_corners(segments, method, 0.001)
