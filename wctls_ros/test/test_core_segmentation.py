# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Segmentation kernels against independent references: IEPF, moment fits, merging, end cuts."""

import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from wctls_ros.core.numba_core.segmentation import (merge_segments, moment_line, pass_budget,
                                                    split_iepf, trim_offset)
from wctls_ros.core.records import Lines, Noise, Segments


def recursive_end_point_fit(x, y, start, stop, threshold):
    """Textbook IEPF, one run at a time: the reference for the compiled version."""
    if stop - start < 3:
        return [(start, stop)] if stop - start else []
    dx, dy = x[stop - 1] - x[start], y[stop - 1] - y[start]
    length = math.hypot(dx, dy)
    if length <= 1e-9:
        return [(start, stop)]
    distance = [abs((x[i] - x[start]) * dy - (y[i] - y[start]) * dx) / length
                for i in range(start, stop)]
    cut = start + int(np.argmax(distance))
    if distance[cut - start] <= threshold:
        return [(start, stop)]
    return (recursive_end_point_fit(x, y, start, cut, threshold)
            + recursive_end_point_fit(x, y, cut + 1, stop, threshold))


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), corners=st.integers(1, 12),
       noise=st.sampled_from([0.0, 0.005, 0.03]), runs=st.integers(1, 4))
def test_iepf_equals_the_recursive_textbook_version(seed, corners, noise, runs):
    rng = np.random.default_rng(seed)
    # A random polyline sampled unevenly, with noise, cut into runs.
    vertices = np.cumsum(rng.uniform(-1.0, 1.0, (corners + 1, 2)), axis=0)
    t = np.sort(rng.uniform(0.0, corners, rng.integers(10, 300)))
    segment = np.minimum(t.astype(int), corners - 1)
    frac = (t - segment)[:, None]
    xy = vertices[segment] * (1 - frac) + vertices[segment + 1] * frac
    xy += rng.normal(0.0, noise, xy.shape)
    x, y = xy[:, 0].copy(), xy[:, 1].copy()
    cuts = np.unique(rng.integers(0, len(x), runs - 1))
    start, stop = np.concatenate([[0], cuts]), np.concatenate([cuts, [len(x)]])
    (found_start, found_stop, found_chain), cut_short = split_iepf(
        x, y, Segments(start, stop, np.arange(len(start))), np.full(len(x), 0.04),
        pass_budget(len(x)))
    assert not cut_short
    expected = [piece for s, e in zip(start, stop)
                for piece in recursive_end_point_fit(x, y, s, e, 0.04) if piece[1] - piece[0] >= 3]
    assert list(zip(found_start.tolist(), found_stop.tolist())) == expected
    assert found_chain.tolist() == [int(np.searchsorted(start, s, side='right')) - 1
                                    for s, _ in expected]


