#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Recorded features of the test corpus: what a rule change moves, as a diff of small text files.

One file per case in ``golden/``: every real recording of data/ (its first scans) and simulated
cluttered rooms, each with the default configuration and with its sensor's preset. A file lists,
scan by scan, every segment (first and last beam, returns, angle, radius) and every corner
(its walls, x, y, yaw, the position standard deviations, whether each wall's end was seen), at
printed precision. ``test_golden_features.py`` holds both pipelines to them; after a change
that moves features on purpose, re-record with ``make golden`` and read ``git diff``.

Usage: python golden_features.py [--write]
"""

import argparse
import json
import math
import pathlib

import numpy as np
from wctls_lab.evaluation.scans import load_json_scans, load_scans
from wctls_lab.simulation import load_floor_plan, NoiseModel, simulate_recording
from wctls_ros.core import FeatureConfig
from wctls_ros.params import feature_settings, load_parameters

HERE = pathlib.Path(__file__).resolve().parent
GOLDEN = HERE / 'golden'
DATA = HERE.parents[1] / 'data'
# Scans of each case: enough to see a rule move, few enough to read a diff.
SCANS = 8
# Printed significant digits: values agree between the two pipelines to about 1e-12.
DIGITS = 9


def preset_config(sensor: str) -> FeatureConfig:
    """Return the feature configuration of a sensor preset, as the node would make it."""
    config, _, _ = feature_settings(load_parameters(None, overrides={'sensor': sensor}))
    return config


def cases():
    """Yield (name, config, ranges (T, N), angle_min, angle_increment, range_min, range_max)."""
    recordings = [
        ('sick_lms1xx_static', load_scans(DATA / 'sick_lms1xx_static', limit=SCANS),
         'sick_lms1xx'),
        ('sick_lms111_static', load_scans(DATA / 'sick_lms111_static', limit=SCANS),
         'sick_lms1xx'),
        ('urg04lx_office', load_scans(DATA / 'urg04lx_office', limit=SCANS), 'hokuyo_urg04lx'),
        ('lms111_building', load_json_scans(DATA / 'lms111_building'), 'sick_lms1xx'),
    ]
    for plan, seed in (('environment_a_cluttered', 1), ('environment_b_cluttered', 2)):
        simulated = simulate_recording(
            load_floor_plan(plan), NoiseModel(range_sigma_m=0.02,
                                              bearing_sigma_rad=math.radians(0.05)),
            SCANS, seed=seed, beams=1440)
        recordings.append((f'{plan}_s1_like', simulated, 'rplidar_s1'))
    for name, scans, sensor in recordings:
        range_min = getattr(scans, 'range_min', 0.0)
        range_max = getattr(scans, 'range_max', math.inf)
        for label, config in (('default', FeatureConfig()), (sensor, preset_config(sensor))):
            yield (f'{name}-{label}', config, np.asarray(scans.ranges)[:SCANS], scans.angle_min,
                   scans.angle_increment, range_min, range_max)


def _number(value: float) -> str:
    return f'{float(value):.{DIGITS}g}'


def describe(features) -> dict:
    """Return one scan's features as printable rows."""
    segments, corners = features.segments, features.corners
    sigma = np.sqrt(np.maximum(corners.covariance[:, [0, 1], [0, 1]], 0.0))
    return {
        'work_limited': bool(features.work_limited),
        'segments': [' '.join([str(int(first)), str(int(last)), str(int(count)),
                               _number(angle), _number(radius)])
                     for first, last, count, angle, radius in zip(
                         segments.first_index, segments.last_index, segments.num_points,
                         segments.angle_rad, segments.radius_m)],
        'corners': [' '.join([str(int(a)), str(int(b)), _number(xy[0]), _number(xy[1]),
                              _number(yaw), _number(s[0]), _number(s[1]),
                              ''.join('1' if flag else '0' for flag in seen)])
                    for a, b, xy, yaw, s, seen in zip(
                        corners.first_segment, corners.second_segment, corners.xy_m,
                        corners.yaw_rad, sigma, corners.end_seen)],
    }


def record(extract) -> dict:
    """Return case name -> its scans' described features, extracted with ``extract``."""
    recorded = {}
    for name, config, ranges, angle_min, increment, range_min, range_max in cases():
        recorded[name] = [describe(extract(scan, angle_min, increment, config, range_min,
                                           range_max)) for scan in ranges]
    return recorded


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--write', action='store_true', help='re-record golden/*.json')
    args = parser.parse_args()
    from wctls_ros.core import numpy_core
    recorded = record(numpy_core.extract_features)
    GOLDEN.mkdir(exist_ok=True)
    for name, scans in recorded.items():
        text = json.dumps(scans, indent=1) + '\n'
        path = GOLDEN / f'{name}.json'
        if args.write:
            path.write_text(text)
        print(f'{path.name}: {sum(len(s["corners"]) for s in scans)} corners in {len(scans)} scans'
              + ('' if args.write or not path.exists() or path.read_text() == text
                 else ' (differs from the recorded file)'))


if __name__ == '__main__':
    main()
