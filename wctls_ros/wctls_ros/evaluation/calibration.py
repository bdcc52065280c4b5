# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Fit the sensor noise model from a static recording, and check it on the corners.

From the ranges alone (no corners, no ground truth), on the beams that hit the interior of
straight walls (segments of the median scan, a few returns away from their ends):

- the per-scan common-mode range offset o_t is the mean over those beams of the deviation of
  the range from the beam's median; its variance (less the part the independent noise
  leaves in a mean over many beams) is ``common_range_sigma_m^2``;
- after removing o_t, each beam's variance over the scans is modelled as
  ``range_sigma^2 + bearing_sigma^2 (d rho / d theta)^2``, with d rho / d theta =
  rho tan(incidence) from the beam's wall: a bearing error moves the return along the wall,
  which changes its range in proportion to the incidence. A least-squares fit (non-negative,
  with outlying beams such as mixed pixels trimmed) gives both sigmas.
"""

from dataclasses import dataclass
import math

import numpy as np

from .samples import NoiseParameters
from .scans import StaticScans
from ..core import extract_features, FeatureConfig

# Returns this close to a segment's end are left out (mixed pixels, corner effects).
_END_MARGIN = 3
# Beams whose variance exceeds this multiple of the median are trimmed as outliers.
_TRIM = 6.0


@dataclass(frozen=True)
class NoiseFit:
    """
    The fitted noise model and how it was obtained.

    :ivar noise: the fitted parameters
    :ivar wall_beams: beams used (interior of straight walls, steady over the scans)
    :ivar offset_lag1: lag-1 autocorrelation of the per-scan common-mode offset
    :ivar offsets_m: the per-scan common-mode offsets, shape (T,), m
    """

    noise: NoiseParameters
    wall_beams: int
    offset_lag1: float
    offsets_m: np.ndarray


def fit_noise(scans: StaticScans, base: FeatureConfig = None) -> NoiseFit:
    """
    Fit range sigma, bearing sigma and the common-mode range offset from static scans.

    :param scans: repeated scans from a still sensor
    :param base: pipeline settings for finding the walls of the median scan (default: paper's)
    :return: the fit
    :raises ValueError: when the scans show too few wall beams to fit anything
    """
    valid = scans.valid()
    steady = valid.mean(axis=0) >= 0.95
    ranges = np.where(valid, scans.ranges, np.nan)
    with np.errstate(invalid='ignore'):
        median = np.where(steady, np.nanmedian(np.where(steady, ranges, 0.0), axis=0), np.inf)
    deviation = ranges - median
    spread = 1.4826 * np.nanmedian(np.abs(deviation[:, steady]))
    base = FeatureConfig() if base is None else base
    config = base.replace(method='wtls', range_sigma_m=float(max(spread, 1e-3)),
                          bearing_sigma_rad=0.0)
    features = extract_features(median, scans.angle_min, scans.angle_increment, config,
                                scans.range_min, scans.range_max)
    beams, slope = _wall_beams(features.segments, scans.bearings, median)
    beams_ok = steady[beams]
    beams, slope = beams[beams_ok], slope[beams_ok]
    if len(beams) < 20:
        raise ValueError(f'{scans.source or "the scans"}: only {len(beams)} beams on straight '
                         'walls: too few to fit a noise model')
    offsets = np.nanmean(deviation[:, beams], axis=1)
    offsets = offsets - offsets.mean()
    residual = deviation[:, beams] - offsets[:, None]
    variance = np.nanvar(residual, axis=0, ddof=1)
    keep = variance <= _TRIM * np.median(variance)
    design = np.column_stack([np.ones(keep.sum()), slope[keep] ** 2])
    (range_var, bearing_var), *_ = np.linalg.lstsq(design, variance[keep], rcond=None)
    if bearing_var < 0.0:                       # no bearing term: range noise alone
        range_var, bearing_var = float(np.mean(variance[keep])), 0.0
    elif range_var < 0.0:                       # no range term: bearing noise alone
        g2 = slope[keep] ** 2
        range_var, bearing_var = 0.0, float(np.sum(variance[keep] * g2) / np.sum(g2 * g2))
    common_var = max(float(np.var(offsets, ddof=1)) - range_var / len(beams), 0.0)
    lag1 = (float(np.corrcoef(offsets[:-1], offsets[1:])[0, 1])
            if len(offsets) > 2 and np.std(offsets) > 0 else math.nan)
    noise = NoiseParameters(math.sqrt(range_var), math.sqrt(bearing_var), math.sqrt(common_var))
    return NoiseFit(noise, int(len(beams)), lag1, offsets)


def _wall_beams(segments, bearings, median):
    """Return the interior beams of the segments and d rho / d theta there."""
    beams, slope = [], []
    count = len(bearings)
    for segment in segments:
        first, last = segment.first_index, segment.last_index
        span = np.arange(first, last + 1 if last >= first else last + count + 1) % count
        span = span[_END_MARGIN:len(span) - _END_MARGIN]
        span = span[np.isfinite(median[span])]
        incidence = bearings[span] - segment.angle_rad
        beams.append(span)
        slope.append(median[span] * np.tan(incidence))
    if not beams:
        return np.zeros(0, np.intp), np.zeros(0)
    return np.concatenate(beams).astype(np.intp), np.concatenate(slope)


def node_yaml(noise: NoiseParameters, effective_scale: float = 1.0) -> str:
    """
    Return the feature_node parameter lines for a fitted noise model.

    When the corners still scatter more (or less) than the fitted model predicts, the lines give
    every sigma scaled by ``effective_scale`` (chosen so that the corner NEES comes out at 2)
    and say so.

    :param noise: the fitted model
    :param effective_scale: factor on all three sigmas that absorbs what the model misses
    :return: YAML text for a params file
    """
    range_sigma = max(noise.range_sigma_m * effective_scale, 1e-4)
    bearing_deg = math.degrees(noise.bearing_sigma_rad) * effective_scale
    common = noise.common_range_sigma_m * effective_scale
    lines = ['feature_node:', '  ros__parameters:',
             f'    range_sigma_m: {range_sigma:.4f}',
             f'    bearing_sigma_deg: {bearing_deg:.4f}',
             f'    common_range_sigma_m: {common:.5f}']
    if abs(effective_scale - 1.0) > 1e-9:
        lines += [f'# fitted: {noise.describe()};',
                  f'# every sigma above is scaled by {effective_scale:.2f} so that the corner '
                  'NEES comes out at 2 on this recording.']
    return '\n'.join(lines)
