# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Wheel odometry as the odometry's prior: its steps between scans, and the fit that takes it.

Against exact motions (an arc sampled at 50 Hz and interpolated at the scans), Monte Carlo (a
corridor and a room, the wheel's steps drawn from their stated covariance: the fused step's
NEES), a corridor simulated by the lab's scanner through the feature pipeline (the
along-corridor error with the wheel and with the constant velocity), and wrong wheel steps on
purpose (a slip, a kidnap, a repeated structure).
"""

import math

import numpy as np
import pytest
from test_frontend_odometry import CORNERS, numeric_jacobian, observe, WALLS
from wctls_lab.simulation import floor_plan_from_dict, full_turn_bearings, NoiseModel, \
    simulate_ranges
from wctls_ros.core import extract_features, FeatureConfig
from wctls_ros.frontend.frames import landmarks_from_features
from wctls_ros.frontend.odometry import (change_frame, compose, estimate_step, inverse, Odometry,
                                         OdometryConfig, Prior, prior_innovation)
from wctls_ros.frontend.wheel import laser_prior, WheelModel, WheelPoses

# Two long walls along x, 2.2 m apart: nothing fixes the motion along the corridor.
CORRIDOR = [((math.pi / 2, 1.0), ((-20.0, 1.0), (20.0, 1.0))),
            ((-math.pi / 2, 1.2), ((-20.0, -1.2), (20.0, -1.2)))]
NO_CORNERS = CORNERS[:0]
GATE_3DOF_95 = 7.815


def arc(t):
    """Return the pose at time t of a robot driving a circle of 2 m at 0.5 m/s, from the origin."""
    yaw = 0.25 * t
    return np.array([2.0 * math.sin(yaw), 2.0 * (1.0 - math.cos(yaw)), yaw])


def test_the_model_grows_with_the_distance_and_the_turn():
    model = WheelModel(sigma_per_m=0.1, floor_m=0.001, sigma_per_rad=0.2,
                       floor_rad=math.radians(0.5))
    covariance = model.covariance(np.array([0.3, -0.4, -0.5]))
    assert np.allclose(np.sqrt(np.diag(covariance)),
                       [0.051, 0.051, 0.1 + math.radians(0.5)], rtol=1e-12)
    assert np.count_nonzero(covariance - np.diag(np.diag(covariance))) == 0
    still = model.covariance(np.zeros(3))
    assert np.allclose(np.sqrt(np.diag(still)), [0.001, 0.001, math.radians(0.5)])
    with pytest.raises(ValueError, match='floor_m must be > 0'):
        WheelModel(floor_m=0.0)


def test_the_step_between_two_stamps_is_interpolated_and_extrapolated():
    poses = WheelPoses(timeout_s=0.5)
    for k in range(51):
        assert poses.add(0.02 * k, arc(0.02 * k)) == 'kept'
    # Between the wheel's stamps: linear interpolation of an arc sampled at 50 Hz.
    step, stated, why = poses.step(0.105, 0.205)
    assert why == 'ok' and stated is None
    assert np.allclose(step, compose(inverse(arc(0.105)), arc(0.205)), atol=2e-5)
    # After the newest pose (1.0 s), within the timeout: along the last motion.
    step, _, why = poses.step(0.9, 1.03)
    assert why == 'ok'
    assert np.allclose(step, compose(inverse(arc(0.9)), arc(1.03)), atol=5e-5)
    # A stated velocity covariance, times the interval squared.
    rate = np.diag([0.01, 0.002, 0.003])
    poses.add(1.02, arc(1.02), rate)
    _, stated, _ = poses.step(0.9, 1.02)
    assert np.allclose(stated, rate * 0.12 ** 2)


def test_what_the_wheel_cannot_give_is_named():
    poses = WheelPoses(timeout_s=0.2, keep_s=2.0)
    assert poses.step(0.0, 0.1)[2] == 'none yet'
    assert poses.add(1.0, [math.nan, 0.0, 0.0]) == 'not finite'
    assert poses.step(0.0, 0.1)[2] == 'none yet'
    for k in range(11):
        poses.add(1.0 + 0.1 * k, arc(0.1 * k))
    assert poses.step(0.9, 1.1)[2] == 'none yet'          # the wheel began after 0.9 s
    assert poses.step(1.1, 1.3)[2] == 'ok'
    assert poses.step(1.9, 2.25)[2] == 'stale'            # 0.25 s after the newest pose
    poses.add(2.5, arc(1.5))                              # a gap of 0.5 s between two poses
    assert poses.step(1.95, 2.2)[2] == 'stale'
    assert poses.step(1.3, 1.1)[2] == 'backwards'         # the scans' time ran back
    # The source's time runs back (a bag from its start): what spans the jump is refused.
    assert poses.add(0.5, arc(0.0)) == 'backwards'
    poses.add(0.6, arc(0.1))
    assert poses.step(2.4, 0.55)[2] == 'backwards'
    assert poses.step(0.3, 0.55)[2] == 'backwards'
    assert poses.step(2.4, 2.5)[2] == 'backwards'         # not 'stale': the jump says why
    assert poses.step(0.5, 0.6)[2] == 'ok'
    assert poses.step(0.3, 0.55)[2] == 'none yet'
    # Poses older than keep_s are dropped: a stamp before them is stale.
    for k in range(40):
        poses.add(0.7 + 0.1 * k, arc(0.2 + 0.1 * k))
    assert poses.step(0.8, 4.0)[2] == 'stale'


def test_the_laser_prior_is_the_robots_step_seen_from_the_mount():
    mount = np.array([0.3, -0.1, 0.4])
    robot_step = np.array([0.2, 0.05, 0.3])
    covariance = np.diag([1e-4, 4e-4, 1e-3])
    prior = laser_prior(robot_step, covariance, mount)
    # The laser, carried at its mount, moved by the prior's step.
    assert np.allclose(compose(mount, prior.step), compose(robot_step, mount), atol=1e-12)
    jacobian = numeric_jacobian(lambda s: laser_prior(s, covariance, mount).step, robot_step)
    assert np.allclose(prior.covariance, jacobian @ covariance @ jacobian.T, atol=1e-9)
    # Back on the robot (as the node publishes it): the wheel's own step and covariance.
    back, back_covariance = change_frame(prior.step, prior.covariance, mount)
    assert np.allclose(back, robot_step, atol=1e-12)
    assert np.allclose(back_covariance, covariance, atol=1e-12)
    with pytest.raises(ValueError, match='positive definite'):
        Prior(np.zeros(3), np.diag([1.0, 1.0, 0.0]))


def monte_carlo(walls, corners, truth, runs=300, seed=7):
    """Return the fused steps' errors, covariances and statuses, the wheel drawn from its own."""
    rng = np.random.default_rng(seed)
    covariance = WheelModel().covariance(truth)
    errors, covariances, estimates = [], [], []
    for _ in range(runs):
        wheel = Prior(truth + rng.multivariate_normal(np.zeros(3), covariance), covariance)
        estimate = estimate_step(observe((0, 0, 0), rng, corners, walls),
                                 observe(truth, rng, corners, walls), np.zeros(3), np.eye(3),
                                 wheel=wheel)
        error = estimate.step - truth
        error[2] = math.remainder(error[2], 2 * math.pi)
        errors.append(error)
        covariances.append(estimate.covariance)
        estimates.append(estimate)
    errors, covariances = np.array(errors), np.array(covariances)
    nees = np.einsum('ni,nij,nj->n', errors, np.linalg.inv(covariances), errors)
    return errors, covariances, nees, estimates


