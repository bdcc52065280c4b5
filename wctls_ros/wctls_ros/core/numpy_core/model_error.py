# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Model error: what a wall's straight-line fit does not know about the wall.

The fits' covariances (docs/derivation.md) describe independent range and bearing noise on a
perfectly straight wall. Two terms widen them (docs/derivation.md#model-error):

- the a-posteriori variance factor: each line's covariance times its residual chi2 per degree
  of freedom, less the one standard deviation sqrt(2 / dof) that chance alone gives it, when
  that is above 1 (a wall rougher, or returns noisier, than the noise model says; the
  returns' scatter about the line is then the better estimate of their variance);
- a wall flatness sigma: each end of a wall may lie this far off the straight line through
  it (a wall straight only to a few mm, bowed or leaning), independently: the line's offset
  and direction move together, by an amount that does not shrink with the number of returns.

Pure numpy; no ROS.
"""

import numpy as np


def flatness_covariance(angle_rad: np.ndarray, start_xy_m: np.ndarray, end_xy_m: np.ndarray,
                        flatness_sigma_m: float) -> np.ndarray:
    """
    Return the (angle, radius) covariance of walls whose ends are each off by flatness_sigma.

    With the two ends displaced across the line by independent d_1, d_2 ~ N(0, sigma^2), the
    line moves by d_0 = (d_1 + d_2) / 2 at the middle of the segment and turns by
    d_angle = (d_2 - d_1) / L: Var(d_0) = sigma^2 / 2, Var(angle) = 2 sigma^2 / L^2, and
    radius = m . n (m the middle, n the unit normal) moves by d_0 + (m . t) d_angle with
    t = (-sin angle, cos angle) (docs/derivation.md#model-error, (D18)).

    :param angle_rad: normal angles, shape (S,), rad
    :param start_xy_m: first end of each wall, shape (S, 2), m
    :param end_xy_m: last end of each wall, shape (S, 2), m
    :param flatness_sigma_m: std of each end's offset from the line, m
    :return: shape (S, 2, 2): rad^2, rad m, m^2
    """
    length2 = np.sum((end_xy_m - start_xy_m) ** 2, axis=1)
    middle = 0.5 * (start_xy_m + end_xy_m)
    lever = middle[:, 1] * np.cos(angle_rad) - middle[:, 0] * np.sin(angle_rad)
    var_angle = 2.0 * flatness_sigma_m ** 2 / length2
    covariance = np.empty((len(angle_rad), 2, 2))
    covariance[:, 0, 0] = var_angle
    covariance[:, 0, 1] = covariance[:, 1, 0] = lever * var_angle
    covariance[:, 1, 1] = 0.5 * flatness_sigma_m ** 2 + lever * lever * var_angle
    return covariance


def line_covariance_added(line: np.ndarray, angle_rad: np.ndarray,
                          added: np.ndarray) -> np.ndarray:
    """
    Return an (angle, radius) covariance added to lines, as a covariance of their (a, b, c).

    Each method's (a, b, c) is lambda (cos angle, sin angle, -radius) for some lambda (its
    scale, e.g. det S_M for UTLS); the corner covariance does not depend on lambda's own
    variation (docs/derivation.md#the-wctls-corner-equals-the-wtls-corner), so d(a, b, c) /
    d(angle, radius) is J = lambda [[-sin angle, 0], [cos angle, 0], [0, -1]], and the result
    J A J^T. Written out entry by entry: the products of J @ A @ J^T less those with J's three
    zeros (which add nothing to a finite sum), without two batched matrix products.

    :param line: (a, b, c), shape (S, 3)
    :param angle_rad: normal angles, shape (S,), rad
    :param added: the covariance A added to (angle, radius), shape (S, 2, 2)
    :return: shape (S, 3, 3)
    """
    cos, sin = np.cos(angle_rad), np.sin(angle_rad)
    scale = line[:, 0] * cos + line[:, 1] * sin
    # The non-zero entries of J: d a / d angle, d b / d angle, d c / d radius.
    a, b, c = -sin * scale, cos * scale, -1.0 * scale
    # J A: rows (a A_00, a A_01), (b A_00, b A_01), (c A_10, c A_11).
    a_angle, a_radius = a * added[:, 0, 0], a * added[:, 0, 1]
    b_angle, b_radius = b * added[:, 0, 0], b * added[:, 0, 1]
    c_angle, c_radius = c * added[:, 1, 0], c * added[:, 1, 1]
    covariance = np.empty((len(angle_rad), 3, 3))
    covariance[:, 0, 0], covariance[:, 0, 1], covariance[:, 0, 2] = (a_angle * a, a_angle * b,
                                                                     a_radius * c)
    covariance[:, 1, 0], covariance[:, 1, 1], covariance[:, 1, 2] = (b_angle * a, b_angle * b,
                                                                     b_radius * c)
    covariance[:, 2, 0], covariance[:, 2, 1], covariance[:, 2, 2] = (c_angle * a, c_angle * b,
                                                                     c_radius * c)
    return covariance


def residual_factor(chi2_dof: np.ndarray, returns: np.ndarray) -> np.ndarray:
    """
    Return the a-posteriori variance factor of each fit (docs/derivation.md#model-error, (D17)).

    On a straight wall under the right noise model chi2 / dof has mean 1 and standard
    deviation sqrt(2 / dof), dof = returns - 2; the factor counts only the excess beyond that
    one standard deviation, so that clean walls keep their covariance (its mean is 1.07 at
    8 returns, 1.02 at 50).

    :param chi2_dof: residual chi2 per degree of freedom, shape (S,)
    :param returns: returns of each fit, shape (S,)
    :return: max(1, chi2_dof - sqrt(2 / dof)), shape (S,)
    """
    dof = np.maximum(returns - 2, 1)
    return np.maximum(chi2_dof - np.sqrt(2.0 / dof), 1.0)
