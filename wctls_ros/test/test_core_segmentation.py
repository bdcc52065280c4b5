# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Segmentation internals against independent references: IEPF, sums, merging, end cuts."""

import math

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
from wctls_ros.core.segmentation import (iterative_end_point_fit, merge_collinear, moment_fit,
                                         moment_terms, pass_budget, piece_sums, SegmentRanges,
                                         trim_offset_ends)


def recursive_end_point_fit(x, y, start, stop, threshold):
    """Textbook IEPF, one run at a time: the reference for the batched version."""
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
def test_batched_iepf_equals_the_recursive_textbook_version(seed, corners, noise, runs):
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
    found, cut_short = iterative_end_point_fit(x, y, start, stop, np.arange(len(start)), 0.04,
                                               pass_budget(len(x)))
    assert not cut_short
    expected = [piece for s, e in zip(start, stop)
                for piece in recursive_end_point_fit(x, y, s, e, 0.04) if piece[1] - piece[0] >= 3]
    assert list(zip(found.start.tolist(), found.stop.tolist())) == expected
    assert found.chain.tolist() == [int(np.searchsorted(start, s, side='right')) - 1
                                    for s, _ in expected]


def test_iepf_splits_at_the_first_of_equally_far_returns():
    # Two runs shaped like a roof ridge: returns 1 and 2 (5 and 6) are equally far from the chord.
    ridge_x = np.array([0.0, 1.0, 2.0, 3.0, 3.5, 4.0, 4.5, 5.0, 6.0, 7.0])
    ridge_y = np.array([0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    x, y = np.concatenate([ridge_x, ridge_x + 10]), np.concatenate([ridge_y, ridge_y])
    found, _ = iterative_end_point_fit(x, y, np.array([0, 10]), np.array([10, 20]),
                                       np.array([0, 1]), 0.04, pass_budget(len(x)))
    expected = [piece for s, e in ((0, 10), (10, 20))
                for piece in recursive_end_point_fit(x, y, s, e, 0.04) if piece[1] - piece[0] >= 3]
    assert list(zip(found.start.tolist(), found.stop.tolist())) == expected == [
        (4, 10), (14, 20)]


def test_piece_sums_give_the_sums_of_any_run_of_pieces_wrapping_or_not():
    rng = np.random.default_rng(5)
    values = rng.normal(size=(3, 40))
    segments = SegmentRanges(np.array([2, 9, 20, 31]), np.array([7, 18, 30, 40]),
                             np.zeros(4, dtype=np.intp))
    sums = piece_sums(values, segments)
    pieces = sums.pieces(segments)
    np.testing.assert_array_equal(sums.positions(pieces).start, segments.start)
    np.testing.assert_array_equal(sums.positions(pieces).stop, segments.stop)
    np.testing.assert_allclose(sums.over(pieces),
                               [values[:, s:e].sum(axis=1) for s, e in
                                zip(segments.start, segments.stop)], rtol=1e-12)
    # Segment 3 merged with segment 0 across the end of a full turn: positions 31..40, 0..7.
    count = sums.edges.size - 1
    merged = SegmentRanges(pieces.start[3:], pieces.stop[:1] + count, np.zeros(1, dtype=np.intp))
    assert sums.positions(merged).stop.tolist() == [47]
    np.testing.assert_allclose(sums.over(merged)[0],
                               values[:, 31:].sum(axis=1) + values[:, :7].sum(axis=1), rtol=1e-12)


def test_moment_fit_is_the_orthogonal_regression_with_its_monte_carlo_covariance():
    rng = np.random.default_rng(11)
    angle, radius, sigma = 2.5, 1.7, 0.01
    along = np.linspace(-0.2, 0.5, 60)              # off-centre: angle and radius correlate
    truth = np.column_stack([radius * math.cos(angle) - along * math.sin(angle),
                             radius * math.sin(angle) + along * math.cos(angle)])
    fits = []
    for _ in range(3000):                           # isotropic noise: the model is exact
        xy = truth + rng.normal(0.0, sigma, truth.shape)
        fits.append(moment_fit(moment_terms(xy[:, 0], xy[:, 1]).sum(axis=1)[None], sigma, 0.0))
    estimates = np.array([[f[0][0], f[1][0]] for f in fits])
    covariance = np.mean([f[2][0] for f in fits], axis=0)
    standard_error = np.sqrt(np.diag(covariance) / len(fits))
    assert (np.abs(estimates.mean(axis=0) - [angle, radius]) < 4.0 * standard_error).all()
    empirical = np.cov(estimates.T)
    np.testing.assert_allclose(np.diag(empirical) / np.diag(covariance), 1.0, atol=0.08)
    assert empirical[0, 1] / covariance[0, 1] == pytest.approx(1.0, rel=0.12)
    # The line is the orthogonal regression: the normal is the centred returns' minor axis.
    centre = xy.mean(axis=0)
    normal = np.linalg.svd(xy - centre)[2][1]
    normal *= np.sign(normal @ centre)
    np.testing.assert_allclose([fits[-1][0][0], fits[-1][1][0]],
                               [math.atan2(normal[1], normal[0]), normal @ centre], atol=1e-10)


def test_merging_across_touching_chains_makes_them_one_chain():
    # One straight wall seen as four pieces on three chains that touch (noise breakpoints),
    # then a wall at a right angle on a fourth chain.
    wall = np.linspace(0.0, 2.0, 80)
    corner = np.linspace(0.05, 1.0, 20)
    x = np.concatenate([wall, np.full(20, 2.0)])
    y = np.concatenate([np.full(80, 1.0), 1.0 + corner])
    segments = SegmentRanges(np.array([0, 20, 40, 60, 80]), np.array([20, 40, 60, 80, 100]),
                             np.array([0, 1, 1, 2, 3]))
    sums = piece_sums(moment_terms(x, y), segments)
    merged, (angle, radius, _), cut_short = merge_collinear(
        sums.pieces(segments), False, sums.edges.size - 1,
        lambda pieces: moment_fit(sums.over(pieces), 0.01, 0.0), 13.8, 10)
    assert not cut_short
    merged = sums.positions(merged)
    assert merged.start.tolist() == [0, 80] and merged.stop.tolist() == [80, 100]
    assert merged.chain[0] != merged.chain[1]
    np.testing.assert_allclose(radius, [1.0, 2.0], atol=1e-9)


@pytest.mark.parametrize('at_start', [False, True])
def test_a_run_off_the_line_at_an_end_is_cut_exactly(at_start):
    # The last 5 returns 2 sigma off the line: |Z_k| / sqrt(k) = 2 sqrt(k) rises to 4.47 at
    # k = 5 and falls after it, since the other returns lie on the line: exactly 5 are cut.
    sigma = 0.01
    x, y = np.linspace(-0.8, 0.8, 40), np.full(40, 1.5)
    off = slice(0, 5) if at_start else slice(35, 40)
    y[off] -= 2.0 * sigma
    segments = SegmentRanges(np.array([0]), np.array([40]), np.array([0]))
    trimmed = trim_offset_ends(segments, 40, x, y, np.array([math.pi / 2]), np.array([1.5]),
                               sigma, 0.0, 8, 4.0)
    assert (trimmed.start[0], trimmed.stop[0]) == ((5, 40) if at_start else (0, 35))
    # A step of 1.5 sigma peaks at 1.5 sqrt(5) = 3.35 < 4: kept.
    y[off] += 0.5 * sigma
    kept = trim_offset_ends(segments, 40, x, y, np.array([math.pi / 2]), np.array([1.5]),
                            sigma, 0.0, 8, 4.0)
    assert (kept.start[0], kept.stop[0]) == (0, 40)


def test_an_end_cuts_at_most_half_the_returns_beyond_the_minimum():
    sigma = 0.01
    x, y = np.linspace(-0.8, 0.8, 14), np.full(14, 1.5)
    y[-8:] += 10.0 * sigma                      # far off: the score peaks at the window's end
    segments = SegmentRanges(np.array([0]), np.array([14]), np.array([0]))
    trimmed = trim_offset_ends(segments, 14, x, y, np.array([math.pi / 2]), np.array([1.5]),
                               sigma, 0.0, 8, 4.0)
    assert (trimmed.start[0], trimmed.stop[0]) == (0, 11)        # (14 - 8) // 2 = 3 cut


def test_straight_walls_are_rarely_cut():
    # 4000 noisy straight walls fitted by moment_fit, as in the pipeline: on one line
    # max_k |Z_k| / sqrt(k) over 8 returns exceeds 4 with probability below 8 P(|N| > 4) = 5e-4
    # per end (fewer: the noise used is an upper bound). Without the sqrt(k) the rule would cut
    # about 1 end in 6.
    rng = np.random.default_rng(7)
    sigma, walls, count = 0.01, 4000, 60
    x = np.tile(np.linspace(-0.8, 0.8, count), walls)
    y = 1.5 + rng.normal(0.0, sigma, walls * count)
    start = np.arange(walls) * count
    segments = SegmentRanges(start, start + count, np.arange(walls))
    sums = np.add.reduceat(moment_terms(x, y), start, axis=1).T
    angle, radius, _ = moment_fit(sums, sigma, 0.0)
    trimmed = trim_offset_ends(segments, x.size, x, y, angle, radius, sigma, 0.0, 8, 4.0)
    cut_ends = np.count_nonzero(trimmed.start != start) + np.count_nonzero(
        trimmed.stop != start + count)
    assert cut_ends <= 8                        # 2 * 4000 * 5e-4 = 4 expected at most