def test_in_a_corridor_the_axis_is_the_wheels_and_the_covariance_holds():
    truth = np.array([0.3, 0.02, 0.03])
    errors, covariances, nees, estimates = monte_carlo(CORRIDOR, NO_CORNERS, truth)
    assert {(e.status, e.prior_source, e.prior_rejected) for e in estimates} == {
        ('degenerate', 'wheel', False)}
    assert 2.7 <= nees.mean() <= 3.3
    assert 0.93 <= np.mean(nees <= GATE_3DOF_95) <= 0.97
    # Along the corridor the wheel's std (5 % of 0.3 m and 2 mm: 17 mm), across it the walls'.
    wheel_sigma = math.sqrt(WheelModel().covariance(truth)[0, 0])
    predicted = np.sqrt(covariances.mean(axis=0).diagonal())
    assert predicted[0] == pytest.approx(wheel_sigma, rel=0.01)
    assert predicted[1] < 0.01
    assert np.std(errors[:, 0]) == pytest.approx(wheel_sigma, rel=0.15)
    assert np.all(np.abs(np.std(errors, axis=0) / predicted - 1.0) < 0.15)


def test_in_a_room_the_wheel_joins_the_landmarks_and_the_covariance_holds():
    truth = np.array([0.35, -0.2, math.radians(30.0)])
    errors, covariances, nees, estimates = monte_carlo(WALLS, CORNERS, truth)
    assert {e.status for e in estimates} == {'tracking'}
    # The wheel's gate is the 99.9 % one: a draw in a few hundred lies outside it.
    fused = [(e.prior_source, e.prior_rejected) == ('wheel', False) for e in estimates]
    assert np.mean(fused) >= 0.99
    assert 2.7 <= nees.mean() <= 3.3
    assert 0.93 <= np.mean(nees <= GATE_3DOF_95) <= 0.97
    # The wheel adds its information: no direction is known worse than from the landmarks.
    rng = np.random.default_rng(1)
    previous, current = observe((0, 0, 0), rng), observe(truth, rng)
    alone = estimate_step(previous, current, np.zeros(3), np.eye(3))
    fused = estimate_step(previous, current, np.zeros(3), np.eye(3),
                          wheel=Prior(truth, WheelModel().covariance(truth)))
    assert np.linalg.eigvalsh(alone.covariance - fused.covariance).min() > -1e-15


