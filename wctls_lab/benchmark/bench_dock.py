#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Measure the dock detector (wctls_ros.frontend.dock): accuracy, NEES, detection, false docks, time.

1. Simulated S1-like scans (1080 beams, 2 cm range noise, 1/3 deg bins, mixed pixels, dropouts)
   of environment A lived in (clutter, a walking person, rough walls) with the example dock (a
   V of two 0.30 m faces, 120 deg) against its east wall, seen from 0.3 to 3 m along lines at
   -60 to +60 deg from the dock's axis (the dock ahead of the sensor; at 1 m straight on also
   at -60 and +60 deg in its scan): per distance and angle the median position and yaw error
   of the reported docks against the truth, their mean NEES (3 dof), and the share of the scans
   with the dock fully in view (every face unoccluded and 12 beams wide or more) that report
   it: all of them, and those after the tracker's first report (its confirmation scans left
   out). A line from which the dock cannot be fully in view (a face edge-on) is skipped.
2. False docks: simulated rooms whose corners have the dock's angle (a hexagonal room, 120 deg
   inside corners of 1.5 m walls; a V of 120 deg with 0.6 and 0.3 m faces), the four bundled
   floor plans without a dock (pilasters, niches, chamfers, columns, clutter; five poses each)
   and every shipped real recording of data/ (none holds a dock): candidates (single scans
   that match) and reported docks (confirmed by the tracker).
3. Time per scan of find_docks + track_dock beside the extraction (the compiled core): wall
   time (median, p99) and CPU time.

Usage: python bench_dock.py [--scans N]
"""

import argparse
import math
import pathlib
import statistics
import time

import numpy as np
from wctls_lab.evaluation.scans import load_json_scans, load_scans
from wctls_lab.simulation import (BUNDLED_PLANS, floor_plan_from_dict, full_turn_bearings,
                                  load_floor_plan, ray_hits, Scene, SENSOR_MODELS,
                                  simulate_scan)
from wctls_ros.core import extract_features, start
from wctls_ros.frontend.dock import (DockShape, find_docks, track_dock, TrackerState,
                                     TrackSettings, wrap_angle)
from wctls_ros.params import defaults, FEATURE_NODE, feature_settings

DATA = pathlib.Path(__file__).resolve().parents[2] / 'data'
SHAPE = DockShape()
APEX = np.array([4.45, 1.6])          # the dock's apex in environment A, its axis along +x
DISTANCES_M = (0.3, 0.5, 1.0, 2.0, 3.0)
VIEWS_DEG = (-60, -30, 0, 30, 60)
# (distance, view) -> the dock's bearings in the scan, deg; 0 elsewhere.
BEARINGS_DEG = {(1.0, 0): (-60, 0, 60)}
SCAN_PERIOD_S = 0.1


def dock_polygon(apex, shape):
    """Return the dock's outline (right tip, apex, left tip, back corners) in plan frame."""
    half = shape.opening_angle_rad / 2.0
    right = apex + shape.right_face_m * np.array([-math.cos(half), -math.sin(half)])
    left = apex + shape.left_face_m * np.array([-math.cos(half), math.sin(half)])
    back = 4.5
    return [right.tolist(), apex.tolist(), left.tolist(), [back, left[1]], [back, right[1]]]


def dock_plan():
    """Return environment A lived in, with the dock against its east wall."""
    return floor_plan_from_dict({
        'name': 'environment_a_dock', 'base': 'environment_a_cluttered',
        'polylines': [{'closed': True, 'points': dock_polygon(APEX, SHAPE)}]})


def fully_in_view(scene, faces, increment):
    """Tell whether both faces are unoccluded and each spans 12 beams or more."""
    for a, b in faces:
        points = a + np.linspace(0.05, 0.95, 15)[:, None] * (b - a)
        bearings = np.arctan2(points[:, 1], points[:, 0])
        hits = ray_hits(scene.walls_m, scene.circles_m, np.zeros(2), bearings)
        if np.any(np.abs(hits.range_m - np.hypot(*points.T)) > 1e-3):
            return False
        span = abs(float(wrap_angle(math.atan2(b[1], b[0]) - math.atan2(a[1], a[0]))))
        if span / increment < 12:
            return False
    return True


def nees3(pose, truth):
    """Return the NEES of a dock pose against the true (x, y, yaw)."""
    error = pose.vector - truth
    error[2] = wrap_angle(error[2])
    return float(error @ np.linalg.solve(pose.covariance, error))


def run_scans(plan, pose, count, config, rng, walk_time_s=0.0):
    """Yield (scene, features, elapsed extraction s) for ``count`` scans from one pose."""
    angle_min, increment, bearings = full_turn_bearings()
    for t in range(count):
        scene = plan.scene(pose, walk_time_s + SCAN_PERIOD_S * t)
        ranges = simulate_scan(scene, bearings, SENSOR_MODELS['s1_like'], rng)
        started = time.perf_counter()
        features = extract_features(ranges, angle_min, increment, config)
        yield scene, features, time.perf_counter() - started


