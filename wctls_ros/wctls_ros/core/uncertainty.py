# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Uncertainty helpers: covariance ellipses, confidence scaling and NEES."""

from dataclasses import dataclass
import math

import numpy as np


@dataclass(frozen=True)
class Ellipse:
    """
    The 1-sigma ellipse of 2D covariances (arrays of shape (k,) for k ellipses).

    :ivar semi_major: semi-axis along the largest variance, m (sqrt of the larger eigenvalue)
    :ivar semi_minor: the other semi-axis, m
    :ivar orientation_rad: angle of the major axis from +x, rad in (-pi/2, pi/2]
    :ivar area: pi * semi_major * semi_minor = pi sqrt(det C), m^2
    """

    semi_major: np.ndarray
    semi_minor: np.ndarray
    orientation_rad: np.ndarray
    area: np.ndarray


def ellipse(covariance: np.ndarray) -> Ellipse:
    """
    Return the 1-sigma ellipses of 2x2 covariances.

    :param covariance: shape (2, 2) or (k, 2, 2), m^2
    :return: the ellipses (arrays of shape (k,); scalars' shape () for one covariance)
    """
    cov = np.asarray(covariance, dtype=float)
    xx, yy, xy = cov[..., 0, 0], cov[..., 1, 1], cov[..., 0, 1]
    half_trace = 0.5 * (xx + yy)
    spread = np.hypot(0.5 * (xx - yy), xy)
    major = np.sqrt(half_trace + spread)
    minor = np.sqrt(np.maximum(half_trace - spread, 0.0))
    orientation = 0.5 * np.arctan2(2.0 * xy, xx - yy)
    return Ellipse(major, minor, orientation, math.pi * major * minor)


def confidence_scale(probability: float) -> float:
    """
    Return the factor k such that the k-sigma ellipse of a 2D Gaussian holds ``probability``.

    For 2 degrees of freedom P(chi2 <= k^2) = 1 - exp(-k^2 / 2), so k = sqrt(-2 ln(1 - p));
    e.g. 0.95 -> 2.448, 0.99 -> 3.035 (1 sigma holds 39.3 %).

    :param probability: in (0, 1)
    :return: the scale factor k
    :raises ValueError: outside (0, 1)
    """
    if not 0.0 < probability < 1.0:
        raise ValueError(f'probability must be in (0, 1), got {probability}')
    return math.sqrt(-2.0 * math.log1p(-probability))


def nees(error: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """
    Return the normalised estimation error squared e^T C^-1 e of each estimate.

    For a calibrated d-dimensional estimate its mean is d (2 for a corner position).

    :param error: estimate minus truth, shape (d,) or (k, d)
    :param covariance: shape (d, d) or (k, d, d)
    :return: shape () or (k,)
    """
    error = np.asarray(error, dtype=float)
    covariance = np.asarray(covariance, dtype=float)
    solved = np.linalg.solve(covariance, error[..., None])[..., 0]
    return np.einsum('...i,...i->...', error, solved)
