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

Compiled loops (numba); no ROS.
"""

import math

import numpy as np

from ._jit import jit
from .lines import normal_jacobians


@jit
def _flatness(angle_rad, start_x, start_y, end_x, end_y, flatness_sigma_m):
    """Return (Var(angle), Cov(angle, radius), Var(radius)) of (D18) for one wall."""
    dx, dy = end_x - start_x, end_y - start_y
    middle_x, middle_y = 0.5 * (start_x + end_x), 0.5 * (start_y + end_y)
    lever = middle_y * math.cos(angle_rad) - middle_x * math.sin(angle_rad)        # m . t
    end_variance = flatness_sigma_m * flatness_sigma_m
    var_angle = 2.0 * end_variance / (dx * dx + dy * dy)
    return var_angle, lever * var_angle, 0.5 * end_variance + lever * lever * var_angle


@jit
def flatness_covariance(angle_rad: np.ndarray, start_xy_m: np.ndarray, end_xy_m: np.ndarray,
                        flatness_sigma_m: float) -> np.ndarray:
    """
    Compiled twin of :func:`..numpy_core.model_error.flatness_covariance`, one wall at a time.

    :param angle_rad: normal angles, shape (S,), rad
    :param start_xy_m: first end of each wall, shape (S, 2), m
    :param end_xy_m: last end of each wall, shape (S, 2), m
    :param flatness_sigma_m: std of each end's offset from the line, m
    :return: shape (S, 2, 2): rad^2, rad m, m^2
    """
    covariance = np.empty((angle_rad.size, 2, 2))
    for s in range(angle_rad.size):
        var_angle, cov_angle_radius, var_radius = _flatness(
            angle_rad[s], start_xy_m[s, 0], start_xy_m[s, 1], end_xy_m[s, 0], end_xy_m[s, 1],
            flatness_sigma_m)
        covariance[s, 0, 0], covariance[s, 1, 1] = var_angle, var_radius
        covariance[s, 0, 1] = covariance[s, 1, 0] = cov_angle_radius
    return covariance


@jit
def residual_factor(chi2_dof: float, returns: int) -> float:
    """
    Compiled twin of :func:`..numpy_core.model_error.residual_factor` for one fit.

    :param chi2_dof: residual chi2 per degree of freedom
    :param returns: returns of the fit
    :return: max(1, chi2_dof - sqrt(2 / dof))
    """
    dof = max(returns - 2, 1)
    return max(chi2_dof - math.sqrt(2.0 / dof), 1.0)


@jit
def with_model_error(walls, residual_scaling: bool, flatness_sigma_m: float,
                     common_range_sigma_m: float):
    """
    Compiled twin of :func:`..numpy_core.pipeline._with_model_error`, one wall at a time.

    :param walls: the walls (:data:`~.records.SegmentArrays`), their covariances from the sensor
        noise alone
    :param residual_scaling: apply the variance factor of (D17)
    :param flatness_sigma_m: std of each wall end's offset from the line, m (0: none)
    :param common_range_sigma_m: std of the range offset common to the scan, m
    :return: (covariance of (angle, radius) (S, 2, 2), covariance of (a, b, c) (S, 3, 3))
    """
    line, angle_rad, normal_covariance = walls.line, walls.angle_rad, walls.covariance
    line_covariance, line_offset_jacobian = walls.line_covariance, walls.line_offset_jacobian
    start_xy_m, end_xy_m = walls.start_xy_m, walls.end_xy_m
    chi2_dof, num_points = walls.residual_chi2_dof, walls.num_points
    count = angle_rad.size
    added = np.zeros((count, 2, 2))           # the model error in (angle, radius)
    for s in range(count):
        if residual_scaling:
            excess = residual_factor(chi2_dof[s], num_points[s]) - 1.0
            for i in range(2):
                for j in range(2):
                    added[s, i, j] = excess * normal_covariance[s, i, j]
        if flatness_sigma_m > 0.0:
            var_angle, cov_angle_radius, var_radius = _flatness(
                angle_rad[s], start_xy_m[s, 0], start_xy_m[s, 1], end_xy_m[s, 0],
                end_xy_m[s, 1], flatness_sigma_m)
            added[s, 0, 0] += var_angle
            added[s, 0, 1] += cov_angle_radius
            added[s, 1, 0] += cov_angle_radius
            added[s, 1, 1] += var_radius
    to_normal = normal_jacobians(line)
    published = normal_covariance.copy()
    new_line_covariance = line_covariance.copy()
    to_line = np.zeros((3, 2))
    for s in range(count):
        cos, sin = math.cos(angle_rad[s]), math.sin(angle_rad[s])
        scale = line[s, 0] * cos + line[s, 1] * sin
        to_line[0, 0], to_line[1, 0], to_line[2, 1] = -sin * scale, cos * scale, -scale
        for i in range(3):
            for j in range(3):
                total = 0.0
                for k in range(2):
                    for m in range(2):
                        total += to_line[i, k] * added[s, k, m] * to_line[j, m]
                new_line_covariance[s, i, j] += total
        offset_angle = offset_radius = 0.0
        for k in range(3):
            offset_angle += to_normal[s, 0, k] * line_offset_jacobian[s, k]
            offset_radius += to_normal[s, 1, k] * line_offset_jacobian[s, k]
        offset_angle *= common_range_sigma_m
        offset_radius *= common_range_sigma_m
        for i in range(2):
            for j in range(2):
                published[s, i, j] += added[s, i, j]
        published[s, 0, 0] += offset_angle * offset_angle
        published[s, 0, 1] += offset_angle * offset_radius
        published[s, 1, 0] += offset_angle * offset_radius
        published[s, 1, 1] += offset_radius * offset_radius
    return published, new_line_covariance
