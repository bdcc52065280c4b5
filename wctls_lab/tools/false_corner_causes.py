#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
"""
Count why the false corners of simulated recordings are false (docs/results/score.md).

Run inside the built workspace (``source tools/env.sh``)::

    tools/false_corner_causes.py                  # the bundled A and B, clean and cluttered
    tools/false_corner_causes.py --method ml --scans 50

Simulates each bundled plan as tools/make_score_results.sh does (100 scans, seed 1; "1cm" with
the S1-like 0.4 deg footprint, and s1_like), extracts corners with the sensor's own noise model,
matches them to the truth as ``score`` does, and sorts every unmatched corner into the first
cause that fits:

1. veil: one of its two segments has most of its returns off every surface (mixed pixels);
2. clutter: it lies within 15 cm of a clutter cylinder, a clutter box or a walker's leg;
3. displaced true corner: a true corner lies within 15 cm (outside the match gate);
4. virtual intersection: it lies more than 5 cm beyond the end of one of its segments (two
   lines extrapolated across an occlusion gap);
5. on a wall: anything else (a split wall, a T-junction).
"""

import argparse
import collections
import dataclasses
from importlib import resources
import math
import sys

import numpy as np
from wctls_lab.evaluation import match_detections, truth_from_recording
from wctls_lab.simulation import (load_floor_plan, NOISELESS, SENSOR_MODELS, simulate_recording,
                                  simulate_scan)
from wctls_ros.core import extract_features, FeatureConfig
import yaml

SENSORS = {
    '1cm': (dataclasses.replace(SENSOR_MODELS['1cm'], beam_divergence_rad=math.radians(0.4)),
            {'range_sigma_m': 0.01, 'bearing_sigma_rad': math.radians(0.05)}),
    's1_like': (SENSOR_MODELS['s1_like'],
                {'range_sigma_m': 0.02, 'bearing_sigma_rad': math.radians(0.108),
                 'common_range_sigma_m': 0.001}),
}
PLANS = ('environment_a', 'environment_a_cluttered', 'environment_b',
         'environment_b_cluttered')


def clutter_box_centres(name: str) -> np.ndarray:
    """Return the centres of a bundled plan's clutter boxes, (B, 2), plan coordinates."""
    spec = yaml.safe_load(resources.files('wctls_lab.simulation').joinpath(
        f'plans/{name}.yaml').read_text())
    return np.array([c['box'] for c in spec.get('clutter', []) if 'box' in c]).reshape(-1, 2)


def segment_beams(segment, beams: int) -> np.ndarray:
    """Return the beam indices of a segment (it may wrap around the scan's seam)."""
    if segment.last_index >= segment.first_index:
        return np.arange(segment.first_index, segment.last_index + 1)
    return np.r_[np.arange(segment.first_index, beams), np.arange(0, segment.last_index + 1)]


def cause(corner_xy, segments, ranges, ideal, config, truth_xy, circles, boxes) -> str:
    """Return why one unmatched corner is false (the first cause that fits)."""
    for segment in segments:
        beams = segment_beams(segment, len(ranges))
        seen = np.isfinite(ranges[beams])
        off = np.abs(ranges[beams][seen] - ideal[beams][seen]) > 5 * config.range_sigma_m + 0.01
        if seen.any() and off.mean() > 0.3:
            return 'veil: a segment of mixed pixels'
    near_clutter = min([np.inf] + list(np.hypot(*(circles[:, :2] - corner_xy).T) - circles[:, 2])
                       + list(np.hypot(*(boxes - corner_xy).T)))
    if near_clutter < 0.15:
        return 'on clutter or a walker'
    if len(truth_xy) and np.nanmin(np.hypot(*(truth_xy - corner_xy).T)) < 0.15:
        return 'a true corner, displaced beyond the gate'
    beyond = max(min(np.hypot(*(corner_xy - s.start_xy_m)), np.hypot(*(corner_xy - s.end_xy_m)))
                 for s in segments)
    if beyond > 0.05:
        return 'virtual intersection across a gap'
    return 'on a wall, away from corners'


def main(argv=None) -> int:
    """Print the causes of the false corners per plan and sensor."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    p.add_argument('--method', default='wtls', help='line fit (default: %(default)s)')
    p.add_argument('--scans', type=int, default=100, help='scans per recording')
    args = p.parse_args(argv)
    for name in PLANS:
        plan = load_floor_plan(name)
        boxes = clutter_box_centres(name)
        boxes = plan.to_sensor_frame(boxes) if len(boxes) else boxes
        for sensor, (noise, model) in SENSORS.items():
            config = FeatureConfig(method=args.method, **model)
            recording = simulate_recording(plan, noise, args.scans, seed=1)
            truth = truth_from_recording(recording)
            bearings = recording.angle_min + recording.angle_increment * np.arange(
                recording.ranges.shape[1])
            counts, total = collections.Counter(), 0
            for t, ranges in enumerate(recording.ranges):
                features = extract_features(ranges, recording.angle_min,
                                            recording.angle_increment, config, 0.05, 40.0)
                corners = features.corners
                truth_xy, _ = truth.at(t)
                match = match_detections(corners.xy_m, corners.covariance[:, :2, :2], truth_xy)
                total += len(match)
                if np.all(match >= 0):
                    continue
                scene = plan.scene(None, 0.1 * t)
                ideal = simulate_scan(scene, bearings, NOISELESS, np.random.default_rng(0))
                for i in np.flatnonzero(match < 0):
                    segments = [features.segments[corners.first_segment[i]],
                                features.segments[corners.second_segment[i]]]
                    counts[cause(corners.xy_m[i], segments, ranges, ideal, config, truth_xy,
                                 scene.circles_m, boxes)] += 1
            print(f'{name}, {sensor}: {total} corners, {sum(counts.values())} false'
                  + ''.join(f'; {reason}: {n}' for reason, n in counts.most_common()),
                  flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
