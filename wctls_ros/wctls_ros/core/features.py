# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The extracted features of one scan.

Segments and corners are held as arrays (``SegmentSet``, ``CornerSet``: one row per feature, fast
to convert to messages) and read one at a time as small records (``Segment``, ``Corner``):
``features.corners[0].x_m`` or ``for corner in features.corners``.
"""

from dataclasses import dataclass
import math

import numpy as np


@dataclass(frozen=True)
class Segment:
    """
    One straight segment: the line x cos(angle) + y sin(angle) = radius and its extent.

    :ivar angle_rad: normal angle, from the sensor towards the line, rad in (-pi, pi]
    :ivar radius_m: distance of the line from the sensor, m (>= 0)
    :ivar covariance: covariance of (angle, radius), shape (2, 2): rad^2, rad m, m^2 (all noise
        terms of the configuration, the common-mode range offset included)
    :ivar line: (a, b, c) of a x + b y + c = 0 as the method defines them, shape (3,)
    :ivar line_covariance: covariance of (a, b, c) from the independent per-return noise,
        shape (3, 3)
    :ivar line_offset_jacobian: d(a, b, c) / d(range offset common to every return of the
        scan), shape (3,), per m (the common-mode part of the covariance is sigma^2 g g^T)
    :ivar start_xy_m: first return projected on the line, shape (2,), m
    :ivar end_xy_m: last return projected on the line, shape (2,), m
    :ivar first_index: beam index of the first return in the scan's ranges
    :ivar last_index: beam index of the last return (smaller than first_index on a segment
        that crosses the seam of a full turn)
    :ivar num_points: number of returns fitted
    :ivar residual_chi2_dof: sum of the squared residuals from the line, each over the
        variance of the return across the line, per degree of freedom (num_points - 2): about 1
        when the wall is straight and the noise model right, above it when the wall bows or the
        noise is larger than modelled
    """

    angle_rad: float
    radius_m: float
    covariance: np.ndarray
    line: np.ndarray
    line_covariance: np.ndarray
    line_offset_jacobian: np.ndarray
    start_xy_m: np.ndarray
    end_xy_m: np.ndarray
    first_index: int
    last_index: int
    num_points: int
    residual_chi2_dof: float


@dataclass(frozen=True)
class Corner:
    """
    One corner: where two adjacent walls meet.

    :ivar x_m: position x, m
    :ivar y_m: position y, m
    :ivar yaw_rad: bisector of the walls, pointing into the open side the sensor sees, rad
    :ivar covariance: joint covariance of (x, y, yaw), shape (3, 3): m^2, m rad, rad^2
    :ivar opening_angle_rad: angle between the walls through the open side, rad in (0, 2 pi)
    :ivar first_segment: index of the earlier segment in the same Features
    :ivar second_segment: index of the later segment
    :ivar first_end_seen: a return of the first wall lies within a beam of the corner (else the
        corner sits in a run of beams without returns, e.g. a dark corner)
    :ivar second_end_seen: the same for the second wall
    """

    x_m: float
    y_m: float
    yaw_rad: float
    covariance: np.ndarray
    opening_angle_rad: float
    first_segment: int
    second_segment: int
    first_end_seen: bool
    second_end_seen: bool

    @property
    def position_covariance(self) -> np.ndarray:
        """
        Return the covariance of (x, y).

        :return: shape (2, 2), m^2
        """
        return self.covariance[:2, :2]


class _Rows:
    """Iteration over a struct of arrays one row (record) at a time."""

    def __iter__(self):
        return (self[i] for i in range(len(self)))


@dataclass(frozen=True)
class SegmentSet(_Rows):
    """
    The segments of one scan as arrays, one row per segment (fields as in :class:`Segment`).

    Shapes: angle_rad, radius_m, first_index, last_index, num_points, residual_chi2_dof (S,);
    covariance (S, 2, 2); line, line_offset_jacobian (S, 3); line_covariance (S, 3, 3);
    start_xy_m, end_xy_m (S, 2).
    """

    angle_rad: np.ndarray
    radius_m: np.ndarray
    covariance: np.ndarray
    line: np.ndarray
    line_covariance: np.ndarray
    line_offset_jacobian: np.ndarray
    start_xy_m: np.ndarray
    end_xy_m: np.ndarray
    first_index: np.ndarray
    last_index: np.ndarray
    num_points: np.ndarray
    residual_chi2_dof: np.ndarray

    def __len__(self):
        return len(self.angle_rad)

    def __getitem__(self, i: int) -> Segment:
        return Segment(float(self.angle_rad[i]), float(self.radius_m[i]), self.covariance[i],
                       self.line[i], self.line_covariance[i], self.line_offset_jacobian[i],
                       self.start_xy_m[i], self.end_xy_m[i], int(self.first_index[i]),
                       int(self.last_index[i]), int(self.num_points[i]),
                       float(self.residual_chi2_dof[i]))

    def select(self, keep: np.ndarray) -> 'SegmentSet':
        """
        Return the segments where ``keep`` selects (a boolean or index array).

        :param keep: selection over the segments
        :return: the selected segments
        """
        return SegmentSet(*(getattr(self, name)[keep] for name in self.__dataclass_fields__))

    @staticmethod
    def empty() -> 'SegmentSet':
        """
        Return a set without segments.

        :return: the empty set
        """
        return SegmentSet(np.zeros(0), np.zeros(0), np.zeros((0, 2, 2)), np.zeros((0, 3)),
                          np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 2)),
                          np.zeros((0, 2)), np.zeros(0, np.intp), np.zeros(0, np.intp),
                          np.zeros(0, np.intp), np.zeros(0))


@dataclass(frozen=True)
class CornerSet(_Rows):
    """
    The corners of one scan as arrays, one row per corner (fields as in :class:`Corner`).

    Shapes: xy_m (C, 2); yaw_rad, opening_angle_rad, first_segment, second_segment (C,);
    covariance (C, 3, 3) over (x, y, yaw); end_seen (C, 2), column 0 the first wall.
    """

    xy_m: np.ndarray
    yaw_rad: np.ndarray
    covariance: np.ndarray
    opening_angle_rad: np.ndarray
    first_segment: np.ndarray
    second_segment: np.ndarray
    end_seen: np.ndarray

    def __len__(self):
        return len(self.yaw_rad)

    def __getitem__(self, i: int) -> Corner:
        return Corner(float(self.xy_m[i, 0]), float(self.xy_m[i, 1]), float(self.yaw_rad[i]),
                      self.covariance[i], float(self.opening_angle_rad[i]),
                      int(self.first_segment[i]), int(self.second_segment[i]),
                      bool(self.end_seen[i, 0]), bool(self.end_seen[i, 1]))

    def select(self, keep: np.ndarray) -> 'CornerSet':
        """
        Return the corners where ``keep`` selects (a boolean or index array).

        :param keep: selection over the corners
        :return: the selected corners
        """
        return CornerSet(self.xy_m[keep], self.yaw_rad[keep], self.covariance[keep],
                         self.opening_angle_rad[keep], self.first_segment[keep],
                         self.second_segment[keep], self.end_seen[keep])

    @staticmethod
    def empty() -> 'CornerSet':
        """
        Return a set without corners.

        :return: the empty set
        """
        return CornerSet(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3, 3)), np.zeros(0),
                         np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros((0, 2), bool))


@dataclass(frozen=True)
class Features:
    """
    Everything extracted from one scan.

    :ivar method: the line fit used: 'utls', 'wtls', 'wctls' or 'ml'
    :ivar segments: the segments, in scan order
    :ivar corners: the corners, in scan order; their segment indices point into ``segments``
    :ivar work_limited: the per-scan work bound stopped splitting or merging early: returns
        that were still not straight after the allowed passes are left out, or neighbouring
        segments stayed apart (a scan no real scene gives; see
        :func:`wctls_ros.core.numpy_core.segmentation.pass_budget`)
    :ivar range_sigma_m: the range noise the scan was processed with (its own estimate when
        ``range_sigma_from_scan``, never below ``range_sigma_m``), m; NaN for a scan with too
        few returns to process
    :ivar noise_implausible: the scan's range-noise estimate exceeded ``max_range_sigma_m``:
        no features (:mod:`wctls_ros.core.plausibility`)
    :ivar implausible_features: segments and corners left out because their position std
        exceeded the plausibility bound for their range
    """

    method: str
    segments: SegmentSet
    corners: CornerSet
    work_limited: bool = False
    range_sigma_m: float = math.nan
    noise_implausible: bool = False
    implausible_features: int = 0


@dataclass(frozen=True)
class SegmentReturns:
    """
    The returns of S segments laid end to end.

    :ivar rho: ranges, shape (P,), m
    :ivar theta: bearings, shape (P,), rad
    :ivar x: rho cos(theta), shape (P,), m
    :ivar y: rho sin(theta), shape (P,), m
    :ivar offsets: first return of each segment, shape (S,)
    :ivar counts: returns per segment, shape (S,), each >= 2
    """

    rho: np.ndarray
    theta: np.ndarray
    x: np.ndarray
    y: np.ndarray
    offsets: np.ndarray
    counts: np.ndarray


def segment_returns(rho, theta, offsets, counts, x=None, y=None) -> SegmentReturns:
    """
    Bundle the returns of consecutive segments for the batched fits.

    :param rho: ranges, shape (P,), m
    :param theta: bearings, shape (P,), rad
    :param offsets: first return of each segment, shape (S,)
    :param counts: returns per segment, shape (S,), each >= 2
    :param x: rho cos(theta) when already known, shape (P,), m
    :param y: rho sin(theta) when already known, shape (P,), m
    :return: the bundle
    """
    rho = np.asarray(rho, dtype=float)
    theta = np.asarray(theta, dtype=float)
    counts = np.asarray(counts, dtype=np.intp)
    if x is None or y is None:
        x, y = rho * np.cos(theta), rho * np.sin(theta)
    return SegmentReturns(rho, theta, x, y, np.asarray(offsets, dtype=np.intp), counts)


@dataclass(frozen=True)
class LineFits:
    """
    Fitted lines of S segments, in the method's own form and in normal form.

    :ivar line: (a, b, c) of a x + b y + c = 0 as the method defines them, shape (S, 3)
    :ivar line_covariance: covariance of (a, b, c), shape (S, 3, 3), in units of (a, b, c)^2
    :ivar angle_rad: direction of the line's normal, pointing from the origin to the line,
        shape (S,), rad in (-pi, pi]
    :ivar radius_m: distance of the line from the origin, shape (S,), m, >= 0
    :ivar normal_covariance: covariance of (angle, radius), shape (S, 2, 2): rad^2, rad m, m^2
    :ivar line_offset_jacobian: d(a, b, c) / d(range offset common to all returns), (S, 3), per m
    :ivar normal_offset_jacobian: d(angle, radius) / d(common range offset), (S, 2): rad/m, m/m
    """

    line: np.ndarray
    line_covariance: np.ndarray
    angle_rad: np.ndarray
    radius_m: np.ndarray
    normal_covariance: np.ndarray
    line_offset_jacobian: np.ndarray
    normal_offset_jacobian: np.ndarray

    def select(self, keep: np.ndarray) -> 'LineFits':
        """
        Return the fits where ``keep`` selects (a boolean or index array over the segments).

        :param keep: selection over the segments
        :return: the selected fits
        """
        return LineFits(self.line[keep], self.line_covariance[keep], self.angle_rad[keep],
                        self.radius_m[keep], self.normal_covariance[keep],
                        self.line_offset_jacobian[keep], self.normal_offset_jacobian[keep])