def test_a_wheel_that_slipped_is_rejected_and_the_landmarks_stand():
    truth = np.array([0.35, -0.2, math.radians(30.0)])
    rng = np.random.default_rng(2)
    previous, current = observe((0, 0, 0), rng), observe(truth, rng)
    # The wheels spun: they claim 0.5 m more than the robot drove.
    slipped = Prior(truth + [0.5, 0.0, 0.0], WheelModel().covariance(truth + [0.5, 0.0, 0.0]))
    estimate = estimate_step(previous, current, np.zeros(3), np.eye(3), wheel=slipped)
    assert (estimate.status, estimate.prior_rejected) == ('tracking', True)
    assert np.allclose(estimate.step, truth, atol=0.01)
    # In a corridor, a wheel turned by 10 deg the walls do not see: rejected, the walls' yaw,
    # the constant velocity along the axis.
    corridor_truth = np.array([0.3, 0.0, 0.0])
    turned = Prior(corridor_truth + [0.0, 0.0, math.radians(10.0)],
                   WheelModel().covariance(corridor_truth))
    estimate = estimate_step(observe((0, 0, 0), rng, NO_CORNERS, CORRIDOR),
                             observe(corridor_truth, rng, NO_CORNERS, CORRIDOR),
                             np.array([0.25, 0.0, 0.0]), np.diag([0.04, 0.04, 0.01]),
                             wheel=turned)
    assert (estimate.status, estimate.prior_source, estimate.prior_rejected) == (
        'degenerate', 'constant_velocity', True)
    assert abs(estimate.step[2]) < math.radians(0.5)
    assert estimate.step[0] == pytest.approx(0.25, abs=0.02)     # not the wheel's 0.3 m


