# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Closed-form batched 2x2 linear algebra that yields NaN/inf instead of raising."""

import numpy as np


def mahalanobis_squared_2x2(u: np.ndarray, v: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """
    Return w^T C^-1 w for a stack of 2-vectors w = (u, v) and symmetric 2x2 covariances.

    :param u: first components, shape (k,)
    :param v: second components, shape (k,)
    :param covariance: shape (k, 2, 2)
    :return: shape (k,); inf or NaN where C is singular (with a floating-point warning unless
        the caller silences it)
    """
    a, b, d = covariance[:, 0, 0], covariance[:, 0, 1], covariance[:, 1, 1]
    return (d * u * u - 2.0 * b * u * v + a * v * v) / (a * d - b * b)
