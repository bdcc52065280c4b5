# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The validated configuration of the feature pipeline."""

from dataclasses import asdict, dataclass, fields
import math

METHODS = ('utls', 'wtls', 'wctls', 'ml')


@dataclass(frozen=True)
class FeatureConfig:
    """
    Every knob of :func:`~wctls_ros.core.extract_features`, validated on construction.

    Defaults follow the paper: WCTLS, the RPLIDAR S1 datasheet figures (5 cm range accuracy,
    0.391 deg angular resolution) as noise, and a 40 mm IEPF threshold.

    :ivar method: line fit whose covariance is propagated: 'utls', 'wtls', 'wctls' or 'ml'
    :ivar range_sigma_m: std of the range noise, m (> 0)
    :ivar bearing_sigma_rad: std of the bearing noise, rad (>= 0)
    :ivar common_range_sigma_m: std of a range offset shared by every return of one scan, m
        (>= 0; some sensors drift as a whole, e.g. the SICK LMS111 by about 1 mm)
    :ivar range_min_m: drop returns closer than this (on top of the scan's own range_min), m
    :ivar range_max_m: drop returns farther than this (on top of the scan's range_max), m
    :ivar breakpoint_lambda_rad: the adaptive breakpoint rule's worst incidence angle lambda: a
        neighbour farther than r sin(dphi) / sin(lambda - dphi) + 3 sigma (sigma of a return's
        position from both noise terms) starts a new chain
    :ivar iepf_threshold_m: split a chain where a point lies farther than this from the chord
    :ivar merge_chi2: merge adjacent segments whose line difference has a Mahalanobis distance
        (squared, 2 dof) below this; 0 disables merging (13.8 = 99.9 % for the same line)
    :ivar end_offset_sigmas: cut the returns at a segment's end that lie off its line together
        (another surface met at a shallow angle, within the IEPF threshold of the chord): the
        last k returns go when their residuals, each in sigmas of its noise, sum to more than
        this times sqrt(k); 0 disables
    :ivar min_segment_points: drop segments with fewer valid returns
    :ivar min_segment_length_m: drop segments shorter than this, m
    :ivar min_corner_angle_rad: no corner between lines closer to parallel than this, rad
    :ivar max_corner_gap_m: no corner when the intersection lies farther than this from either
        segment's facing end point (a virtual intersection across an occlusion), m
    """

    method: str = 'wctls'
    range_sigma_m: float = 0.05
    bearing_sigma_rad: float = math.radians(0.391)
    common_range_sigma_m: float = 0.0
    range_min_m: float = 0.0
    range_max_m: float = math.inf
    breakpoint_lambda_rad: float = math.radians(10.0)
    iepf_threshold_m: float = 0.04
    merge_chi2: float = 13.8
    end_offset_sigmas: float = 4.0
    min_segment_points: int = 8
    min_segment_length_m: float = 0.15
    min_corner_angle_rad: float = math.radians(30.0)
    max_corner_gap_m: float = 0.3

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
    ranges = {  # field: (low, high, low inclusive, high inclusive)
        'range_sigma_m': (0.0, 10.0, False, True),
        'bearing_sigma_rad': (0.0, 0.2, True, True),
        'common_range_sigma_m': (0.0, 1.0, True, True),
        'range_min_m': (0.0, math.inf, True, False),
        'range_max_m': (0.0, math.inf, False, True),
        'breakpoint_lambda_rad': (0.0, math.pi / 2, False, False),
        'iepf_threshold_m': (0.0, 10.0, False, True),
        'merge_chi2': (0.0, 1e6, True, True),
        'end_offset_sigmas': (0.0, 1e3, True, True),
        'min_segment_length_m': (0.0, 100.0, True, True),
        'min_corner_angle_rad': (0.0, math.pi / 2, False, True),
        'max_corner_gap_m': (0.0, 100.0, False, True),
    }
    for name, (low, high, low_ok, high_ok) in ranges.items():
        value = getattr(config, name)
        if not _is_number(value) or math.isnan(value):
            yield f'{name} must be a number, got {value!r}'
            continue
        above = value > low or (low_ok and value == low)
        below = value < high or (high_ok and value == high)
        if not (above and below):
            yield (f'{name} must be in {"[" if low_ok else "("}{low:g}, {high:g}'
                   f'{"]" if high_ok else ")"}, got {value:g}')
    points = config.min_segment_points
    if not isinstance(points, int) or isinstance(points, bool) or not 3 <= points <= 100000:
        yield f'min_segment_points must be an integer in [3, 100000], got {points!r}'
    if (_is_number(config.range_min_m) and _is_number(config.range_max_m)
            and not config.range_min_m < config.range_max_m):
        yield (f'range_min_m ({config.range_min_m:g}) must be below range_max_m '
               f'({config.range_max_m:g})')
