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
    with np.errstate(divide='ignore', invalid='ignore'):
        inv_det = 1.0 / (a * d - b * c)
        inverse = np.stack([np.stack([d, -b], -1), np.stack([-c, a], -1)], -2)
        return inverse * inv_det[:, None, None]


def solve_2x2(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """
    Solve a stack of 2x2 systems M x = v.

    :param matrix: shape (k, 2, 2)
    :param vector: shape (k, 2)
    :return: shape (k, 2)
    """
    return np.einsum('kij,kj->ki', inverse_2x2(matrix), vector)