def accuracy(config, count):
    """Print the sweep of part 1."""
    plan = dock_plan()
    half = SHAPE.opening_angle_rad / 2.0
    tips = (APEX + SHAPE.right_face_m * np.array([-math.cos(half), -math.sin(half)]),
            APEX + SHAPE.left_face_m * np.array([-math.cos(half), math.sin(half)]))
    _, increment, _ = full_turn_bearings()
    rng = np.random.default_rng(46)
    print('distance m | view deg | bearings deg | in view | detected % | once confirmed % | '
          'median error mm | median yaw error deg | mean NEES (3 dof)')
    for distance in DISTANCES_M:
        for view in VIEWS_DEG:
            in_view = detected = in_view_after = detected_after = 0
            errors, yaw_errors, nees = [], [], []
            bearings = BEARINGS_DEG.get((distance, view), (0,))
            for bearing in bearings:
                direction = math.radians(view)
                sensor_xy = APEX - distance * np.array([math.cos(direction),
                                                        math.sin(direction)])
                yaw = direction - math.radians(bearing)
                pose = (sensor_xy[0], sensor_xy[1], yaw)
                apex = plan.to_sensor_frame(APEX[None], pose)[0]
                truth = np.array([apex[0], apex[1], float(wrap_angle(-yaw))])
                faces = [(plan.to_sensor_frame(tip[None], pose)[0], apex) for tip in tips]
                if not fully_in_view(Scene.of_walls(plan.scene(pose).walls_m), faces,
                                     increment):
                    continue
                state, confirmed = TrackerState(), False
                for t, (scene, features, _) in enumerate(
                        run_scans(plan, pose, count, config, rng, walk_time_s=rng.uniform(0, 3))):
                    state, report = track_dock(
                        state, find_docks(features.segments, features.corners, SHAPE),
                        SCAN_PERIOD_S * t, TrackSettings())
                    # The scans after the tracker's first report: the steady rate.
                    after, confirmed = confirmed, confirmed or report is not None
                    if not fully_in_view(scene, faces, increment):
                        continue
                    in_view += 1
                    in_view_after += after
                    if report is None:
                        continue
                    detected += 1
                    detected_after += after
                    errors.append(1e3 * math.hypot(*(report.vector[:2] - truth[:2])))
                    yaw_errors.append(abs(math.degrees(wrap_angle(report.yaw_rad - truth[2]))))
                    nees.append(nees3(report, truth))
            rate = 100.0 * detected / in_view if in_view else math.nan
            steady = 100.0 * detected_after / in_view_after if in_view_after else math.nan
            if not in_view:
                continue
            print(f'{distance:10.1f} | {view:8d} | {",".join(map(str, bearings)):>12} | '
                  f'{in_view:7d} | {rate:10.1f} | {steady:16.1f} | {_median(errors):15.1f} | '
                  f'{_median(yaw_errors):20.2f} | {_mean(nees):6.2f}', flush=True)


def _median(values):
    return statistics.median(values) if values else math.nan


def _mean(values):
    return statistics.fmean(values) if values else math.nan


def look_alikes(config, count):
    """Print part 2 for the simulated rooms."""
    side = 1.5
    hexagon = [[2.0 + side * math.cos(k * math.pi / 3), 1.5 + side * math.sin(k * math.pi / 3)]
               for k in range(6)]
    wrong_faces = DockShape(right_face_m=0.6, left_face_m=0.3)
    v_apex = np.array([4.45, 1.25])
    rooms = {
        'hexagonal room, 120 deg corners, 1.5 m walls': (
            {'name': 'hexagon', 'polylines': [{'closed': True, 'points': hexagon}]},
            [(2.0, 1.5, 0.0), (2.6, 1.0, 1.0), (1.2, 2.0, -2.0)]),
        'environment A with a 120 deg V of 0.6 and 0.3 m faces': (
            {'name': 'wrong_v', 'base': 'environment_a_cluttered',
             'polylines': [{'closed': True, 'points': dock_polygon(v_apex, wrong_faces)}]},
            [(3.45, 1.25, 0.0), (2.5, 1.0, 0.3), (4.0, 0.8, 2.0)]),
    }
    for name in BUNDLED_PLANS:
        x, y, _ = load_floor_plan(name).sensor_pose
        offsets = ((0.0, 0.0, 0.0), (0.8, 0.3, 1.0), (-0.8, -0.3, 2.0), (1.5, 0.2, -1.0),
                   (-1.2, 0.4, 3.0))
        rooms[f'{name} (no dock)'] = ({'name': name, 'base': name},
                                      [(x + dx, y + dy, yaw) for dx, dy, yaw in offsets])
    rng = np.random.default_rng(7)
    for name, (spec, poses) in rooms.items():
        plan = floor_plan_from_dict(spec)
        candidates = reports = scans = 0
        for pose in poses:
            state = TrackerState()
            for t, (_, features, _) in enumerate(run_scans(plan, pose, count, config, rng)):
                found = find_docks(features.segments, features.corners, SHAPE)
                state, report = track_dock(state, found, SCAN_PERIOD_S * t, TrackSettings())
                candidates += len(found)
                reports += report is not None
                scans += 1
        print(f'{name}: {scans} scans, {candidates} candidates, {reports} docks reported',
              flush=True)


