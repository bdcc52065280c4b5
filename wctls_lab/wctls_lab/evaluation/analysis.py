# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The paper's repeatability analysis, and the consistency check it lacks, on repeated scans.

Every method sees the same scans; its corners are associated across scans (clusters of corner
positions present in most scans), and for each associated corner the analysis compares the
propagated covariance with the real scan-to-scan scatter: the ratio of the ellipse areas and
the normalised estimation error squared (NEES, expected 2 for a calibrated 2-D estimate; the
error is taken from the corner's mean over the scans, which has no ground truth to need).
"""

from dataclasses import dataclass, field
import math
from typing import Dict, List, Sequence

import numpy as np
from wctls_ros.core import ellipse, FeatureConfig, nees

from .rules import assign, associate
from .samples import feature_config, scan_corners, ScanCorners
from .scans import StaticScans
from ..simulation import NoiseModel

PROPAGATIONS = ('full', 'diagonal')


@dataclass(frozen=True)
class CornerStats:
    """
    One associated corner under one method: propagated versus empirical covariance.

    :ivar count: scans in which the method found the corner
    :ivar mean_xy: mean position over those scans, m
    :ivar empirical_cov: covariance of the position across the scans, m^2
    :ivar propagated_cov: mean of the per-scan propagated covariances, m^2
    :ivar area_ratio: propagated over empirical 1-sigma ellipse area
    :ivar nees: mean NEES over the scans (expected 2 when calibrated)
    """

    count: int
    mean_xy: np.ndarray
    empirical_cov: np.ndarray
    propagated_cov: np.ndarray
    area_ratio: float
    nees: float


@dataclass
class Evaluation:
    """
    Everything the report shows for one set of repeated scans.

    :ivar scans: the scans
    :ivar noise: the noise model the covariances use
    :ivar methods: the methods compared
    :ivar propagation: 'full' (correct) or 'diagonal' (line covariances' off-diagonal dropped)
    :ivar per_scan: method -> one ScanCorners per scan
    :ivar centers: associated corners' positions (mean of the reference method), (K, 2), m,
        numbered clockwise from the sensor's +x axis as in the paper
    :ivar assignment: method -> (T, K) index of the corner in each scan, -1 where missing
    :ivar stats: method -> one CornerStats per associated corner
    :ivar representative: the scan the tables and the figure show
    """

    scans: StaticScans
    noise: NoiseModel
    methods: Sequence[str]
    propagation: str
    per_scan: Dict[str, List[ScanCorners]]
    centers: np.ndarray
    assignment: Dict[str, np.ndarray]
    stats: Dict[str, List[CornerStats]] = field(default_factory=dict)
    representative: int = 0

    def scan_median_areas(self, method: str) -> np.ndarray:
        """
        Return the median 1-sigma ellipse area of the corners of each scan (the paper's Fig. 4).

        :param method: one of the methods
        :return: shape (T,), mm^2 (NaN for a scan without corners)
        """
        areas = []
        for corners in self.per_scan[method]:
            covariance = corners.covariances(self.propagation)
            areas.append(float(np.median(ellipse(covariance).area)) * 1e6
                         if len(corners) else math.nan)
        return np.array(areas)

    def pooled_nees(self, method: str) -> float:
        """
        Return the mean NEES over every associated corner in every scan.

        :param method: one of the methods
        :return: the mean (2 when calibrated)
        """
        total = sum(s.nees * s.count for s in self.stats[method])
        count = sum(s.count for s in self.stats[method])
        return total / count if count else math.nan


def run_methods(scans: StaticScans, noise: NoiseModel, methods: Sequence[str],
                base: FeatureConfig = None) -> Dict[str, List[ScanCorners]]:
    """
    Extract every scan's corners with every method.

    :param scans: the scans
    :param noise: the noise model
    :param methods: the methods
    :param base: the pipeline's other settings (defaults: the paper's)
    :return: method -> one ScanCorners per scan
    """
    return {method: corners_per_scan(scans, feature_config(noise, method, base))
            for method in methods}


def features_per_scan(scans: StaticScans, config: FeatureConfig) -> list:
    """
    Extract every scan's features and corners with one configuration.

    :param scans: the scans
    :param config: the pipeline configuration (method and noise model)
    :return: one (the core's Features, ScanCorners) per scan
    """
    return [scan_corners(ranges, scans.angle_min, scans.angle_increment, scans.range_min,
                         scans.range_max, config) for ranges in scans.ranges]


def corners_per_scan(scans: StaticScans, config: FeatureConfig) -> List[ScanCorners]:
    """
    Extract every scan's corners with one configuration.

    :param scans: the scans
    :param config: the pipeline configuration (method and noise model)
    :return: one ScanCorners per scan
    """
    return [corners for _, corners in features_per_scan(scans, config)]


def corner_stats(xy: np.ndarray, covariance: np.ndarray) -> CornerStats:
    """
    Compare the propagated covariances of one corner with its scatter over the scans.

    :param xy: the corner's position in each scan where found, (n, 2), m
    :param covariance: its propagated covariance in those scans, (n, 2, 2), m^2
    :return: the statistics (NaN ratios with fewer than 3 scans)
    """
    count = len(xy)
    mean = xy.mean(axis=0)
    if count < 3:
        nan2 = np.full((2, 2), math.nan)
        return CornerStats(count, mean, nan2, covariance.mean(axis=0), math.nan, math.nan)
    error = xy - mean
    empirical = error.T @ error / (count - 1)
    propagated = covariance.mean(axis=0)
    with np.errstate(divide='ignore'):          # a corner that never moved: ratio inf
        ratio = math.sqrt(max(np.linalg.det(propagated), 0.0) / np.linalg.det(empirical))
    return CornerStats(count, mean, empirical, propagated, ratio,
                       float(np.mean(nees(error, covariance))))


def evaluate_scans(scans: StaticScans, noise: NoiseModel, methods: Sequence[str],
                   propagation: str = 'full', min_presence: float = 0.8,
                   base: FeatureConfig = None, reference: str = None) -> Evaluation:
    """
    Run the whole analysis on repeated scans from a still sensor.

    :param scans: the scans (check them with :func:`~.scans.require_still` first)
    :param noise: the noise model the covariances use
    :param methods: the methods to compare
    :param propagation: 'full' (correct) or 'diagonal' (the paper-gap analysis)
    :param min_presence: keep corners found in at least this fraction of the scans
    :param base: the pipeline's other settings (defaults: the paper's)
    :param reference: the method whose corners define the association (default: 'wtls' when
        compared, else the first method)
    :return: the evaluation
    :raises ValueError: on an unknown propagation
    """
    if propagation not in PROPAGATIONS:
        raise ValueError(f'propagation must be one of {PROPAGATIONS}, got {propagation!r}')
    methods = list(methods)
    per_scan = run_methods(scans, noise, methods, base)
    if reference is None:
        reference = 'wtls' if 'wtls' in methods else methods[0]
    centers, radii = associate(per_scan[reference], min_presence)
    assignment = {m: assign(per_scan[m], centers, radii) for m in methods}
    evaluation = Evaluation(scans, noise, methods, propagation, per_scan, centers, assignment)
    for method in methods:
        stats = []
        for k in range(len(centers)):
            hits = [(t, i) for t, i in enumerate(assignment[method][:, k]) if i >= 0]
            xy = np.array([per_scan[method][t].xy[i] for t, i in hits]).reshape(-1, 2)
            cov = np.array([per_scan[method][t].covariances(propagation)[i]
                            for t, i in hits]).reshape(-1, 2, 2)
            stats.append(corner_stats(xy, cov))
        evaluation.stats[method] = stats
    present = (assignment[reference] >= 0).sum(axis=1)
    evaluation.representative = int(np.argmax(present)) if len(present) else 0
    return evaluation