def test_iepf_splits_at_the_first_of_equally_far_returns():
    # Two runs shaped like a roof ridge: returns 1 and 2 (5 and 6) are equally far from the chord.
    ridge_x = np.array([0.0, 1.0, 2.0, 3.0, 3.5, 4.0, 4.5, 5.0, 6.0, 7.0])
    ridge_y = np.array([0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    x, y = np.concatenate([ridge_x, ridge_x + 10]), np.concatenate([ridge_y, ridge_y])
    (start, stop, _), _ = split_iepf(
        x, y, Segments(np.array([0, 10]), np.array([10, 20]), np.array([0, 1])),
        np.full(len(x), 0.04), pass_budget(len(x)))
    expected = [piece for s, e in ((0, 10), (10, 20))
                for piece in recursive_end_point_fit(x, y, s, e, 0.04) if piece[1] - piece[0] >= 3]
    assert list(zip(start.tolist(), stop.tolist())) == expected == [
        (4, 10), (14, 20)]


def test_moment_line_is_the_orthogonal_regression_with_its_monte_carlo_covariance():
    rng = np.random.default_rng(11)
    angle, radius, sigma = 2.5, 1.7, 0.01
    along = np.linspace(-0.2, 0.5, 60)              # off-centre: angle and radius correlate
    truth = np.column_stack([radius * math.cos(angle) - along * math.sin(angle),
                             radius * math.sin(angle) + along * math.cos(angle)])
    fits = []
    for _ in range(3000):                           # isotropic noise: the model is exact
        xy = truth + rng.normal(0.0, sigma, truth.shape)
        fits.append(moment_line(xy[:, 0].copy(), xy[:, 1].copy(), 0, len(xy), sigma, 0.0))
    estimates = np.array([fit[:2] for fit in fits])
    covariance = np.mean([[[fit[2], fit[3]], [fit[3], fit[4]]] for fit in fits], axis=0)
    standard_error = np.sqrt(np.diag(covariance) / len(fits))
    assert (np.abs(estimates.mean(axis=0) - [angle, radius]) < 4.0 * standard_error).all()
    empirical = np.cov(estimates.T)
    np.testing.assert_allclose(np.diag(empirical) / np.diag(covariance), 1.0, atol=0.08)
    assert empirical[0, 1] / covariance[0, 1] == pytest.approx(1.0, rel=0.12)
    # The line is the orthogonal regression: the normal is the centred returns' minor axis.
    centre = xy.mean(axis=0)
    normal = np.linalg.svd(xy - centre)[2][1]
    normal *= np.sign(normal @ centre)
    np.testing.assert_allclose(fits[-1][:2],
                               [math.atan2(normal[1], normal[0]), normal @ centre], atol=1e-10)


def test_merging_across_touching_chains_makes_them_one_chain():
    # One straight wall seen as four pieces on three chains that touch (noise breakpoints),
    # then a wall at a right angle on a fourth chain.
    wall = np.linspace(0.0, 2.0, 80)
    corner = np.linspace(0.05, 1.0, 20)
    x = np.concatenate([wall, np.full(20, 2.0)])
    y = np.concatenate([np.full(80, 1.0), 1.0 + corner])
    (start, stop, chain), (angle, radius), cut_short = merge_segments(
        x, y, Segments(np.array([0, 20, 40, 60, 80]), np.array([20, 40, 60, 80, 100]),
                       np.array([0, 1, 1, 2, 3])),
        False, np.ones(len(x), dtype=bool), noise_of(0.01), 13.8, 10)
    assert not cut_short
    assert start.tolist() == [0, 80] and stop.tolist() == [80, 100]
    assert chain[0] != chain[1]
    np.testing.assert_allclose(radius, [1.0, 2.0], atol=1e-9)


# The frame trim_offset measures returns in: the line y = 1.5 (normal angle pi / 2, radius 1.5).
ON_THE_LINE = Lines(np.array([math.pi / 2]), np.array([1.5]))


def noise_of(range_sigma_m: float, bearing_sigma_rad: float = 0.0) -> Noise:
    """Return the noise of a kernel's decisions: the range noise without model error."""
    return Noise(range_sigma_m, bearing_sigma_rad, range_sigma_m)


@pytest.mark.parametrize('at_start', [False, True])
def test_a_run_off_the_line_at_an_end_is_cut_exactly(at_start):
    # 40 returns on a line, the 5 at one end 2.5 sigma off it. Against the line of the other
    # 35, Z_5 = 12.5 with Var(Z_5) = 5 + 25 (1 / 35 + t^2 Var(angle) / sigma^2) = 8.6 (t the
    # run's distance from their centroid): 4.3 > 4, and less for any other k: exactly 5 cut.
    sigma, count = 0.01, 40
    x, y = np.linspace(-0.8, 0.8, count), np.full(count, 1.5)
    off = slice(0, 5) if at_start else slice(count - 5, count)
    y[off] -= 2.5 * sigma
    one = Segments(np.array([0]), np.array([count]), np.array([0]))
    start, stop, _ = trim_offset(one, x, y, ON_THE_LINE, noise_of(sigma), 8, 4.0, 8)
    assert (start[0], stop[0]) == ((5, count) if at_start else (0, count - 5))
    # The run pulls the line of all 40 towards itself: tested against that line, as the rule
    # did before, it peaks at 3.3 and stays. As the frame, that line cuts the same 5.
    angle, radius = moment_line(x, y, 0, count, sigma, 0.0)[:2]
    residual = (x * math.cos(angle) + y * math.sin(angle) - radius) / sigma
    ends = residual[:8] if at_start else residual[::-1][:8]
    assert np.max(np.abs(np.cumsum(ends)) / np.sqrt(np.arange(1, 9))) < 3.5
    start, stop, _ = trim_offset(one, x, y, Lines(np.array([angle]), np.array([radius])),
                                 noise_of(sigma), 8, 4.0, 8)
    assert (start[0], stop[0]) == ((5, count) if at_start else (0, count - 5))
    # A step of 2 sigma peaks at 10 / sqrt(8.6) = 3.4 < 4: kept.
    y[off] += 0.5 * sigma
    start, stop, _ = trim_offset(one, x, y, ON_THE_LINE, noise_of(sigma), 8, 4.0, 8)
    assert (start[0], stop[0]) == (0, count)


def test_an_end_cuts_at_most_half_the_returns_beyond_the_minimum():
    sigma = 0.01
    x, y = np.linspace(-0.8, 0.8, 14), np.full(14, 1.5)
    y[-8:] += 10.0 * sigma                      # far off: the score peaks at the window's end
    start, stop, _ = trim_offset(Segments(np.array([0]), np.array([14]), np.array([0])), x, y,
                                 ON_THE_LINE, noise_of(sigma), 8, 4.0, 8)
    assert (start[0], stop[0]) == (0, 11)                        # (14 - 8) // 2 = 3 cut


def test_straight_walls_are_rarely_cut():
    # 4000 noisy straight walls: against the line of a wall's other returns, Z_k / sqrt(Var(Z_k))
    # is standard normal for each k, so the largest of 8 exceeds 4 with probability below
    # 8 P(|N| > 4) = 5e-4 per end (4 of these 8000 ends are cut). Without the line's own error
    # in Var(Z_k) the rule would cut 35 (measured once, with a throwaway polyfit).
    rng = np.random.default_rng(7)
    sigma, walls, count = 0.01, 4000, 60
    x = np.tile(np.linspace(-0.8, 0.8, count), walls)
    y = 1.5 + rng.normal(0.0, sigma, walls * count)
    start = np.arange(walls) * count
    frame = Lines(np.full(walls, math.pi / 2), np.full(walls, 1.5))
    trimmed_start, trimmed_stop, _ = trim_offset(
        Segments(start, start + count, np.arange(walls)), x, y, frame, noise_of(sigma), 8, 4.0,
        8)
    cut_ends = np.count_nonzero(trimmed_start != start) + np.count_nonzero(
        trimmed_stop != start + count)
    assert cut_ends <= 8                        # 2 * 4000 * 5e-4 = 4 expected at most
