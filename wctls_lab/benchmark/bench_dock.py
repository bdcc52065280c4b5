#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Measure the dock detector (wctls_ros.frontend.dock): accuracy, NEES, detection, false docks, time.

Two detectors side by side on the same scans, each with its own tracker: "corners", the dock
from the corners alone (find_docks without the returns, the way before the fit to the returns),
and "returns", the dock fitted to the scan's returns (what feature_node and process_bag run).

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
3. Time per scan of find_docks + track_dock beside the extraction (the compiled core), 1 m
   from the dock and in environment A lived in without it (every start tried): wall time
   (median, p99) and CPU time; the fit to the returns also by its numpy steps ("numpy", as
   where numba is missing) beside its compiled twin ("returns").

Usage: python bench_dock.py [--scans N] [--parts accuracy false time]
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
from wctls_ros.frontend.dock import (dock_returns, DockShape, find_docks, track_dock,
                                     TrackerState, TrackSettings, wrap_angle)
from wctls_ros.params import defaults, FEATURE_NODE, feature_settings

DATA = pathlib.Path(__file__).resolve().parents[2] / 'data'
SHAPE = DockShape()
APEX = np.array([4.45, 1.6])          # the dock's apex in environment A, its axis along +x
DISTANCES_M = (0.3, 0.5, 1.0, 2.0, 3.0)
VIEWS_DEG = (-60, -30, 0, 30, 60)
# (distance, view) -> the dock's bearings in the scan, deg; 0 elsewhere.
BEARINGS_DEG = {(1.0, 0): (-60, 0, 60)}
SCAN_PERIOD_S = 0.1
DETECTORS = ('corners', 'returns')
# Timed also: the fit to the returns by its numpy steps, beside the compiled one.
TIMED = DETECTORS + ('numpy',)
PARTS = ('accuracy', 'false', 'time')


def detect(detector, features, ranges, angle_min, increment, config):
    """Return one scan's dock candidates by a detector: 'corners', 'returns' or 'numpy'."""
    if detector == 'corners':
        return find_docks(features.segments, features.corners, SHAPE)
    # 'returns': the compiled fit while the compiled core serves; 'numpy': its numpy steps.
    return find_docks(features.segments, features.corners, SHAPE,
                      dock_returns(ranges, angle_min, increment, config, features.range_sigma_m),
                      compiled=False if detector == 'numpy' else None)


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
    """Yield (scene, ranges, features, elapsed extraction s) for ``count`` scans from a pose."""
    angle_min, increment, bearings = full_turn_bearings()
    for t in range(count):
        scene = plan.scene(pose, walk_time_s + SCAN_PERIOD_S * t)
        ranges = simulate_scan(scene, bearings, SENSOR_MODELS['s1_like'], rng)
        started = time.perf_counter()
        features = extract_features(ranges, angle_min, increment, config)
        yield scene, ranges, features, time.perf_counter() - started


