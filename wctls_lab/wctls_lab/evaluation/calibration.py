# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Fit the sensor noise model from the ranges of a static recording, robust to a moving object.

From the ranges alone (no corners, no ground truth), on the beams that hit the interior of
straight walls (segments of the median scan, a few returns away from their ends):

- each beam's median over the scans is its reference range; a person or a door that crosses
  the beam in a minority of the scans does not move it;
- the per-scan common-mode range offset o_t is first the median over the wall beams of the
  deviation from the beam medians (one object crossing a few dozen beams does not move it);
- a return whose deviation, less o_t, exceeds ``CROSSING_Z`` times its beam's robust scatter
  (1.4826 MAD over the scans) is *crossed*: something stood between the sensor and the wall.
  It is rejected, and so are its neighbours in that scan (an object's edge returns are mixed);
- o_t is then the mean over the wall returns left (efficient, and no longer pulled by the
  object), and its variance, less the part the independent noise leaves in that mean, is
  ``common_range_sigma_m^2``;
- after removing o_t, each beam's variance over its returns left is modelled as
  ``range_sigma^2 + bearing_sigma^2 (d rho / d theta)^2``, with d rho / d theta =
  rho tan(incidence) from the beam's wall: a bearing error moves the return along the wall,
  which changes its range in proportion to the incidence. A least-squares fit (non-negative,
  with outlying beams such as mixed pixels trimmed) gives both sigmas.

The fit keeps each wall beam's measured scatter, so that any model (this one, or a parameter
file's) can be compared with what the beams show (:meth:`NoiseFit.beam_ratio`).
"""

from dataclasses import dataclass, replace
import math
from typing import List, Optional, Sequence
import warnings

import numpy as np
from wctls_ros.core import extract_features, FeatureConfig
import yaml

from .analysis import corners_per_scan
from .corner_check import (corner_nees, CornerNees, fit_flatness, is_stable, nees_of,
                           pooled_nees, track_corners, TrackedCorner)
from .rules import corners_per_scan_figure
from .samples import feature_config
from .scans import StaticScans
from ..simulation import NoiseModel

# Returns this close to a segment's end are left out (mixed pixels, corner effects).
_END_MARGIN = 3
# Crossings are sought on the walls of the median scan but their outermost return, which is
# often a mixed pixel flickering between the wall and what lies beyond (LMS1xx beam 110: the
# 1.6 m wall's first return reads 0.3 m in 39 of the 89 scans).
_CROSSING_END_MARGIN = 1
# Beams whose variance exceeds this multiple of the median are trimmed as outliers.
_TRIM = 6.0
# A return this many robust sigmas (1.4826 MAD of its beam) off its beam's median, less the
# scan's common offset, is crossed by something (Gaussian noise: once in 1.7 million returns).
CROSSING_Z = 5.0
# A beam needs this share of its scans left after the rejection to count in the fit.
_MIN_KEPT_SHARE = 0.5
_MAD_TO_SIGMA = 1.4826
# The wall-flatness sigma (D18) fitted on the stable corners is sought up to this, m.
FLATNESS_UPPER_M = 0.05
# A model is implausible when the stable corners scatter more than this many times the std
# the fitted noise predicts (something other than the sensor noise moves them)...
EXCESS_LIMIT = 2.0
# ... when its per-beam std is this far from the one the wall beams show (median over them)...
BEAM_RATIO_LIMITS = (0.5, 2.0)
# ... or when one stable corner's NEES exceeds this multiple of the median of the others'.
DOMINANCE = 3.0
# Validated on other scans, each stable corner's NEES should lie in the target; outside the
# limits the model is implausible there (the targets: 1-3 calibrated on another
# recording, 0.5-5 at the least).
VALIDATION_TARGET = (1.0, 3.0)
VALIDATION_LIMITS = (0.5, 5.0)
# A fitted model is implausible when the extractor finds fewer than this share of the corners
# per scan that it finds with the model before calibration: a model that loses the corners
# is of no use to the node, however well it explains the beams.
KEPT_CORNERS_SHARE = 0.9


@dataclass(frozen=True)
class NoiseFit:
    """
    The fitted noise model, how it was obtained, and what the beams showed.

    :ivar noise: the fitted parameters
    :ivar wall_beams: wall beams used in the fit (interior of straight walls, steady over the
        scans, not trimmed)
    :ivar offset_lag1: lag-1 autocorrelation of the per-scan common-mode offset
    :ivar offsets_m: the per-scan common-mode offsets, shape (T,), m
    :ivar crossed: returns rejected as crossed by something, shape (T, N) (only beams on the
        walls of the median scan are tested: an edge beam that flickers between two surfaces
        is no crossing)
    :ivar beam_std_m: measured range std of each wall beam used, m
    :ivar beam_slope_m: d rho / d theta of each wall beam used, m / rad
    """

    noise: NoiseModel
    wall_beams: int
    offset_lag1: float
    offsets_m: np.ndarray
    crossed: np.ndarray
    beam_std_m: np.ndarray
    beam_slope_m: np.ndarray

    @property
    def crossed_scans(self) -> int:
        """
        Return how many scans had a return rejected as crossed.

        :return: the count
        """
        return int(self.crossed.any(axis=1).sum())

    def beam_ratio(self, noise: NoiseModel) -> float:
        """
        Return the median over the wall beams of the std a model predicts over the one measured.

        The common-mode offset is left out on both sides (the measured scatter is taken after
        removing each scan's offset). 1 when the model's independent terms match the beams.

        :param noise: the model
        :return: the ratio (NaN without wall beams)
        """
        if not len(self.beam_std_m):
            return math.nan
        predicted = np.hypot(noise.range_sigma_m, noise.bearing_sigma_rad * self.beam_slope_m)
        return float(np.median(predicted / np.maximum(self.beam_std_m, 1e-9)))


def fit_noise(scans: StaticScans, base: FeatureConfig = None) -> NoiseFit:
    """
    Fit range sigma, bearing sigma and the common-mode range offset from static scans.

    :param scans: repeated scans from a still sensor (something may move through the scene)
    :param base: pipeline settings for finding the walls of the median scan (default: paper's)
    :return: the fit
    :raises ValueError: when the scans show too few wall beams to fit anything
    """
    valid = scans.valid()
    steady = valid.mean(axis=0) >= 0.95
    ranges = np.where(valid & steady[None, :], scans.ranges, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)     # beams without any return
        median = np.nanmedian(ranges, axis=0)
    median = np.where(steady, median, np.inf)
    deviation = ranges - median
    spread = _MAD_TO_SIGMA * np.nanmedian(np.abs(deviation[:, steady]))
    base = FeatureConfig() if base is None else base
    config = base.replace(method='wtls', range_sigma_m=float(max(spread, 1e-3)),
                          bearing_sigma_rad=0.0, common_range_sigma_m=0.0)
    features = extract_features(median, scans.angle_min, scans.angle_increment, config,
                                scans.range_min, scans.range_max)
    beams, slope = _wall_beams(features.segments, scans.bearings, median, _END_MARGIN)
    if len(beams) < 20:
        raise ValueError(f'{scans.source or "the scans"}: only {len(beams)} beams on straight '
                         'walls: too few to fit a noise model')
    on_walls = np.zeros(len(median), dtype=bool)
    crossing_beams, _ = _wall_beams(features.segments, scans.bearings, median,
                                    _CROSSING_END_MARGIN)
    on_walls[crossing_beams] = True
    crossed, offsets = _crossings(np.where(on_walls, deviation, np.nan), beams)
    residual = np.where(crossed, np.nan, deviation)[:, beams] - offsets[:, None]
    kept = np.isfinite(residual).sum(axis=0)
    usable = kept >= max(3, _MIN_KEPT_SHARE * len(scans))
    beams, slope, residual = beams[usable], slope[usable], residual[:, usable]
    variance = np.nanvar(residual, axis=0, ddof=1)
    keep = variance <= _TRIM * np.median(variance)
    design = np.column_stack([np.ones(keep.sum()), slope[keep] ** 2])
    (range_var, bearing_var), *_ = np.linalg.lstsq(design, variance[keep], rcond=None)
    if bearing_var < 0.0:                       # no bearing term: range noise alone
        range_var, bearing_var = float(np.mean(variance[keep])), 0.0
    elif range_var < 0.0:                       # no range term: bearing noise alone
        g2 = slope[keep] ** 2
        range_var, bearing_var = 0.0, float(np.sum(variance[keep] * g2) / np.sum(g2 * g2))
    # What the independent noise leaves in each scan's mean over its wall returns.
    per_beam = range_var + bearing_var * float(np.mean(slope[keep] ** 2))
    returns = np.maximum(np.isfinite(residual).sum(axis=1), 1)
    common_var = max(float(np.var(offsets, ddof=1)) - per_beam * float(np.mean(1.0 / returns)),
                     0.0)
    lag1 = (float(np.corrcoef(offsets[:-1], offsets[1:])[0, 1])
            if len(offsets) > 2 and np.std(offsets) > 0 else math.nan)
    noise = NoiseModel(range_sigma_m=math.sqrt(range_var),
                       bearing_sigma_rad=math.sqrt(bearing_var),
                       common_range_sigma_m=math.sqrt(common_var))
    return NoiseFit(noise, int(keep.sum()), lag1, offsets, crossed,
                    np.sqrt(variance[keep]), slope[keep])


def _crossings(deviation: np.ndarray, beams: np.ndarray):
    """
    Find the returns something crossed, and the per-scan common-mode offsets without them.

    :param deviation: range minus the beam's median, shape (T, N), m; NaN on beams not tested
    :param beams: the wall beams, whose returns define the common-mode offset
    :return: (crossed, shape (T, N); offsets, shape (T,), m, mean 0)
    """
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)     # a scan without wall returns
        first_offsets = np.nan_to_num(np.nanmedian(deviation[:, beams], axis=1))
        centred = deviation - first_offsets[:, None]
        scale = _MAD_TO_SIGMA * np.nanmedian(np.abs(centred), axis=0)
    # A beam's robust scatter is taken as at least the median over the wall beams: the MAD of
    # a beam over a few dozen scans of ranges in whole mm is coarse (LMS111, 43 scans: 3-4 mm
    # on beams of 8 mm std, which would reject returns 3 std off as crossed).
    floor = max(float(np.median(scale[beams])), 1e-4)
    with np.errstate(invalid='ignore'):
        crossed = np.abs(centred) > CROSSING_Z * np.maximum(np.nan_to_num(scale), floor)
    # The edges of a crossing object are mixed returns: reject the neighbours in the scan too.
    neighbours = np.zeros_like(crossed)
    neighbours[:, 1:] = crossed[:, :-1]
    neighbours[:, :-1] |= crossed[:, 1:]
    crossed |= neighbours
    wall = np.where(crossed[:, beams], np.nan, deviation[:, beams])
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        offsets = np.nanmean(wall, axis=1)
    offsets = np.where(np.isfinite(offsets), offsets, first_offsets)
    return crossed, offsets - offsets.mean()


def _wall_beams(segments, bearings, median, margin: int):
    """Return the beams of the segments but ``margin`` at each end, and d rho / d theta."""
    beams, slope = [], []
    count = len(bearings)
    for segment in segments:
        first, last = segment.first_index, segment.last_index
        span = np.arange(first, last + 1 if last >= first else last + count + 1) % count
        span = span[margin:len(span) - margin]
        span = span[np.isfinite(median[span])]
        incidence = bearings[span] - segment.angle_rad
        beams.append(span)
        slope.append(median[span] * np.tan(incidence))
    if not beams:
        return np.zeros(0, np.intp), np.zeros(0)
    return np.concatenate(beams).astype(np.intp), np.concatenate(slope)


def node_yaml(noise: NoiseModel, config: FeatureConfig = None, comments=()) -> str:
    """
    Return the feature_node parameter lines for a fitted noise model.

    The model-error settings it was checked under (``residual_scaling``,
    ``model_error_sigma_m``, ``wall_flatness_sigma_m``, the latter fitted by :func:`calibrate`)
    are written too: the corner NEES and corner counts hold for them only.
    ``range_sigma_from_scan`` is off: the model is fixed.

    :param noise: the fitted model
    :param config: the pipeline settings the model was checked under (default: the paper's)
    :param comments: extra comment lines to append (without the leading '# ')
    :return: YAML text for a params file
    """
    config = FeatureConfig() if config is None else config
    lines = ['feature_node:', '  ros__parameters:',
             f'    range_sigma_m: {max(noise.range_sigma_m, 1e-4):.4f}',
             f'    bearing_sigma_deg: {math.degrees(noise.bearing_sigma_rad):.4f}',
             f'    common_range_sigma_m: {noise.common_range_sigma_m:.5f}',
             '    range_sigma_from_scan: false',
             f'    residual_scaling: {str(config.residual_scaling).lower()}',
             f'    model_error_sigma_m: {config.model_error_sigma_m:.5f}',
             f'    wall_flatness_sigma_m: {config.wall_flatness_sigma_m:.5f}']
    lines += [f'# {line}' for line in comments]
    return '\n'.join(lines)


def preset_yaml(calibration: 'Calibration', source: str, count: int,
                implausible: Sequence[str] = ()) -> str:
    """
    Return a sensor preset file (as ``config/sensors/*.yaml``) with a calibrated model.

    A preset holds the sensor's noise, and the model error and wall flatness it was checked
    under (a preset sets them since they also decide which features are found).

    :param calibration: the calibration
    :param source: the recording it was fitted on, as the user named it
    :param count: how many scans of it
    :param implausible: what found the model implausible (written anyway on request)
    :return: YAML text that :meth:`wctls_ros.sensors.SensorPreset.from_file` reads
    """
    fit, config = calibration.fit, calibration.published_config
    measured = f'measured: calibrate on {source}, {count} scans'
    document = {
        'description': f'Calibrated on {source} ({count} scans of a still sensor); '
                       f'{sum(calibration.stable)} stable corner(s), pooled NEES '
                       f'{calibration.pooled(calibration.final):.2f} there ({config.method}, '
                       f'residual scaling {"on" if config.residual_scaling else "off"}, wall '
                       f'flatness {1e3 * config.wall_flatness_sigma_m:.2f} mm).'
                       + ''.join(f' IMPLAUSIBLE: {text}.' for text in implausible),
        'parameters': {
            'range_sigma_from_scan': False,
            'range_sigma_m': round(max(fit.noise.range_sigma_m, 1e-4), 5),
            'bearing_sigma_deg': round(math.degrees(fit.noise.bearing_sigma_rad), 4),
            'common_range_sigma_m': round(fit.noise.common_range_sigma_m, 5),
            'model_error_sigma_m': config.model_error_sigma_m,
            'wall_flatness_sigma_m': round(config.wall_flatness_sigma_m, 5)},
        'sources': {
            'range_sigma_from_scan': f'{measured}: a fixed model, fitted over all scans',
            'range_sigma_m': f'{measured}: {1e3 * fit.noise.range_sigma_m:.2f} mm from the '
                             f'scatter of {fit.wall_beams} wall beams',
            'bearing_sigma_deg': f'{measured}: {math.degrees(fit.noise.bearing_sigma_rad):.3f}'
                                 " deg from how the wall beams' scatter grows with incidence",
            'common_range_sigma_m': f'{measured}: {1e3 * fit.noise.common_range_sigma_m:.2f} '
                                    'mm per-scan offset common to the wall beams (lag-1 '
                                    f'correlation {fit.offset_lag1:.2f})',
            'model_error_sigma_m': 'assumed: the setting it was checked under (calibrate does '
                                   'not fit it; docs/sensors.md#model-error)',
            'wall_flatness_sigma_m': f'{measured}: the larger of what its stable corners called '
                                     f'for ({1e3 * calibration.flatness_m:.2f} mm) and the '
                                     'configured flatness, which a still recording cannot '
                                     'show'}}
    return yaml.safe_dump(document, sort_keys=False, width=95)


def noise_of(config: FeatureConfig) -> NoiseModel:
    """
    Return the noise model of a pipeline configuration.

    :param config: the configuration
    :return: its three sigmas
    """
    return NoiseModel(range_sigma_m=config.range_sigma_m,
                      bearing_sigma_rad=config.bearing_sigma_rad,
                      common_range_sigma_m=config.common_range_sigma_m)


@dataclass(frozen=True)
class Finding:
    """
    Something wrong with a model or its check, in one line.

    :ivar implausible: the model is implausible (``calibrate`` refuses it); False: a warning
    :ivar text: what was found
    """

    implausible: bool
    text: str


@dataclass(frozen=True)
class Calibration:
    """
    A noise model fitted to a static recording and checked on its stable corners.

    :ivar fit: the model fitted from the wall beams
    :ivar config: the pipeline settings it was fitted under (method, model-error terms)
    :ivar flatness_m: the wall-flatness sigma (D18) that brings the stable corners' pooled
        NEES down to 2 (that of ``config`` when they scatter no more than the model predicts,
        or without a stable corner), m
    :ivar converged: whether that NEES came within 1 % of 2 (or below 2 without a flatness)
    :ivar corners: the corners tracked across the scans
    :ivar stable: which of them are stable (only those check a model)
    :ivar before: each corner's NEES under the model before calibration
    :ivar fitted: ... under the fitted noise model, with the flatness of ``config``
    :ivar final: ... under the final model: the fitted noise and the fitted flatness
    :ivar corners_per_scan_before: corners the extractor reports per scan with the model
        before calibration
    :ivar corners_per_scan_final: ... with the final model
    :ivar findings: what makes the model implausible, and warnings
    """

    fit: NoiseFit
    config: FeatureConfig
    flatness_m: float
    converged: bool
    corners: List[TrackedCorner]
    stable: List[bool]
    before: List[CornerNees]
    fitted: List[CornerNees]
    final: List[CornerNees]
    corners_per_scan_before: float
    corners_per_scan_final: float
    findings: List[Finding]

    @property
    def noise(self) -> NoiseModel:
        """
        Return the fitted noise model.

        :return: the model
        """
        return self.fit.noise

    @property
    def final_config(self) -> FeatureConfig:
        """
        Return the pipeline settings with the final model (noise and wall flatness).

        :return: the configuration
        """
        return feature_config(self.noise, self.config.method, self.config).replace(
            wall_flatness_sigma_m=self.flatness_m)

    @property
    def published_config(self) -> FeatureConfig:
        """
        Return the settings calibrate gives the node: the final model, flatness at least as set.

        A still recording cannot show a wall's bow (only another viewpoint can), so the
        configured wall flatness stays when the corners called for less.

        :return: the configuration
        """
        return self.final_config.replace(wall_flatness_sigma_m=max(
            self.flatness_m, self.config.wall_flatness_sigma_m))

    @property
    def excess(self) -> float:
        """
        Return how many times the std the fitted noise predicts the stable corners scatter.

        :return: sqrt(pooled NEES / 2) under the fitted noise (NaN without a stable corner)
        """
        return math.sqrt(self.pooled(self.fitted) / 2.0)

    @property
    def implausible(self) -> bool:
        """
        Return whether any finding makes the model implausible.

        :return: True when calibrate refuses the model
        """
        return any(f.implausible for f in self.findings)

    def pooled(self, results: List[CornerNees]) -> float:
        """
        Return the pooled NEES of the stable corners.

        :param results: one of before, fitted, final
        :return: the mean NEES (2 when calibrated)
        """
        return pooled_nees([r for r, stable in zip(results, self.stable) if stable])


def calibrate(scans: StaticScans, config: Optional[FeatureConfig] = None,
              before: Optional[FeatureConfig] = None) -> Calibration:
    """
    Fit the noise model on the wall beams, the wall flatness on the stable corners, and check.

    The beams measure the sensor's noise; what the stable corners scatter beyond it is the
    scene's: walls straight only to a few mm (and what else moves a corner but not the beams).
    That excess is fitted as the wall-flatness sigma (D18), never by changing the sensor's
    sigmas: a model narrower than the beams' scatter, or wider on every wall because one corner
    scattered, would not hold on another scene. It is fitted with the pipeline settings the
    node will run with, by default its residual factor (D17) on: the NEES it brings to 2 is
    that of the covariances the node publishes.

    :param scans: repeated scans from a still sensor (something may move through the scene)
    :param config: the pipeline settings (method, model-error terms; default: the paper's);
        the model fitted under them estimates no range noise from each scan
    :param before: the model to compare with (default: ``config`` as it is)
    :return: the calibration
    :raises ValueError: when the scans show too few wall beams to fit anything
    """
    config = FeatureConfig() if config is None else config
    before = config if before is None else before
    # The fitted model is a fixed one: with range_sigma_from_scan the node would take the
    # larger of it and each scan's own estimate, a model nobody fitted.
    config = config.replace(range_sigma_from_scan=False)
    fit = fit_noise(scans, config)
    # A still sensor sees each wall's bow from one place only: its corners' scatter shows the
    # flatness a flickering segmentation calls for, never the bow itself. The fit starts from
    # straight walls; what the node is given keeps at least the configured flatness
    # (:attr:`Calibration.published_config`).
    model = feature_config(fit.noise, config.method, config).replace(wall_flatness_sigma_m=0.0)
    corners = track_corners(scans, model, fit.crossed)
    fitted = corner_nees(scans, model, corners)
    stable = [is_stable(c, r) for c, r in zip(corners, fitted)]
    chosen = [c for c, keep in zip(corners, stable) if keep]
    flatness, converged = 0.0, False
    if chosen:
        flatness, _, converged = fit_flatness(
            lambda sigma: pooled_nees(corner_nees(
                scans, model.replace(wall_flatness_sigma_m=sigma), chosen)),
            0.0, pooled_nees([r for r, keep in zip(fitted, stable) if keep]),
            FLATNESS_UPPER_M)
    final_per_scan = corners_per_scan(scans, model.replace(wall_flatness_sigma_m=flatness))
    before_per_scan = corners_per_scan(scans, before)
    calibration = Calibration(fit, config, flatness, converged, corners, stable,
                              nees_of(before_per_scan, corners), fitted,
                              nees_of(final_per_scan, corners),
                              corners_per_scan_figure(before_per_scan),
                              corners_per_scan_figure(final_per_scan), [])
    return replace(calibration, findings=_calibration_findings(calibration, len(scans)))


def _crossing_findings(fit: NoiseFit, count: int, what: str) -> List[Finding]:
    """Return the warning that returns were rejected as crossed, if any were."""
    if not fit.crossed.any():
        return []
    return [Finding(False, f'something crossed the walls (a moving object, or an occluding edge '
                    f'that flickers) in {fit.crossed_scans} of {count} scans: '
                    f'{int(fit.crossed.sum())} returns, with their neighbours, left out of '
                    f'{what}')]


def _calibration_findings(calibration: Calibration, count: int) -> List[Finding]:
    """Return what makes a calibration implausible, and its warnings."""
    fit = calibration.fit
    findings = _crossing_findings(fit, count, 'the fit and the corner checks')
    ratio = fit.beam_ratio(fit.noise)
    if not BEAM_RATIO_LIMITS[0] <= ratio <= BEAM_RATIO_LIMITS[1]:
        findings.append(Finding(True, f'the fitted model predicts {ratio:.2f} times the range '
                                'scatter the wall beams show (median over them; allowed '
                                f'{BEAM_RATIO_LIMITS[0]:g}-{BEAM_RATIO_LIMITS[1]:g})'))
    kept = calibration.corners_per_scan_final
    if not kept >= KEPT_CORNERS_SHARE * calibration.corners_per_scan_before:
        findings.append(Finding(True, f'with the fitted model the extractor finds {kept:.2f} '
                                'corners per scan against '
                                f'{calibration.corners_per_scan_before:.2f} with the model '
                                f'before calibration (at least {100 * KEPT_CORNERS_SHARE:.0f} % '
                                'needed): the model loses the corners'))
    stable = [r for r, keep in zip(calibration.final, calibration.stable) if keep]
    if not stable:
        findings.append(Finding(True, 'no stable corner: the model cannot be validated in the '
                                'extractor (the corners of half of the scans check it; none '
                                'was found there often enough), and no wall flatness is '
                                'fitted'))
        return findings
    if calibration.excess > EXCESS_LIMIT:
        findings.append(Finding(True, f'the stable corners scatter {calibration.excess:.2f} '
                                'times the std the fitted noise predicts (allowed up to '
                                f'{EXCESS_LIMIT:g}): something other than the sensor noise '
                                'moves them'))
    elif not calibration.converged:
        findings.append(Finding(False, 'the wall-flatness search did not bring the corner '
                                f'NEES to 2 (NEES {calibration.pooled(calibration.final):.2f} '
                                f'at {1e3 * calibration.flatness_m:.2f} mm)'))
    numbers = [k + 1 for k, keep in enumerate(calibration.stable) if keep]
    for n, result in zip(numbers, stable):
        others = [r.nees for r in stable if r is not result]
        if others and result.nees > DOMINANCE * float(np.median(others)):
            findings.append(Finding(True, f'corner {n} dominates: NEES {result.nees:.2f}, over '
                                    f'{DOMINANCE:g} times the median of the other stable '
                                    f'corners ({float(np.median(others)):.2f})'))
    return findings


@dataclass(frozen=True)
class Validation:
    """
    A model checked on a recording it was not fitted on.

    :ivar fit: the noise fit of that recording (its beams' scatter, its crossings)
    :ivar config: the model under test, with its pipeline settings
    :ivar beam_ratio: the std the model predicts over the one the wall beams show (median)
    :ivar corners: the corners tracked across its scans (with the model under test)
    :ivar stable: which of them are stable
    :ivar nees: each corner's NEES under the model
    :ivar corners_per_scan: corners the extractor reports per scan with the model
    :ivar findings: what makes the model implausible there, and warnings
    """

    fit: NoiseFit
    config: FeatureConfig
    beam_ratio: float
    corners: List[TrackedCorner]
    stable: List[bool]
    nees: List[CornerNees]
    corners_per_scan: float
    findings: List[Finding]

    @property
    def implausible(self) -> bool:
        """
        Return whether the model is implausible on this recording.

        :return: True when any finding says so
        """
        return any(f.implausible for f in self.findings)

    @property
    def pooled(self) -> float:
        """
        Return the pooled NEES of the stable corners.

        :return: the mean NEES (2 when calibrated)
        """
        return pooled_nees([r for r, stable in zip(self.nees, self.stable) if stable])


def validate(scans: StaticScans, config: FeatureConfig) -> Validation:
    """
    Check a model on a static recording: its beams' scatter and its stable corners' NEES.

    :param scans: repeated scans from a still sensor (something may move through the scene)
    :param config: the model and pipeline settings under test
    :return: the validation
    :raises ValueError: when the scans show too few wall beams to measure their scatter
    """
    fit = fit_noise(scans, config)
    corners = track_corners(scans, config, fit.crossed)
    per_scan = corners_per_scan(scans, config)
    nees = nees_of(per_scan, corners)
    stable = [is_stable(c, r) for c, r in zip(corners, nees)]
    ratio = fit.beam_ratio(noise_of(config))
    findings = _crossing_findings(fit, len(scans), 'the corner checks')
    if not BEAM_RATIO_LIMITS[0] <= ratio <= BEAM_RATIO_LIMITS[1]:
        findings.append(Finding(True, f'the model predicts {ratio:.2f} times the range scatter '
                                'the wall beams show (median over them; allowed '
                                f'{BEAM_RATIO_LIMITS[0]:g}-{BEAM_RATIO_LIMITS[1]:g})'))
    if not any(stable):
        findings.append(Finding(True, 'no stable corner to check the model on: it cannot be '
                                'validated on this recording'))
    # A still sensor sees each wall's bow from one place: the flatness prior (D18) covers what
    # only another viewpoint shows. So a covariance is too narrow when the published one
    # (flatness included) is, and too wide only when the one without the flatness is.
    without_flatness = nees
    if config.wall_flatness_sigma_m > 0.0:
        without_flatness = nees_of(corners_per_scan(
            scans, config.replace(wall_flatness_sigma_m=0.0)), corners)
    for k, (result, narrowest, keep) in enumerate(zip(nees, without_flatness, stable)):
        low, high = min(narrowest.nees, result.nees), max(narrowest.nees, result.nees)
        if not keep or (VALIDATION_TARGET[0] <= high and low <= VALIDATION_TARGET[1]):
            continue
        outside = high < VALIDATION_LIMITS[0] or low > VALIDATION_LIMITS[1]
        shown = (f'NEES {result.nees:.2f}' if narrowest is result else
                 f'NEES {result.nees:.2f} ({narrowest.nees:.2f} without the wall flatness)')
        findings.append(Finding(outside, f'corner {k + 1}: {shown}, outside '
                                + (f'{VALIDATION_LIMITS[0]:g}-{VALIDATION_LIMITS[1]:g}'
                                   if outside else
                                   f'the target {VALIDATION_TARGET[0]:g}-'
                                   f'{VALIDATION_TARGET[1]:g}')))
    return Validation(fit, config, ratio, corners, stable, nees,
                      corners_per_scan_figure(per_scan), findings)
