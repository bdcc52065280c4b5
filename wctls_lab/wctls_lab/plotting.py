# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Figures of scans and features with matplotlib (Agg backend: no display needed)."""

import math

import numpy as np

from wctls_ros.core import ellipse, Features

# The paper draws the 1-sigma ellipses magnified ten times.
PAPER_ELLIPSE_SCALE = 10.0


def pyplot():
    """
    Return matplotlib.pyplot on the Agg backend.

    :return: the pyplot module
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def add_covariance_ellipses(ax, xy_m: np.ndarray, covariance: np.ndarray, scale: float,
                            colour: str, label: str = None, line_width: float = 1.0) -> None:
    """
    Draw the 1-sigma ellipses of 2D positions, magnified.

    :param ax: matplotlib axes
    :param xy_m: centres, shape (C, 2), m
    :param covariance: position covariances, shape (C, 2, 2), m^2
    :param scale: magnification of the 1-sigma semi-axes
    :param colour: matplotlib colour
    :param label: legend label (given to the first ellipse only)
    :param line_width: outline width, points
    """
    from matplotlib.patches import Ellipse as EllipsePatch
    shape = ellipse(np.asarray(covariance).reshape(-1, 2, 2))
    for k, (centre, major, minor, orientation) in enumerate(zip(
            np.asarray(xy_m).reshape(-1, 2), shape.semi_major, shape.semi_minor,
            shape.orientation_rad)):
        ax.add_patch(EllipsePatch(centre, 2 * scale * float(major), 2 * scale * float(minor),
                                  angle=math.degrees(float(orientation)), fill=False,
                                  color=colour, lw=line_width,
                                  label=label if k == 0 else None))


def draw_scan_features(ax, ranges_m: np.ndarray, bearings_rad: np.ndarray, features: Features,
                       ellipse_scale: float = PAPER_ELLIPSE_SCALE,
                       colour: str = 'tab:red') -> None:
    """
    Draw one scan's returns, segments, numbered corners and their covariance ellipses.

    :param ax: matplotlib axes
    :param ranges_m: the scan's ranges, shape (N,), m (invalid returns are skipped)
    :param bearings_rad: the beams' bearings, shape (N,), rad
    :param features: the features extracted from the scan
    :param ellipse_scale: magnification of the 1-sigma ellipses
    :param colour: colour of the corners and ellipses
    """
    valid = np.isfinite(ranges_m)
    ax.plot(ranges_m[valid] * np.cos(bearings_rad[valid]),
            ranges_m[valid] * np.sin(bearings_rad[valid]), '.', color='0.6', ms=1.5,
            label='returns')
    for k, segment in enumerate(features.segments):
        ax.plot([segment.start_xy_m[0], segment.end_xy_m[0]],
                [segment.start_xy_m[1], segment.end_xy_m[1]], '-', color='black', lw=1.0,
                label='segments' if k == 0 else None)
    corners = features.corners
    add_covariance_ellipses(ax, corners.xy_m, corners.covariance[:, :2, :2], ellipse_scale,
                            colour, f'1-sigma ellipses x{ellipse_scale:g}')
    for k, (x, y) in enumerate(corners.xy_m):
        ax.plot(x, y, '^', color=colour, ms=4)
        ax.annotate(str(k), (x, y), textcoords='offset points', xytext=(4, 4), fontsize=7)
    ax.plot(0.0, 0.0, 'b*', ms=8, label='sensor')
    ax.set_aspect('equal')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
