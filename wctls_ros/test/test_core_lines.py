# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Line fits and corner propagation against finite differences and Monte Carlo."""

import math

import numpy as np
import pytest
from wctls_ros.core import (find_corners, fit_lines, intersect, METHODS, nees, segment_returns,
                            SegmentSet)
from wctls_ros.core.numba_core import corners as compiled_corners
from wctls_ros.core.numba_core.lines import normal_form, utls, wctls, wtls
from wctls_ros.core.numpy_core import corners as numpy_corners
from wctls_ros.core.records import SegmentArrays

RANGE_SIGMA = 0.05
BEARING_SIGMA = math.radians(0.391)


def wall_returns(normal_angle, radius, along_m, rng=None, sigmas=(0.0, 0.0)):
    """Polar returns of points on a wall, optionally with polar noise."""
    foot = radius * np.array([math.cos(normal_angle), math.sin(normal_angle)])
    direction = np.array([-math.sin(normal_angle), math.cos(normal_angle)])
    xy = foot + np.asarray(along_m)[:, None] * direction
    rho, theta = np.hypot(xy[:, 0], xy[:, 1]), np.arctan2(xy[:, 1], xy[:, 0])
    if rng is not None:
        rho = rho + rng.normal(0.0, sigmas[0], rho.shape)
        theta = theta + rng.normal(0.0, sigmas[1], theta.shape)
    return rho, theta


def fd_covariance(estimate, rho, theta, step=1e-6):
    """Covariance of estimate(rho, theta) by central differences over every return."""
    columns = []
    for values, sigma in ((rho, RANGE_SIGMA), (theta, BEARING_SIGMA)):
        for i in range(len(values)):
            up, down = values.copy(), values.copy()
            h = step * max(1.0, abs(values[i]))
            up[i] += h
            down[i] -= h
            args_up = (up, theta) if values is rho else (rho, up)
            args_down = (down, theta) if values is rho else (rho, down)
            columns.append(sigma * (estimate(*args_up) - estimate(*args_down)) / (2 * h))
    jac = np.column_stack(columns)
    return jac @ jac.T


def single(rho, theta):
    return segment_returns(rho, theta, [0], [len(rho)])


@pytest.mark.parametrize('fit', [utls, wtls, wctls], ids=['utls', 'wtls', 'wctls'])
@pytest.mark.parametrize('normal_angle,radius,along', [
    (0.3, 2.0, np.linspace(-1.0, 1.5, 25)),
    (-2.4, 3.7, np.linspace(0.4, 2.9, 60)),
    (1.9, 1.1, np.linspace(-0.2, 0.3, 12)),
])
def test_analytic_covariance_matches_finite_differences(fit, normal_angle, radius, along):
    rho, theta = wall_returns(normal_angle, radius, along, np.random.default_rng(7),
                              (0.02, 0.002))
    _, analytic, _ = fit(single(rho, theta), RANGE_SIGMA, BEARING_SIGMA)
    numeric = fd_covariance(lambda r, t: fit(single(r, t), 1.0, 1.0)[0][0], rho, theta)
    assert np.abs(numeric - analytic[0]).max() / np.abs(analytic[0]).max() < 1e-5


def test_normal_form_covariance_matches_finite_differences():
    rho, theta = wall_returns(2.2, 1.6, np.linspace(-0.8, 0.6, 30),
                              np.random.default_rng(3), (0.02, 0.002))
    returns = single(rho, theta)
    _, _, analytic = normal_form(*utls(returns, RANGE_SIGMA, BEARING_SIGMA)[:2])

    def angle_radius(r, t):
        angle, radius, _ = normal_form(*utls(single(r, t), 1.0, 1.0)[:2])
        return np.array([angle[0], radius[0]])
    numeric = fd_covariance(angle_radius, rho, theta)
    assert np.abs(numeric - analytic[0]).max() / np.abs(analytic[0]).max() < 1e-5


def test_ml_fisher_covariance_equals_propagated_covariance_on_exact_returns():
    # At zero residuals the first-order covariance of the ML estimator is exactly F^-1.
    rho, theta = wall_returns(-0.7, 2.4, np.linspace(-1.2, 0.9, 40))

    def angle_radius(r, t):
        fits = fit_lines('ml', single(r, t), RANGE_SIGMA, BEARING_SIGMA)
        return np.array([fits.angle_rad[0], fits.radius_m[0]])
    fisher_inverse = fit_lines('ml', single(rho, theta), RANGE_SIGMA,
                               BEARING_SIGMA).normal_covariance[0]
    numeric = fd_covariance(angle_radius, rho, theta)
    assert np.abs(numeric - fisher_inverse).max() / np.abs(fisher_inverse).max() < 1e-5
    assert fit_lines('ml', single(rho, theta), RANGE_SIGMA, BEARING_SIGMA).radius_m[0] == \
        pytest.approx(2.4, abs=1e-12)