def test_a_kidnap_reinitializes_with_the_wheels_step_and_a_wide_covariance():
    rng = np.random.default_rng(5)
    other = observe((0, 0, 0), None, rng.uniform(-6, 6, (6, 2)),
                    [((a, r), ((-9.0, -9.0), (9.0, 9.0))) for a, r in
                     zip(rng.uniform(-3, 3, 4), rng.uniform(7, 9, 4))])
    wheel = Prior(np.array([0.1, 0.0, 0.02]), WheelModel().covariance([0.1, 0.0, 0.02]))
    estimate = estimate_step(observe((0, 0, 0)), other, np.zeros(3), np.eye(3), wheel=wheel)
    assert (estimate.status, estimate.prior_source) == ('reinitialized', 'wheel')
    assert np.array_equal(estimate.step, wheel.step)
    assert np.all(np.sqrt(np.diag(estimate.covariance))[:2] >= 1.0)
    # Too few landmarks: the wheel's step with its own covariance.
    empty = observe((0, 0, 0), None, NO_CORNERS, [])
    estimate = estimate_step(observe((0, 0, 0)), empty, np.zeros(3), np.eye(3), wheel=wheel)
    assert (estimate.status, estimate.prior_source) == ('prior', 'wheel')
    assert np.array_equal(estimate.covariance, wheel.covariance)


def test_the_wheels_gate_resolves_a_row_of_pillars_the_constant_velocity_gets_wrong():
    # Two rows of pillars 1 m apart; the sensor sees those within 3 m along the row. Moved by
    # 0.8 m, a shift of -0.2 m lays as many pillars on pillars as the true one.
    pillars = np.array([[x, y] for x in range(-8, 9) for y in (-1.0, 1.0)], dtype=float)
    truth = np.array([0.8, 0.0, 0.0])

    def seen(at):
        return observe(at, None, pillars[np.abs(pillars[:, 0] - at[0]) <= 3.0], [])

    previous, current = seen(np.zeros(3)), seen(truth)
    unknown = estimate_step(previous, current, np.zeros(3), np.diag([1.0, 1.0, 1.0]))
    assert unknown.status == 'tracking'
    # A wrong period, or the rows taken turned by 180 deg.
    assert np.abs(unknown.step - truth).max() > 0.1
    wheel = Prior(truth + [0.03, 0.0, 0.0], WheelModel().covariance(truth))
    estimate = estimate_step(previous, current, np.zeros(3), np.diag([1.0, 1.0, 1.0]),
                             wheel=wheel)
    assert (estimate.status, estimate.prior_rejected) == ('tracking', False)
    assert np.allclose(estimate.step, truth, atol=1e-3)


def test_the_innovation_counts_only_what_the_landmarks_constrain():
    # The landmarks fix y and yaw (information 1e4 and 1e6), x not at all.
    information = np.diag([0.0, 1e4, 1e6])
    prior = Prior(np.zeros(3), np.diag([0.01, 0.01, 0.0001]))
    # At the fused step, y lies 0.0099 m from the prior: by hand, r^T W r + (W r)^T I^+ (W r)
    # = 0.0099^2 / 0.01 + (0.99)^2 / 1e4.
    value = prior_innovation(information, np.array([5.0, 0.0099, 0.0]), prior)
    assert value == pytest.approx(25.0 / 0.01 + 0.0099 ** 2 / 0.01 + 0.99 ** 2 / 1e4)
    # In the linear case it is the chi-square of the difference: d^T (C + P)^-1 d.
    information = np.array([[4e4, 1e3, 0.0], [1e3, 9e4, 2e3], [0.0, 2e3, 1e6]])
    measured = np.array([0.02, -0.01, 0.003])
    prior_information = np.linalg.inv(prior.covariance)
    fused = np.linalg.solve(information + prior_information, information @ measured)
    expected = measured @ np.linalg.solve(np.linalg.inv(information) + prior.covariance,
                                          measured)
    assert prior_innovation(information, fused, prior) == pytest.approx(expected, rel=1e-9)


# A corridor 2.2 m wide and 200 m long, seen by a 720-beam scanner of 8 m range: the ends are
# never in sight.
CORRIDOR_PLAN = {'name': 'corridor', 'polylines': [
    {'closed': False, 'points': [[-50.0, 1.0], [150.0, 1.0]]},
    {'closed': False, 'points': [[-50.0, -1.2], [150.0, -1.2]]}]}
SIMULATED_NOISE = NoiseModel(range_sigma_m=0.01, bearing_sigma_rad=math.radians(0.05),
                             max_range_m=8.0)
