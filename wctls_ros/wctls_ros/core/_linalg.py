"""Closed-form batched 2x2 linear algebra that yields NaN/inf instead of raising."""

import numpy as np


def inverse_2x2(matrix: np.ndarray) -> np.ndarray:
    """
    Invert a stack of 2x2 matrices; singular ones give inf or NaN entries (never an exception).

    :param matrix: shape (k, 2, 2)
    :return: shape (k, 2, 2)
    """
    a, b = matrix[:, 0, 0], matrix[:, 0, 1]
    c, d = matrix[:, 1, 0], matrix[:, 1, 1]
    inverse = np.empty_like(matrix, dtype=float)
    with np.errstate(divide='ignore', invalid='ignore'):
        inv_det = 1.0 / (a * d - b * c)
    inverse[:, 0, 0], inverse[:, 0, 1] = d * inv_det, -b * inv_det
    inverse[:, 1, 0], inverse[:, 1, 1] = -c * inv_det, a * inv_det
    return inverse


def solve_2x2(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """
    Solve a stack of 2x2 systems M x = v.

    :param matrix: shape (k, 2, 2)
    :param vector: shape (k, 2)
    :return: shape (k, 2)
    """
    inverse = inverse_2x2(matrix)
    solution = np.empty_like(vector, dtype=float)
    solution[:, 0] = inverse[:, 0, 0] * vector[:, 0] + inverse[:, 0, 1] * vector[:, 1]
    solution[:, 1] = inverse[:, 1, 0] * vector[:, 0] + inverse[:, 1, 1] * vector[:, 1]
    return solution


def mahalanobis_squared_2x2(vector: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """
    Return v^T C^-1 v for a stack of 2-vectors and symmetric 2x2 covariances.

    :param vector: shape (k, 2)
    :param covariance: shape (k, 2, 2)
    :return: shape (k,); inf or NaN where C is singular
    """
    a, b, d = covariance[:, 0, 0], covariance[:, 0, 1], covariance[:, 1, 1]
    u, v = vector[:, 0], vector[:, 1]
    with np.errstate(divide='ignore', invalid='ignore'):
        return (d * u * u - 2.0 * b * u * v + a * v * v) / (a * d - b * b)