def accuracy(config, count):
    """Print the sweep of part 1: per line, the corners' figures, then the returns'."""
    plan = dock_plan()
    half = SHAPE.opening_angle_rad / 2.0
    tips = (APEX + SHAPE.right_face_m * np.array([-math.cos(half), -math.sin(half)]),
            APEX + SHAPE.left_face_m * np.array([-math.cos(half), math.sin(half)]))
    angle_min, increment, _ = full_turn_bearings()
    rng = np.random.default_rng(46)
    print('distance m | view deg | bearings deg | in view | detector | detected % | '
          'once confirmed % | median error mm | median yaw error deg | mean NEES (3 dof)')
    for distance in DISTANCES_M:
        for view in VIEWS_DEG:
            figures = {d: {'detected': 0, 'after': 0, 'in_view_after': 0, 'errors': [],
                           'yaw': [], 'nees': []} for d in DETECTORS}
            in_view = 0
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
                states = {d: TrackerState() for d in DETECTORS}
                confirmed = dict.fromkeys(DETECTORS, False)
                for t, (scene, ranges, features, _) in enumerate(
                        run_scans(plan, pose, count, config, rng, walk_time_s=rng.uniform(0, 3))):
                    shown = fully_in_view(scene, faces, increment)
                    in_view += shown
                    for detector in DETECTORS:
                        states[detector], report = track_dock(
                            states[detector], detect(detector, features, ranges, angle_min,
                                                     increment, config),
                            SCAN_PERIOD_S * t, TrackSettings())
                        # The scans after the tracker's first report: the steady rate.
                        after = confirmed[detector]
                        confirmed[detector] = after or report is not None
                        figure = figures[detector]
                        figure['in_view_after'] += shown and after
                        if not shown or report is None:
                            continue
                        figure['detected'] += 1
                        figure['after'] += after
                        figure['errors'].append(1e3 * math.hypot(*(report.vector[:2]
                                                                   - truth[:2])))
                        figure['yaw'].append(abs(math.degrees(wrap_angle(report.yaw_rad
                                                                         - truth[2]))))
                        figure['nees'].append(nees3(report, truth))
            if not in_view:
                continue
            for detector in DETECTORS:
                figure = figures[detector]
                rate = 100.0 * figure['detected'] / in_view
                # Each detector's own confirmation: its scans after its first report.
                steady = (100.0 * figure['after'] / figure['in_view_after']
                          if figure['in_view_after'] else math.nan)
                print(f'{distance:10.1f} | {view:8d} | {",".join(map(str, bearings)):>12} | '
                      f'{in_view:7d} | {detector:>8} | {rate:10.1f} | {steady:16.1f} | '
                      f'{_median(figure["errors"]):15.1f} | {_median(figure["yaw"]):20.2f} | '
                      f'{_mean(figure["nees"]):6.2f}', flush=True)


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
    angle_min, increment, _ = full_turn_bearings()
    for name, (spec, poses) in rooms.items():
        plan = floor_plan_from_dict(spec)
        candidates, reports, scans = dict.fromkeys(DETECTORS, 0), dict.fromkeys(DETECTORS, 0), 0
        for pose in poses:
            states = {d: TrackerState() for d in DETECTORS}
            for t, (_, ranges, features, _) in enumerate(run_scans(plan, pose, count, config,
                                                                   rng)):
                for detector in DETECTORS:
                    found = detect(detector, features, ranges, angle_min, increment, config)
                    states[detector], report = track_dock(states[detector], found,
                                                          SCAN_PERIOD_S * t, TrackSettings())
                    candidates[detector] += len(found)
                    reports[detector] += report is not None
                scans += 1
        print(f'{name}: {scans} scans; ' + '; '.join(
            f'{d}: {candidates[d]} candidates, {reports[d]} docks reported' for d in DETECTORS),
            flush=True)


def real_recordings(config_for):
    """Print part 2 for the shipped recordings."""
    paths = sorted(DATA.glob('*/*.mcap')) + sorted((DATA / 'lms111_building').glob('*.json'))
    total_scans = 0
    totals = {d: [0, 0] for d in DETECTORS}
    for path in paths:
        scans = load_json_scans(path) if path.suffix == '.json' else load_scans(path)
        config = config_for(path)
        states = {d: TrackerState() for d in DETECTORS}
        counts = {d: [0, 0] for d in DETECTORS}
        for k, ranges in enumerate(scans.ranges):
            features = extract_features(ranges, scans.angle_min, scans.angle_increment, config)
            stamp_s = (scans.stamps_ns[k] - scans.stamps_ns[0]) * 1e-9 if len(
                scans.stamps_ns) else 0.0
            for detector in DETECTORS:
                found = detect(detector, features, ranges, scans.angle_min,
                               scans.angle_increment, config)
                states[detector], report = track_dock(states[detector], found, float(stamp_s),
                                                      TrackSettings())
                counts[detector][0] += len(found)
                counts[detector][1] += report is not None
        total_scans += len(scans.ranges)
        for detector in DETECTORS:
            totals[detector] = [t + c for t, c in zip(totals[detector], counts[detector])]
        print(f'{path.parent.name}/{path.name}: {len(scans.ranges)} scans; ' + '; '.join(
            f'{d}: {counts[d][0]} candidates, {counts[d][1]} docks reported' for d in DETECTORS))
    print(f'all recordings: {total_scans} scans; ' + '; '.join(
        f'{d}: {totals[d][0]} candidates, {totals[d][1]} docks reported' for d in DETECTORS))