SIMULATED_CONFIG = FeatureConfig(range_sigma_m=0.01, bearing_sigma_rad=math.radians(0.05),
                                 range_sigma_from_scan=False)
MOUNT = np.array([0.2, 0.05, 0.3])


def drive_the_corridor(seed: int, with_wheel: bool, scans: int = 40):
    """Return the odometry of a laser driven down CORRIDOR_PLAN, its true poses, the priors."""
    plan = floor_plan_from_dict(CORRIDOR_PLAN)
    angle_min, increment, bearings = full_turn_bearings(720)
    rng = np.random.default_rng(seed)
    stamps = 0.1 * np.arange(scans)
    # The robot speeds up from 0.2 to 1 m/s and slows down again, weaving a little.
    speed = 0.2 + 0.8 * np.sin(math.pi * stamps / (0.1 * scans)) ** 2
    x = np.concatenate([[0.0], np.cumsum(0.1 * speed[1:])])
    robot = np.column_stack([x, 0.05 * np.sin(stamps), 0.03 * np.sin(0.7 * stamps)])
    lasers = np.array([compose(pose, MOUNT) for pose in robot])
    odometry = Odometry(OdometryConfig(), MOUNT)
    model = WheelModel()
    updates, priors = [], []
    for k, laser in enumerate(lasers):
        walls, _ = plan.in_sensor_frame(laser)
        features = extract_features(simulate_ranges(walls, bearings, SIMULATED_NOISE, rng),
                                    angle_min, increment, SIMULATED_CONFIG, 0.05, 8.0)
        wheel = None
        if with_wheel and k:
            step = compose(inverse(robot[k - 1]), robot[k])
            covariance = model.covariance(step)
            wheel = laser_prior(step + rng.multivariate_normal(np.zeros(3), covariance),
                                covariance, MOUNT)
        updates.append(odometry.update(
            stamps[k], landmarks_from_features(features, SIMULATED_CONFIG
                                               .max_landmark_angle_sigma_rad), wheel))
        priors.append(wheel)
    # The laser's odometry starts at its mount: the truth in odom.
    truth = np.array([compose(MOUNT, compose(inverse(lasers[0]), laser)) for laser in lasers])
    return updates, truth, priors


def test_a_simulated_corridor_takes_its_axis_from_the_wheel_and_says_so():
    ends, sigmas, fused = [], [], []
    for seed in range(12):
        updates, truth, priors = drive_the_corridor(seed, True)
        assert {u.status for u in updates[1:]} == {'degenerate'}
        fused += [u.prior_source == 'wheel' and not u.prior_rejected for u in updates[1:]]
        # Each step's std along the corridor is the wheel's, matched against a keyframe or
        # not (the match's covariance with the last scan's pose, through the wheel, counted).
        for update, prior, before in zip(updates[1:], priors[1:], truth[:-1]):
            if update.prior_source == 'wheel':
                axis = np.array([math.cos(before[2]), -math.sin(before[2]), 0.0])
                assert (axis @ update.step_covariance @ axis) == pytest.approx(
                    axis @ prior.covariance @ axis, rel=0.15)
        error = updates[-1].pose - truth[-1]
        # Along the corridor (plan x): the wheel's random walk, as the covariance says.
        ends.append(error[0])
        sigmas.append(math.sqrt(updates[-1].pose_covariance[0, 0]))
        assert abs(error[1]) < 3 * math.sqrt(updates[-1].pose_covariance[1, 1])
        for update in updates:
            assert np.isfinite(update.pose_covariance).all()
    # A wheel step drawn beyond the 99.9 % gate of the walls' yaw is rejected: about 1 in 1000.
    assert np.mean(fused) >= 0.99
    assert np.sqrt(np.mean(np.square(ends))) == pytest.approx(np.mean(sigmas), rel=0.4)
    assert np.mean(sigmas) < 0.05
    # With the constant velocity alone, the speeding up and slowing down is not seen.
    updates, truth, _ = drive_the_corridor(0, False)
    assert abs(updates[-1].pose[0] - truth[-1][0]) > 1.0
    assert {u.prior_source for u in updates} == {'constant_velocity'}
