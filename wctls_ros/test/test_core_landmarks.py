# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The line landmark rule: a segment is a landmark when its own angle std is within the bound.

On segments built with known covariances the rule keeps exactly those within the bound (the
bound itself included) and every segment at 180 deg; on a simulated scan a long wall is a
landmark and a short face of a box far away is not, while both still make the box's corner.
"""

import math

import numpy as np
from wctls_lab.simulation import floor_plan_from_dict, NoiseModel, simulate_recording
from wctls_ros.core import (angle_sigma_rad, extract_features, FeatureConfig, line_landmarks,
                            SegmentSet)


def segments_with_angle_sigmas(sigmas_rad) -> SegmentSet:
    """Return segments whose (angle, radius) covariances have these angle stds."""
    count = len(sigmas_rad)
    covariance = np.zeros((count, 2, 2))
    covariance[:, 0, 0] = np.square(sigmas_rad)
    covariance[:, 1, 1] = 1e-4
    covariance[:, 0, 1] = covariance[:, 1, 0] = 0.5 * np.asarray(sigmas_rad) * 1e-2
    return SegmentSet.filled(count, covariance=covariance)     # all angle_sigma_rad reads


def test_the_rule_keeps_the_segments_within_the_angle_bound():
    sigmas = np.radians([0.5, 2.9, 3.0, 3.1, 10.0, 45.0])
    segments = segments_with_angle_sigmas(sigmas)
    np.testing.assert_allclose(angle_sigma_rad(segments), sigmas)
    bound = math.radians(3.0)
    np.testing.assert_array_equal(line_landmarks(segments, bound),
                                  [True, True, True, False, False, False])
    np.testing.assert_array_equal(line_landmarks(segments, math.radians(1.0)),
                                  [True, False, False, False, False, False])
    assert line_landmarks(segments, math.pi).all()
    assert line_landmarks(segments_with_angle_sigmas([]), bound).shape == (0,)


def test_the_default_bound_is_three_degrees_and_a_parameter():
    assert FeatureConfig().max_landmark_angle_sigma_rad == math.radians(3.0)
    from wctls_ros.params import FEATURE_NODE
    parameter = next(p for p in FEATURE_NODE if p.name == 'max_landmark_angle_sigma_deg')
    assert parameter.default == 3.0 and parameter.limits.holds(180.0)
    assert not parameter.limits.holds(0.0)


def test_a_long_wall_is_a_landmark_and_a_short_far_face_is_not():
    # A long wall 2 m ahead, and a box 4 m behind whose faces are 0.4 m wide; a 2 cm sensor.
    plan = floor_plan_from_dict({
        'name': 'wall and box',
        'polylines': [{'closed': False, 'points': [[2.0, -3.0], [2.0, 3.0]]}],
        'boxes': [{'center': [-4.0, 0.0], 'size': [0.4, 0.4], 'yaw_deg': 45.0}],
        'sensor': {'x': 0.0, 'y': 0.0, 'yaw_deg': 0.0}})
    noise = NoiseModel(range_sigma_m=0.02, bearing_sigma_rad=math.radians(0.05))
    recording = simulate_recording(plan, noise, 1, seed=3, beams=1440)
    config = FeatureConfig().replace(range_sigma_m=0.02)
    features = extract_features(recording.ranges[0], recording.angle_min,
                                recording.angle_increment, config)
    segments = features.segments
    middle = 0.5 * (segments.start_xy_m + segments.end_xy_m)
    is_landmark = line_landmarks(segments, config.max_landmark_angle_sigma_rad)
    wall = np.flatnonzero(np.abs(middle[:, 0] - 2.0) < 0.1)
    faces = np.flatnonzero(middle[:, 0] < -3.5)
    assert len(wall) == 1 and len(faces) == 2
    assert is_landmark[wall].all() and not is_landmark[faces].any()
    # Their angles are known to 4-5 deg from their 12-13 returns, the wall's to 0.04 deg.
    assert np.degrees(angle_sigma_rad(segments)[faces]).min() > 3.5
    # The box's faces still make its corner: the rule selects lines, not corners.
    corner_walls = {int(features.corners.first_segment[k]) for k in range(len(features.corners))}
    corner_walls |= {int(k) for k in features.corners.second_segment}
    assert set(faces.tolist()) <= corner_walls