def real_recordings(config_for):
    """Print part 2 for the shipped recordings."""
    paths = sorted(DATA.glob('*/*.mcap')) + sorted((DATA / 'lms111_building').glob('*.json'))
    total_scans = total_candidates = total_reports = 0
    for path in paths:
        scans = load_json_scans(path) if path.suffix == '.json' else load_scans(path)
        config = config_for(path)
        state = TrackerState()
        candidates = reports = 0
        for k, ranges in enumerate(scans.ranges):
            features = extract_features(ranges, scans.angle_min, scans.angle_increment, config)
            found = find_docks(features.segments, features.corners, SHAPE)
            stamp_s = (scans.stamps_ns[k] - scans.stamps_ns[0]) * 1e-9 if len(
                scans.stamps_ns) else 0.0
            state, report = track_dock(state, found, float(stamp_s), TrackSettings())
            candidates += len(found)
            reports += report is not None
        total_scans += len(scans.ranges)
        total_candidates += candidates
        total_reports += reports
        print(f'{path.parent.name}/{path.name}: {len(scans.ranges)} scans, {candidates} '
              f'candidates, {reports} docks reported')
    print(f'all recordings: {total_scans} scans, {total_candidates} candidates, '
          f'{total_reports} docks reported')


def timing(config, count):
    """
    Print part 3: the detector's time beside the extraction's, per scan.

    Wall time per scan (median, p99), and CPU time (``time.process_time``) over five passes of
    the same scans, which a loaded machine's preemption does not inflate.
    """
    plan = dock_plan()
    pose = (APEX[0] - 1.0, APEX[1], 0.0)
    rng = np.random.default_rng(3)
    extraction, detection, features_of = [], [], []
    state = TrackerState()
    for t, (_, features, elapsed) in enumerate(run_scans(plan, pose, count, config, rng)):
        started = time.perf_counter()
        found = find_docks(features.segments, features.corners, SHAPE)
        state, _ = track_dock(state, found, SCAN_PERIOD_S * t, TrackSettings())
        detection.append(time.perf_counter() - started)
        extraction.append(elapsed)
        features_of.append(features)
    print(f'{count} scans at 1 m, wall time: extraction median '
          f'{1e3 * statistics.median(extraction):.3f} ms, find_docks + track_dock median '
          f'{1e3 * statistics.median(detection):.3f} ms, p99 '
          f'{1e3 * float(np.percentile(detection, 99)):.3f} ms '
          f'({statistics.median(detection) / statistics.median(extraction):.2f}x the extraction)')
    angle_min, increment, bearings = full_turn_bearings()
    scans = [simulate_scan(plan.scene(pose, SCAN_PERIOD_S * k), bearings,
                           SENSOR_MODELS['s1_like'], rng) for k in range(len(features_of))]
    passes = 5
    started = time.process_time()
    for _ in range(passes):
        for ranges in scans:
            extract_features(ranges, angle_min, increment, config)
    extraction_s = (time.process_time() - started) / (passes * len(scans))
    started = time.process_time()
    for _ in range(passes):
        state = TrackerState()
        for t, features in enumerate(features_of):
            state, _ = track_dock(state, find_docks(features.segments, features.corners, SHAPE),
                                  SCAN_PERIOD_S * t, TrackSettings())
    detection_s = (time.process_time() - started) / (passes * len(features_of))
    print(f'CPU time per scan ({passes} passes): extraction {1e3 * extraction_s:.3f} ms, '
          f'find_docks + track_dock {1e3 * detection_s:.3f} ms '
          f'({detection_s / extraction_s:.2f}x the extraction)')


def main():
    """Run the three parts and print their figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scans', type=int, default=30, help='scans per pose (default 30)')
    args = parser.parse_args()
    print(start(wait=True).describe())
    s1 = feature_settings(defaults(FEATURE_NODE, 'rplidar_s1')).config
    generic = feature_settings(defaults(FEATURE_NODE, 'generic')).config
    sick = feature_settings(defaults(FEATURE_NODE, 'sick_lms1xx')).config
    hokuyo = feature_settings(defaults(FEATURE_NODE, 'hokuyo_urg04lx')).config

    def config_for(path):
        name = path.parent.name
        if name.startswith(('sick', 'lms111', 'mrpt')):
            return sick
        if name.startswith(('urg', 'tuw')):
            return hokuyo
        return generic

    print('\n## 1. accuracy, NEES, detection (S1-like noise, environment A lived in)')
    accuracy(s1, args.scans)
    print('\n## 2. false docks')
    look_alikes(s1, args.scans)
    real_recordings(config_for)
    print('\n## 3. time per scan')
    timing(s1, max(args.scans, 200))


if __name__ == '__main__':
    main()