def two_walls(corner, first_direction, second_direction, counts, rng=None):
    """Return the returns of two walls leaving a corner, as one batch of two segments."""
    corner = np.asarray(corner, dtype=float)
    parts = []
    for direction, count in zip((first_direction, second_direction), counts):
        u = np.array([math.cos(direction), math.sin(direction)])
        xy = corner + np.linspace(0.1, 1.3, count)[:, None] * u
        rho, theta = np.hypot(*xy.T), np.arctan2(xy[:, 1], xy[:, 0])
        if rng is not None:
            rho = rho + rng.normal(0.0, RANGE_SIGMA, count)
            theta = theta + rng.normal(0.0, BEARING_SIGMA, count)
        parts.append((rho, theta))
    return segment_returns(np.concatenate([parts[0][0], parts[1][0]]),
                           np.concatenate([parts[0][1], parts[1][1]]),
                           [0, counts[0]], list(counts))


def corner_of(fits, scale=(1.0, 1.0)):
    """Corner (x, y, yaw) and its 3x3 covariance from two fitted lines, lines rescaled."""
    k = np.asarray(scale)[:, None]
    line = fits.line * k
    cov = fits.line_covariance * (k * k)[:, :, None]
    ends = np.array([[5.0, 5.0], [5.0, 5.0]])
    found = find_corners(line, cov, ends, ends, [0], [1], 0.1)
    return found


@pytest.mark.parametrize('method', METHODS)
def test_corner_covariance_is_invariant_to_rescaling_a_line(method):
    fits = fit_lines(method, two_walls([2.5, 1.0], math.pi, -math.pi / 2, (40, 30),
                                       np.random.default_rng(11)), RANGE_SIGMA, BEARING_SIGMA)
    reference = corner_of(fits).covariance[0]
    for scale in [(1e6, 1.0), (1.0, 1e-6), (-1e-6, 1e6), (-3.0, -1.0)]:
        scaled = corner_of(fits, scale).covariance[0]
        assert np.abs(scaled - reference).max() / np.abs(reference).max() < 1e-9


