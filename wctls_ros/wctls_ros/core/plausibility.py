# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Nothing published that says "unknown": the plausibility bounds on a scan and on its features.

The numpy pipeline applies these functions to its result; the compiled one applies their
compiled twin (:mod:`.numba_core.plausibility`) within its compiled call
(docs/derivation.md#plausibility):

- a scan whose own range-noise estimate exceeds ``max_range_sigma_m`` is no scan of surfaces
  (returns scattered at random, a wall interleaved with short echoes): it gives no features;
- a segment or corner whose position standard deviation exceeds :data:`MAX_SIGMA_RATIO` times
  the decision noise of one return at its range is dropped: a covariance that large gates
  nothing.

Both are counted in the result (:class:`~.features.Features`), for the node's diagnostics.
"""

from dataclasses import replace

import numpy as np

from .config import FeatureConfig
from .features import CornerSet, Features, SegmentSet

# A feature's position std may be at most this many times the decision noise of one return at
# its range, sqrt(sigma_rho^2 + sigma_m^2 + sigma_f^2 + (r sigma_theta)^2). On the ten recordings
# of data/ and simulated rooms (generic preset) the 99th percentile of the ratio is 0.4-2.9 for
# corners and 0.4-2.3 for segments; 7.4 on the single RPLIDAR C1 scans, 16.6 for one corner of
# 115 in the Malaga recording (short walls at a shallow angle).
MAX_SIGMA_RATIO = 10.0


def return_noise_m(range_m: np.ndarray, config: FeatureConfig, range_sigma_m: float):
    """
    Return the decision noise of one return at each range, with the wall flatness, m.

    :param range_m: ranges, any shape, m
    :param config: the configuration (bearing noise, model error, wall flatness)
    :param range_sigma_m: the scan's range noise, m
    :return: the noise, the shape of ``range_m``
    """
    return np.sqrt(range_sigma_m ** 2 + config.model_error_sigma_m ** 2
                   + config.wall_flatness_sigma_m ** 2
                   + (range_m * config.bearing_sigma_rad) ** 2)


def corner_sigma_m(corners: CornerSet) -> np.ndarray:
    """
    Return each corner's position std along its worst direction, m.

    The larger eigenvalue of the (x, y) covariance [[a, b], [b, c]] in closed form,
    (a + c) / 2 + sqrt(((a - c) / 2)^2 + b^2), as the compiled twin has it.

    :param corners: the corners
    :return: the square root of the larger eigenvalue of each (x, y) covariance, shape (C,)
    """
    covariance = corners.covariance
    a, b, c = covariance[:, 0, 0], covariance[:, 0, 1], covariance[:, 1, 1]
    half_difference = 0.5 * (a - c)
    largest = 0.5 * (a + c) + np.sqrt(half_difference * half_difference + b * b)
    return np.sqrt(np.maximum(largest, 0.0))


def segment_sigma_m(segments: SegmentSet) -> np.ndarray:
    """
    Return each segment's std across its line at its middle, m.

    At the middle m of the segment, a change (d alpha, d r) of the normal form moves the line
    across by d r - l d alpha, l = m . t the lever along the line (t = (-sin alpha, cos alpha)).

    :param segments: the segments
    :return: shape (S,)
    """
    middle = 0.5 * (segments.start_xy_m + segments.end_xy_m)
    lever = (-middle[:, 0] * np.sin(segments.angle_rad)
             + middle[:, 1] * np.cos(segments.angle_rad))
    cov = segments.covariance
    variance = cov[:, 1, 1] - 2.0 * lever * cov[:, 0, 1] + lever * lever * cov[:, 0, 0]
    return np.sqrt(np.maximum(variance, 0.0))


def noise_is_plausible(range_sigma_m: float, config: FeatureConfig) -> bool:
    """
    Return whether a scan's range noise is within ``max_range_sigma_m``.

    :param range_sigma_m: the range noise the scan would be processed with, m
    :param config: the configuration
    :return: True when the scan may give features
    """
    return range_sigma_m <= config.max_range_sigma_m        # False for NaN too


def implausible_scan(method: str, range_sigma_m: float) -> Features:
    """
    Return the result of a scan whose range noise is beyond the bound: no features, flagged.

    :param method: the configured line fit
    :param range_sigma_m: the scan's range noise, m
    :return: the features
    """
    return Features(method, SegmentSet.empty(), CornerSet.empty(), range_sigma_m=range_sigma_m,
                    noise_implausible=True)


def plausible(features: Features, config: FeatureConfig, range_sigma_m: float) -> Features:
    """
    Return the features without those whose position std is beyond the bound, counted.

    :param features: a scan's features as the pipeline found them
    :param config: the configuration they were found with
    :param range_sigma_m: the range noise the scan was processed with (its own estimate when
        ``range_sigma_from_scan``), m
    :return: the features that pass, with ``range_sigma_m`` set and the drops counted
    """
    segments, corners = features.segments, features.corners
    count = len(segments)
    # The segments' middles and the corners, and their stds, in one array each.
    middle = 0.5 * (segments.start_xy_m + segments.end_xy_m)
    point = np.concatenate((middle, corners.xy_m))
    within = (np.concatenate((segment_sigma_m(segments), corner_sigma_m(corners)))
              <= MAX_SIGMA_RATIO * return_noise_m(np.hypot(point[:, 0], point[:, 1]), config,
                                                  range_sigma_m))
    found = Features(features.method, segments, corners, features.work_limited, range_sigma_m)
    if np.count_nonzero(within) == within.size:
        return found
    keep_segment = within[:count]
    keep_corner = (keep_segment[corners.first_segment] & keep_segment[corners.second_segment]
                   & within[count:])
    return kept(found, keep_segment, keep_corner)


def kept(features: Features, keep_segment: np.ndarray, keep_corner: np.ndarray) -> Features:
    """
    Return the segments and corners that pass the bound, the others counted as dropped.

    Both pipelines' last step (the compiled one's bounds are :mod:`.numba_core.plausibility`).

    :param features: the features
    :param keep_segment: which segments pass, shape (S,)
    :param keep_corner: which corners pass (those of a dropped segment do not), shape (C,)
    :return: the features that pass, ``implausible_features`` the number of the others
    """
    dropped = int(np.count_nonzero(~keep_segment) + np.count_nonzero(~keep_corner))
    if not dropped:
        return features
    # Corners name their walls by index: renumber them over the segments kept.
    renumber = np.add.accumulate(keep_segment, dtype=np.intp) - 1
    corners = features.corners.select(keep_corner)
    corners = replace(corners, first_segment=renumber[corners.first_segment],
                      second_segment=renumber[corners.second_segment])
    return replace(features, segments=features.segments.select(keep_segment), corners=corners,
                   implausible_features=dropped)