def timing(config, count, plan, pose, scene):
    """
    Print part 3 for one scene: each detector's time beside the extraction's, per scan.

    Wall time per scan (median, p99), and CPU time (``time.process_time``) over five passes of
    the same scans, which a loaded machine's preemption does not inflate; the detectors
    alternate scan by scan.
    """
    rng = np.random.default_rng(3)
    angle_min, increment, _ = full_turn_bearings()
    extraction, scans = [], []
    detection = {d: [] for d in TIMED}
    states = {d: TrackerState() for d in TIMED}
    for t, (_, ranges, features, elapsed) in enumerate(run_scans(plan, pose, count, config,
                                                                 rng)):
        for detector in TIMED:
            started = time.perf_counter()
            found = detect(detector, features, ranges, angle_min, increment, config)
            states[detector], _ = track_dock(states[detector], found, SCAN_PERIOD_S * t,
                                             TrackSettings())
            detection[detector].append(time.perf_counter() - started)
        extraction.append(elapsed)
        scans.append((ranges, features))
    extraction_ms = 1e3 * statistics.median(extraction)
    print(f'{count} scans {scene}, wall time: extraction median {extraction_ms:.3f} ms; '
          + '; '.join(f'{d}: find_docks + track_dock median '
                      f'{1e3 * statistics.median(detection[d]):.3f} ms, p99 '
                      f'{1e3 * float(np.percentile(detection[d], 99)):.3f} ms '
                      f'({1e3 * statistics.median(detection[d]) / extraction_ms:.2f}x the '
                      'extraction)' for d in TIMED))
    passes = 5
    started = time.process_time()
    for _ in range(passes):
        for ranges, _ in scans:
            extract_features(ranges, angle_min, increment, config)
    extraction_s = (time.process_time() - started) / (passes * len(scans))
    cpu = {}
    for detector in TIMED:
        started = time.process_time()
        for _ in range(passes):
            state = TrackerState()
            for t, (ranges, features) in enumerate(scans):
                state, _ = track_dock(state, detect(detector, features, ranges, angle_min,
                                                    increment, config),
                                      SCAN_PERIOD_S * t, TrackSettings())
        cpu[detector] = (time.process_time() - started) / (passes * len(scans))
    print(f'CPU time per scan ({passes} passes): extraction {1e3 * extraction_s:.3f} ms; '
          + '; '.join(f'{d}: find_docks + track_dock {1e3 * cpu[d]:.3f} ms '
                      f'({cpu[d] / extraction_s:.2f}x the extraction)' for d in TIMED))


def main():
    """Run the three parts and print their figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scans', type=int, default=30, help='scans per pose (default 30)')
    parser.add_argument('--parts', nargs='+', choices=PARTS, default=PARTS,
                        help='which parts to run (default all)')
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

    if 'accuracy' in args.parts:
        print('\n## 1. accuracy, NEES, detection (S1-like noise, environment A lived in)')
        accuracy(s1, args.scans)
    if 'false' in args.parts:
        print('\n## 2. false docks')
        look_alikes(s1, args.scans)
        real_recordings(config_for)
    if 'time' in args.parts:
        print('\n## 3. time per scan')
        timing(s1, max(args.scans, 200), dock_plan(), (APEX[0] - 1.0, APEX[1], 0.0), 'at 1 m')
        # Without the dock every start is tried, the one segment's too.
        lived_in = load_floor_plan('environment_a_cluttered')
        timing(s1, max(args.scans, 200), lived_in, lived_in.sensor_pose,
               'in environment A lived in without the dock')


if __name__ == '__main__':
    main()