def test_wctls_corner_equals_wtls_corner():
    returns = two_walls([-1.8, 2.7], 0.0, -math.pi / 2, (25, 70), np.random.default_rng(5))
    wtls_corner = corner_of(fit_lines('wtls', returns, RANGE_SIGMA, BEARING_SIGMA))
    wctls_corner = corner_of(fit_lines('wctls', returns, RANGE_SIGMA, BEARING_SIGMA))
    np.testing.assert_allclose(wctls_corner.xy_m, wtls_corner.xy_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(wctls_corner.covariance, wtls_corner.covariance, rtol=1e-9)
    # ... while the lines' own covariances are in different parameterisations.
    assert not np.allclose(fit_lines('wctls', returns, 1, 1).line_covariance,
                           fit_lines('wtls', returns, 1, 1).line_covariance)


def test_joint_corner_covariance_matches_finite_differences():
    fits = fit_lines('utls', two_walls([2.0, -1.5], math.pi / 2, math.pi + 0.3, (30, 30),
                                       np.random.default_rng(2)), RANGE_SIGMA, BEARING_SIGMA)
    ends = np.full((2, 2), 5.0)

    def corner_state(line):
        found = find_corners(line, fits.line_covariance, ends, ends, [0], [1], 0.1)
        return np.array([*found.xy_m[0], found.yaw_rad[0]])
    jac = np.zeros((3, 6))
    for j in range(6):
        h = 1e-7 * max(1.0, abs(fits.line.flat[j]))
        up, down = fits.line.copy(), fits.line.copy()
        up.flat[j] += h
        down.flat[j] -= h
        jac[:, j] = (corner_state(up) - corner_state(down)) / (2 * h)
    block = np.zeros((6, 6))
    block[:3, :3], block[3:, 3:] = fits.line_covariance
    numeric = jac @ block @ jac.T
    analytic = corner_of(fits).covariance[0]
    assert np.abs(numeric - analytic).max() / np.abs(analytic).max() < 1e-5


def bisector_state(line, inside_xy):
    """
    Return a corner's (x, y, yaw), computed here: where two lines meet, and their bisector.

    :param line: (a, b, c) of the two walls, shape (2, 3)
    :param inside_xy: a point on each wall on the side of its returns, shape (2, 2), m
    """
    corner = np.linalg.solve(line[:, :2], -line[:, 2])
    directions = np.column_stack([-line[:, 1], line[:, 0]])
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    directions *= np.sign(((inside_xy - corner) * directions).sum(axis=1))[:, None]
    bisector = directions.sum(axis=0)
    return np.array([*corner, math.atan2(bisector[1], bisector[0])])


@pytest.mark.parametrize('core', [numpy_corners, compiled_corners], ids=['numpy', 'compiled'])
def test_corner_covariance_matches_finite_differences(core):
    # Both walls' full line covariances, and a range offset common to the scan that moves both
    # lines together (line k by its offset Jacobian): the covariance of the corner state of two
    # WCTLS lines (not normalised) against central differences over the six line parameters and
    # the offset.
    corner, directions, common_sigma = np.array([1.8, 1.1]), (math.pi + 0.2, -math.pi / 2), 0.02
    fits = fit_lines('wctls', two_walls(corner, *directions, (35, 25), np.random.default_rng(6)),
                     RANGE_SIGMA, BEARING_SIGMA)
    inside = corner + 0.7 * np.array([[math.cos(d), math.sin(d)] for d in directions])
    jacobian = np.zeros((3, 7))
    steps = [(j, fits.line.flat[j], np.eye(6)[j].reshape(2, 3)) for j in range(6)]
    steps.append((6, 0.0, fits.line_offset_jacobian))
    for column, value, direction in steps:
        h = 1e-7 * max(1.0, abs(value))
        jacobian[:, column] = (bisector_state(fits.line + h * direction, inside)
                               - bisector_state(fits.line - h * direction, inside)) / (2 * h)
    inputs = np.zeros((7, 7))
    inputs[:3, :3], inputs[3:6, 3:6] = fits.line_covariance
    inputs[6, 6] = common_sigma ** 2
    numeric = jacobian @ inputs @ jacobian.T
    walls = SegmentArrays(**vars(SegmentSet.filled(
        2, line=fits.line, line_covariance=fits.line_covariance,
        line_offset_jacobian=fits.line_offset_jacobian)))     # all corner_covariance reads
    analytic = core.corner_covariance(walls, np.array([0]), np.array([1]), common_sigma)
    assert analytic.shape == (1, 3, 3)
    assert np.abs(numeric - analytic[0]).max() / np.abs(analytic[0]).max() < 1e-5


def test_intersection_is_the_common_point_of_both_lines():
    lines = np.array([[1.0, 0.0, -2.0], [0.0, 2.0, -3.0]])     # x = 2 and y = 1.5
    xy, cov, _, _ = intersect(lines[:1], np.eye(3)[None], lines[1:], np.eye(3)[None])
    np.testing.assert_allclose(xy, [[2.0, 1.5]])
    assert np.all(np.linalg.eigvalsh(cov[0]) > 0)


# Corners 1.5-4 m away, 15-100 returns per wall, at the paper's S1 noise figures.
MONTE_CARLO_CASES = [
    ([2.5, 1.0], math.pi, -math.pi / 2, (40, 40)),
    ([1.5, -0.5], math.pi / 2, math.pi, (15, 15)),
    ([-2.0, 3.0], 0.0, -math.pi / 2, (30, 80)),
    ([-1.2, -2.6], 0.4, math.pi / 2 + 0.4, (100, 20)),
]


@pytest.mark.parametrize('corner,first,second,counts', MONTE_CARLO_CASES)
def test_monte_carlo_corner_covariance_is_calibrated(corner, first, second, counts):
    trials = 400
    rng = np.random.default_rng(20261122)
    batches = [two_walls(corner, first, second, counts, rng) for _ in range(trials)]
    rho = np.concatenate([b.rho for b in batches])
    theta = np.concatenate([b.theta for b in batches])
    lengths = np.tile(counts, trials)
    offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    returns = segment_returns(rho, theta, offsets, lengths)
    for method in METHODS:
        fits = fit_lines(method, returns, RANGE_SIGMA, BEARING_SIGMA)
        ends = np.full((2 * trials, 2), 1e3)
        found = find_corners(fits.line, fits.line_covariance, ends, ends,
                             np.arange(0, 2 * trials, 2), np.arange(1, 2 * trials, 2), 0.1)
        assert len(found) == trials
        error = found.xy_m - np.asarray(corner)
        covariance = found.covariance[:, :2, :2]
        mean_nees = nees(error, covariance).mean()
        area_ratio = math.sqrt(np.linalg.det(covariance.mean(axis=0))
                               / np.linalg.det(np.cov(error.T)))
        assert 1.8 <= mean_nees <= 2.2, f'{method}: mean NEES {mean_nees:.2f}'
        assert 0.9 <= area_ratio <= 1.1, f'{method}: area ratio {area_ratio:.3f}'


def test_corner_covariances_are_exactly_symmetric():
    returns = two_walls([2.2, -0.7], 2.0, -2.5, (33, 47), np.random.default_rng(9))
    fits = fit_lines('wctls', returns, RANGE_SIGMA, BEARING_SIGMA)
    covariance = corner_of(fits).covariance
    np.testing.assert_array_equal(covariance, covariance.transpose(0, 2, 1))


@pytest.mark.parametrize('method', METHODS)
def test_offset_jacobian_matches_shifting_every_range(method):
    # The ML fit's Jacobian is first order (like its Fisher covariance): exact on exact returns.
    rng = None if method == 'ml' else np.random.default_rng(4)
    returns = two_walls([2.4, 0.8], math.pi, -math.pi / 2 + 0.2, (35, 25), rng)

    def fit(offset):
        shifted = segment_returns(returns.rho + offset, returns.theta, returns.offsets,
                                  returns.counts)
        return fit_lines(method, shifted, RANGE_SIGMA, BEARING_SIGMA)
    h = 1e-6
    numeric_line = (fit(h).line - fit(-h).line) / (2 * h)
    numeric_normal = np.column_stack([
        (fit(h).angle_rad - fit(-h).angle_rad) / (2 * h),
        (fit(h).radius_m - fit(-h).radius_m) / (2 * h)])
    fits = fit(0.0)
    scale = np.abs(fits.line_offset_jacobian).max()
    assert np.abs(numeric_line - fits.line_offset_jacobian).max() < 1e-5 * scale
    np.testing.assert_allclose(fits.normal_offset_jacobian, numeric_normal, rtol=1e-5,
                               atol=1e-9)


@pytest.mark.parametrize('method', METHODS)
def test_common_range_offset_is_propagated_with_its_correlation(method):
    # 1 mm independent noise and a 5 mm offset common to each scan: only the joint term
    # (both walls move together) makes the corner covariance match the scatter.
    trials, counts, corner = 400, (40, 30), np.array([2.0, 1.2])
    rng = np.random.default_rng(77)
    sigmas = (0.001, 0.0, 0.005)
    batches = []
    for _ in range(trials):
        walls = two_walls(corner, math.pi, -math.pi / 2, counts)
        batches.append((walls.rho + rng.normal(0.0, sigmas[0], walls.rho.shape)
                        + rng.normal(0.0, sigmas[2]), walls.theta))
    rho = np.concatenate([b[0] for b in batches])
    theta = np.concatenate([b[1] for b in batches])
    lengths = np.tile(counts, trials)
    returns = segment_returns(rho, theta, np.cumsum(lengths) - lengths, lengths)
    fits = fit_lines(method, returns, 0.001, 1e-9)
    ends = np.full((2 * trials, 2), 1e3)
    pairs = (np.arange(0, 2 * trials, 2), np.arange(1, 2 * trials, 2))
    with_common = find_corners(fits.line, fits.line_covariance, ends, ends, *pairs, 0.1,
                               fits.line_offset_jacobian, sigmas[2])
    without = find_corners(fits.line, fits.line_covariance, ends, ends, *pairs, 0.1)
    error = with_common.xy_m - corner
    assert 1.8 <= nees(error, with_common.covariance[:, :2, :2]).mean() <= 2.2
    assert nees(error, without.covariance[:, :2, :2]).mean() > 10.0


def test_uncertainty_helpers():
    from wctls_ros.core import confidence_scale, ellipse
    c, s = math.cos(0.4), math.sin(0.4)
    rotation = np.array([[c, -s], [s, c]])
    covariance = rotation @ np.diag([0.03 ** 2, 0.01 ** 2]) @ rotation.T
    shape = ellipse(covariance)
    assert (shape.semi_major, shape.semi_minor) == pytest.approx((0.03, 0.01))
    assert shape.orientation_rad == pytest.approx(0.4)
    assert shape.area == pytest.approx(math.pi * math.sqrt(np.linalg.det(covariance)))
    # The k-sigma ellipse holds p of a 2D Gaussian: checked by sampling.
    k = confidence_scale(0.95)
    assert k == pytest.approx(2.4477, abs=1e-4)
    samples = np.random.default_rng(8).multivariate_normal([0, 0], covariance, 20000)
    assert np.mean(nees(samples, np.broadcast_to(covariance, (20000, 2, 2))) <= k * k) == \
        pytest.approx(0.95, abs=0.005)
    with pytest.raises(ValueError, match='probability'):
        confidence_scale(1.0)
