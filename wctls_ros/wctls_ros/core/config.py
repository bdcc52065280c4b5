# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The validated configuration of the feature pipeline.

Each field of :class:`FeatureConfig` carries its meaning and its allowed interval as field
metadata (:func:`field_limits`, :func:`field_description`): the validation here, the ROS
parameters of feature_node, the parameter-file checks of the offline tools and the documented
parameter table are all derived from it (see :mod:`wctls_ros.params`), so each limit is stated
once.
"""

from dataclasses import asdict, dataclass, field, fields
import math
from typing import NamedTuple, Optional

METHODS = ('utls', 'wtls', 'wctls', 'ml')


class Limits(NamedTuple):
    """
    The interval a numeric setting must lie in.

    :ivar low: lower end
    :ivar high: upper end
    :ivar low_open: the lower end itself is not allowed
    :ivar high_open: the upper end itself is not allowed
    """

    low: float
    high: float
    low_open: bool = False
    high_open: bool = False

    def holds(self, value) -> bool:
        """
        Return whether a number lies in the interval.

        :param value: the number
        :return: True when allowed
        """
        above = value > self.low or (not self.low_open and value == self.low)
        below = value < self.high or (not self.high_open and value == self.high)
        return above and below

    def describe(self, scale: float = 1.0) -> str:
        """
        Return the interval in the usual notation, e.g. '(0, 10]'.

        :param scale: factor applied to both ends (a unit conversion)
        :return: the text
        """
        return (f'{"(" if self.low_open else "["}{self.low * scale:g}, {self.high * scale:g}'
                f'{")" if self.high_open else "]"}')


def _setting(default, description: str, limits: Optional[Limits] = None):
    """Declare a FeatureConfig field with its description and (for numbers) its limits."""
    return field(default=default, metadata={'description': description, 'limits': limits})


@dataclass(frozen=True)
class FeatureConfig:
    """
    Every knob of :func:`~wctls_ros.core.extract_features`, validated on construction.

    Defaults follow the paper: WCTLS, the RPLIDAR S1 datasheet figures (5 cm range accuracy,
    0.391 deg angular resolution) as noise, and a 40 mm IEPF threshold. feature_node and the
    tools take their noise model from a sensor preset instead (:mod:`wctls_ros.sensors`), whose
    default is measured to suit every recording we have. Each field's meaning,
    unit and allowed interval are in its metadata (:func:`field_description`,
    :func:`field_limits`).
    """

    method: str = _setting(
        'wctls', 'line fit whose covariance is propagated: ' + ' | '.join(METHODS))
    range_sigma_m: float = _setting(
        0.05, 'std of the range noise of one return, m',
        Limits(0.0, 10.0, low_open=True))
    bearing_sigma_rad: float = _setting(
        math.radians(0.391), 'std of the bearing noise of one return, {unit}',
        Limits(0.0, math.radians(10.0)))
    range_sigma_from_scan: bool = _setting(
        False, 'estimate the range noise of each scan from the scan itself (the second '
        'differences of neighbouring ranges); range_sigma_m is then its floor')
    max_range_sigma_m: float = _setting(
        0.1, 'a scan whose own range-noise estimate exceeds this is no scan of surfaces (returns '
        'scattered at random, a wall interleaved with short echoes): it gives no features and '
        'is counted; no 2D LiDAR we know of scatters 10 cm per return, m',
        Limits(0.0, 100.0, low_open=True))
    common_range_sigma_m: float = _setting(
        0.0, 'std of a range offset shared by every return of one scan, m (some sensors drift '
        'as a whole, e.g. the SICK LMS111 by about 1 mm; calibrate measures it)',
        Limits(0.0, 1.0))
    max_beams: int = _setting(
        100000, 'refuse scans with more beams than this (a ScanError: the node drops the scan '
        'with a warning); the time per scan grows linearly, about 0.5-1 ms per 10 000 beams '
        'with the compiled pipeline on a 2-core VM, about five times that with numpy '
        '(bench_core.py)',
        Limits(1, 10 ** 7))
    range_min_m: float = _setting(
        0.0, 'ignore returns closer than this (besides the scan range_min), m',
        Limits(0.0, math.inf, high_open=True))
    range_max_m: float = _setting(
        math.inf, 'ignore returns farther than this (besides the scan range_max), m',
        Limits(0.0, math.inf, low_open=True))
    breakpoint_lambda_rad: float = _setting(
        math.radians(10.0), 'adaptive breakpoint rule (Borges and Aldon): worst incidence '
        'angle of one surface, {unit}; a neighbour farther than r sin(dphi) / sin(lambda - dphi) '
        '+ 3 sigma starts a new chain', Limits(0.0, math.pi / 2, low_open=True, high_open=True))
    iepf_threshold_m: float = _setting(
        0.04, 'Iterative End Point Fit split distance, m (paper: 0.04)',
        Limits(0.0, 10.0, low_open=True))
    iepf_noise_sigmas: float = _setting(
        4.0, "the IEPF split distance is at least this many sigma of a return's position "
        'noise (under 4 sigma, the noise of a straight wall splits it in many scans); 0 keeps '
        'iepf_threshold_m alone', Limits(0.0, 100.0))
    merge_chi2: float = _setting(
        13.8, 'merge neighbouring segments below this chi2 (2 dof) of their line difference '
        '(13.8: 99.9 % for the same line); 0 disables merging', Limits(0.0, 1e6))
    merge_max_missing_beams: int = _setting(
        3, 'more invalid beams than this between two returns separate them, and merging never '
        'crosses such a gap (nor a range jump beyond what noise explains): collinear surfaces '
        'across a dark or open gap are not one wall', Limits(0, 100000))
    end_offset_sigmas: float = _setting(
        4.0, 'cut the last k returns of a segment end when their residuals from the line of '
        "the segment's other returns, each in sigmas of its noise, sum to more than this many "
        'standard deviations of their sum (another surface met at a shallow angle, an object '
        "before the wall's end); the same threshold tells a wall seen behind an edge from a "
        'corner; 0 disables both', Limits(0.0, 1e3))
    residual_scaling: bool = _setting(
        True, "scale each line's covariance by its residual chi2 per degree of freedom when "
        'above 1 (an a-posteriori variance factor: a wall rougher, or returns noisier, than '
        'the noise model are reported less precise)')
    model_error_sigma_m: float = _setting(
        0.0, 'how far a return may stray from the ideal model beyond its measurement noise '
        '(a bowed or rough wall, a rounded corner, a mixed return at an edge), m: every '
        'decision (breakpoints, splitting, merging, the end trims, the corner tests) tolerates '
        'it in quadrature with the range noise; the fits and their covariances do not use it '
        '(wall_flatness_sigma_m carries the model error into the covariances)',
        Limits(0.0, 1.0))
    wall_flatness_sigma_m: float = _setting(
        0.0, 'each end of a wall may lie this far off its fitted line (walls straight only to '
        "a few mm): added to every line's covariance, it does not shrink with the number of "
        'returns; 0: walls are straight, m', Limits(0.0, 1.0))
    min_segment_points: int = _setting(
        8, 'drop segments with fewer returns', Limits(3, 100000))
    min_segment_length_m: float = _setting(
        0.15, 'drop segments shorter than this, m', Limits(0.0, 100.0))
    min_corner_angle_rad: float = _setting(
        math.radians(30.0), 'no corner between walls closer to parallel than this, {unit}',
        Limits(0.0, math.pi / 2, low_open=True))
    min_wall_beam_angle_rad: float = _setting(
        math.radians(5.0), 'a segment within this angle of the beam to its middle is not a '
        'wall (mixed pixels strung along the beams at an edge, grazing veils), {unit}',
        Limits(0.0, math.pi / 2, high_open=True))
    corner_end_sigmas: float = _setting(
        3.0, 'a corner needs both walls to end at it: its bearing between their facing ends, '
        'and every return between them on one of the two lines, within this many standard '
        'deviations (plus corner_end_floor_m); a nearer return there is an occluder, a farther '
        'one a gap where the walls do not meet; nor may the other wall be seen behind one '
        "wall's line between its end and the corner (end_offset_sigmas)",
        Limits(0.0, 100.0, low_open=True))
    corner_end_floor_m: float = _setting(
        0.01, 'the smallest tolerance of the corner end test, m', Limits(0.0, 1.0))
    max_landmark_angle_sigma_rad: float = _setting(
        math.radians(3.0), 'a segment is a line landmark (flagged landmark on lines, '
        "re-observed by score) when its normal angle's std from its own covariance is at most "
        'this; every segment is published and forms corners all the same (3 deg: lines of '
        'moving robots inside their 95 % gate in 94-95 % of re-observations, '
        'docs/results/score.md); 180 makes every segment a landmark, {unit}',
        Limits(0.0, math.pi, low_open=True))

    def __post_init__(self):
        problems = list(validation_errors(self))
        if problems:
            raise ValueError('invalid FeatureConfig: ' + '; '.join(problems))

    def replace(self, **changes) -> 'FeatureConfig':
        """
        Return a copy with some fields changed (validated again).

        :param changes: field names and their new values
        :return: the new configuration
        :raises ValueError: if the result is invalid or a name is unknown
        """
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise ValueError(f'unknown FeatureConfig fields: {sorted(unknown)}')
        return FeatureConfig(**{**asdict(self), **changes})


def field_description(name: str, angle_unit: str = 'rad') -> str:
    """
    Return the meaning and unit of a FeatureConfig field.

    :param name: the field name
    :param angle_unit: the unit to name for an angle ('rad', as the field holds it, or 'deg'
        for a parameter that states it in degrees)
    :return: the description
    """
    return _FIELDS[name].metadata['description'].replace('{unit}', angle_unit)


def field_limits(name: str) -> Optional[Limits]:
    """
    Return the interval a numeric FeatureConfig field must lie in (None for the method).

    :param name: the field name
    :return: the limits
    """
    return _FIELDS[name].metadata['limits']


_FIELDS = {f.name: f for f in fields(FeatureConfig)}


def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def validation_errors(config: FeatureConfig):
    """
    Yield one readable sentence per violated rule of a configuration.

    :param config: the configuration to check
    :return: iterator of messages (empty when valid)
    """
    if config.method not in METHODS:
        yield f'method must be one of {METHODS}, got {config.method!r}'
    for name, setting in _FIELDS.items():
        limits, value = setting.metadata['limits'], getattr(config, name)
        if limits is None:
            continue
        if isinstance(setting.default, int) and (not isinstance(value, int)
                                                 or isinstance(value, bool)):
            yield f'{name} must be an integer, got {value!r}'
        elif not _is_number(value) or math.isnan(value):
            yield f'{name} must be a number, got {value!r}'
        elif not limits.holds(value):
            yield f'{name} must be in {limits.describe()}, got {value:g}'
    if (_is_number(config.range_sigma_m) and _is_number(config.max_range_sigma_m)
            and config.range_sigma_m > config.max_range_sigma_m):
        yield (f'range_sigma_m ({config.range_sigma_m:g}) must not exceed max_range_sigma_m '
               f'({config.max_range_sigma_m:g}): every scan would be dropped')
    if (_is_number(config.range_min_m) and _is_number(config.range_max_m)
            and not config.range_min_m < config.range_max_m):
        yield (f'range_min_m ({config.range_min_m:g}) must be below range_max_m '
               f'({config.range_max_m:g})')
