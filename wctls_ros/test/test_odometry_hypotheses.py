# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The odometry's hypotheses from a corner and a line, and its prior over a longer gap.

Scenes of test_frontend_odometry, observed with their covariances' noise; the truth is the
simulated motion.
"""

import math

import numpy as np

from test_frontend_odometry import observe
from wctls_ros.frontend.odometry import (corner_line_hypotheses, estimate_step, Odometry,
                                         OdometryConfig)

# A corridor along x, 2 m wide, with one pillar: no two corners and no two walls off parallel.
CORRIDOR = [((math.pi / 2, 1.0), ((-20.0, 1.0), (20.0, 1.0))),
            ((-math.pi / 2, 1.0), ((-20.0, -1.0), (20.0, -1.0)))]
PILLAR = np.array([[2.5, 0.4]])


def test_a_corner_and_a_wall_find_a_motion_far_from_the_prior():
    """Two parallel walls and one corner: only a corner-line pair proposes the motion."""
    rng = np.random.default_rng(8)
    truth = np.array([0.9, 0.1, math.radians(35.0)])
    errors = []
    for _ in range(50):
        previous = observe((0.0, 0.0, 0.0), rng, PILLAR, CORRIDOR)
        current = observe(truth, rng, PILLAR, CORRIDOR)
        hypotheses = corner_line_hypotheses(previous, current)
        assert np.min(np.abs(hypotheses - truth).max(axis=1)) < 0.05
        # No velocity known yet: the prior's spread is the reinitialization's (1 m, 60 deg).
        estimate = estimate_step(previous, current, np.zeros(3), np.diag([1.0, 1.0, 1.1]))
        assert estimate.status == 'tracking'
        error = estimate.step - truth
        errors.append(error @ np.linalg.solve(estimate.covariance, error))
    assert 2.0 <= np.mean(errors) <= 4.2                 # 3 dof; 50 draws: +- 0.6 at 2 sigma


def test_the_priors_growth_scales_with_the_gap_it_bridges():
    """A scan without landmarks takes the prior: a gap 10 times the last widens it 10 times."""
    config = OdometryConfig()
    empty = observe((0.0, 0.0, 0.0), None, PILLAR[:0], [])
    stds = []
    for gap_s in (0.1, 1.0):
        odometry = Odometry(config)
        for k in range(4):
            odometry.update(0.1 * k, observe((0.05 * k, 0.0, 0.0)))
        update = odometry.update(0.3 + gap_s, empty)
        assert update.status == 'prior'
        stds.append(np.sqrt(update.step_covariance.diagonal()))
    assert np.all(stds[0] < 1.1 * np.array([config.prior_sigma_m, config.prior_sigma_m,
                                            config.prior_sigma_rad]))
    assert np.all(stds[1] >= 10.0 * np.array([config.prior_sigma_m, config.prior_sigma_m,
                                              config.prior_sigma_rad]))


def test_a_period_of_repeated_structure_that_associates_more_loses_to_the_prior():
    """Two rows of pillars 1 m apart: the view moves on, the motion one period on sees more."""
    rows = [(x, y) for x in range(-1, 4) for y in (-1.0, 1.0)]
    truth = np.array([0.3, 0.0, 0.0])
    rng = np.random.default_rng(6)
    # The previous scan saw x = 0..3, the current sees x = -1..2: the true motion associates
    # three pillars of each row, the motion 1 m further all four.
    previous = observe((0.0, 0.0, 0.0), rng, np.array([p for p in rows if p[0] >= 0]), [])
    current = observe(truth, rng, np.array([p for p in rows if p[0] <= 2]), [])
    estimate = estimate_step(previous, current, truth, np.diag([0.01, 0.01, 0.003]))
    assert estimate.status == 'tracking'
    assert estimate.corners == 6
    assert np.abs(estimate.step - truth).max() < 0.02


def test_a_velocity_held_beyond_the_largest_step_gives_no_motion_where_nothing_matches():
    """0.5 m/s over 10 s would be 5 m, beyond max_step_m: no motion, with the grown spread."""
    config = OdometryConfig()
    odometry = Odometry(config)
    for k in range(4):
        odometry.update(0.1 * k, observe((0.05 * k, 0.0, 0.0)))
    update = odometry.update(10.3, observe((0.0, 0.0, 0.0), None, PILLAR[:0], []))
    assert update.status == 'prior'
    assert np.array_equal(update.step, np.zeros(3))
    assert np.all(np.sqrt(update.step_covariance.diagonal())
                  >= [config.reinit_sigma_m, config.reinit_sigma_m, config.reinit_sigma_rad])
