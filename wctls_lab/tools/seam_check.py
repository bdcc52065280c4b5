#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
"""
Measure whether the returns next to the seam of a full turn (first and last beams) leave walls.

Run inside the built workspace (``source tools/env.sh``)::

    wctls_lab/tools/seam_check.py data/rplidar_c1_single_scans --sensor rplidar_c1
    wctls_lab/tools/seam_check.py MY_A2_BAG --sensor rplidar_a2
    wctls_lab/tools/seam_check.py --layout        # sllidar_ros2's and rplidar_node's layouts
    wctls_lab/tools/seam_check.py --copies        # what sllidar_ros2's copies do to features

For a recording of full turns (docs/sensors.md#the-seam-of-a-turn):

1. each return against the straight line through its 4 + 4 nearest neighbours in bearing, where
   those lie on a line within 4 mm rms, by its angle from the seam;
2. each wall that one of the preset's segments carries across the seam: its returns within 3 deg
   of the seam against the line through its returns farther away; and, for comparison, the
   same at the middle bearing of every other segment of at least 20 returns;
3. the scans whose wall is split at the seam: a segment ending at the last beam and one starting
   at the first on the same line (normals within 3 deg, radii within 3 cm).

With ``--layout``: exact ranges of one straight wall across the seam, laid out with
``angle_compensate`` (binned) as sllidar_ros2 does (N = 360 k bins from -pi to pi in N - 1
increments, each sample copied into the next k - 1 bins) and as rplidar_node does (each bin at
its centre, 2 pi / N apart, each sample once), and without it (per sample, the same in both),
for an A2 (8000 samples a second) and a C1 (5000) at 10 Hz: how far the returns within 3 deg on
one side of the seam lie off the line through those 3-15 deg beyond it on the other, the same
probed away from the seam, and the segments the sensor's preset finds.
"""

import argparse
from dataclasses import replace
import math
import sys

import numpy as np
from wctls_lab.evaluation.scans import load_scans
from wctls_lab.evaluation.score_cli import node_config
from wctls_lab.simulation import load_floor_plan, SENSOR_MODELS, simulate_scan
from wctls_ros.core import extract_features
from wctls_rplidar.laserscan import compensation_multiple, ScanArrays, turn_to_scan
from wctls_rplidar.turns import Turn

NEIGHBOURS = 4                  # each side
STRAIGHT_RMS_M = 0.004          # the neighbours' rms off their line, for a straight wall
NEAR_SEAM_DEG = 3.0
ANGLE_BINS_DEG = (0.0, 1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 180.01)
SAME_LINE_RAD = math.radians(3.0)
SAME_LINE_M = 0.03
# --layout: (model, microseconds per sample, preset), walls (distance m, angle deg of the beam at
# the seam from the wall's normal).
MODELS = (('A2', 125.0, 'rplidar_a2'), ('C1', 200.0, 'rplidar_c1'))
WALLS = ((3.0, 45.0), (3.0, 60.0), (1.0, 45.0))
# --copies: (model, samples a turn at 10 Hz, preset, the simulator's noise, its range sigma m),
# turns per model, how far the sensor strays from the plan's pose, m; a true corner within.
ROOM_SENSORS = (('A2', 800, 'rplidar_a2', '1cm', 0.02), ('S1', 926, 'rplidar_s1', 's1_like', None))
ROOM_TURNS = 40
ROOM_STRAY_M = 0.3
TRUE_CORNER_M = 0.1


def line_through(x, y):
    """
    Return the total-least-squares line through points.

    :param x: x, m
    :param y: y, m
    :return: (a point on it (2,), its unit normal (2,), rms of the points off it m)
    """
    centre = np.array([x.mean(), y.mean()])
    _, singular, vt = np.linalg.svd(np.c_[x - centre[0], y - centre[1]], full_matrices=False)
    return centre, vt[1], singular[1] / math.sqrt(len(x))


def off_line(x, y, line) -> np.ndarray:
    """Return the signed distances of points from a line of :func:`line_through`, m."""
    centre, normal, _ = line
    return (x - centre[0]) * normal[0] + (y - centre[1]) * normal[1]


def seam_angle_deg(count: int, increment_rad: float) -> np.ndarray:
    """Return each beam's angle from the seam (between the last beam and the first), deg."""
    index = np.arange(count)
    return np.degrees(np.minimum(index, count - 1 - index) * abs(increment_rad))


def neighbour_residuals(scans):
    """
    Return every return's distance from the line through its neighbours, with its seam angle.

    :param scans: the recording
    :return: (angle from the seam deg, |distance| m), each (R,)
    """
    count = scans.ranges.shape[1]
    bearing = scans.angle_min + np.arange(count) * scans.angle_increment
    seam = seam_angle_deg(count, scans.angle_increment)
    angles, distances = [], []
    for ranges in scans.ranges:
        valid = np.flatnonzero(np.isfinite(ranges) & (ranges > scans.range_min)
                               & (ranges < scans.range_max))
        x, y = ranges[valid] * np.cos(bearing[valid]), ranges[valid] * np.sin(bearing[valid])
        for j in range(valid.size):
            around = [(j + o) % valid.size for o in range(-NEIGHBOURS, NEIGHBOURS + 1) if o]
            apart = np.abs(np.angle(np.exp(1j * (bearing[valid[around]] - bearing[valid[j]]))))
            if apart.max() > (NEIGHBOURS + 2) * abs(scans.angle_increment):
                continue                                # a gap: not one run of returns
            line = line_through(x[around], y[around])
            if line[2] <= STRAIGHT_RMS_M:
                angles.append(seam[valid[j]])
                distances.append(abs(off_line(x[j], y[j], line)))
    return np.array(angles), np.array(distances)


def walls_across(scans, config):
    """
    Return the walls the segments carry across the seam, and the scans split there.

    :param scans: the recording
    :param config: the pipeline settings
    :return: (per wall: scan, returns near the seam, their median and largest distance from the
        line through the others m, that line's rms m, the angle of the first beam from the
        wall's normal rad; the largest distance at the middle of
        every other wall m; per split: scan, the two segments' beams)
    """
    count = scans.ranges.shape[1]
    bearing = scans.angle_min + np.arange(count) * scans.angle_increment
    seam = seam_angle_deg(count, scans.angle_increment)
    walls, elsewhere, splits = [], [], []
    for k, ranges in enumerate(scans.ranges):
        segments = extract_features(ranges, scans.angle_min, scans.angle_increment, config,
                                    scans.range_min, scans.range_max).segments
        first, last = segments.first_index, segments.last_index
        for i in range(len(first)):
            beams = (np.r_[first[i]:count, 0:last[i] + 1] if first[i] > last[i]
                     else np.arange(first[i], last[i] + 1))
            beams = beams[np.isfinite(ranges[beams])]
            x, y = ranges[beams] * np.cos(bearing[beams]), ranges[beams] * np.sin(bearing[beams])
            if first[i] > last[i]:
                near = seam[beams] <= NEAR_SEAM_DEG
            elif beams.size >= 20:
                middle = bearing[beams[beams.size // 2]]
                near = np.degrees(np.abs(bearing[beams] - middle)) <= NEAR_SEAM_DEG
            else:
                continue
            if near.any() and (~near).sum() >= 3:
                line = line_through(x[~near], y[~near])
                distance = np.abs(off_line(x[near], y[near], line))
                if first[i] > last[i]:
                    normal_off = abs(math.remainder(segments.angle_rad[i] - scans.angle_min,
                                                    2.0 * math.pi))
                    walls.append((k, int(near.sum()), float(np.median(distance)),
                                  float(distance.max()), line[2], normal_off))
                else:
                    elsewhere.append(float(distance.max()))
        ends = np.flatnonzero(last >= count - 3), np.flatnonzero(first <= 2)
        for a in ends[0]:
            for b in ends[1]:
                turn = abs(math.remainder(segments.angle_rad[a] - segments.angle_rad[b],
                                          2.0 * math.pi))
                if (a != b and turn < SAME_LINE_RAD
                        and abs(segments.radius_m[a] - segments.radius_m[b]) < SAME_LINE_M):
                    splits.append((k, (int(first[a]), int(last[a])),
                                   (int(first[b]), int(last[b]))))
    return walls, np.array(elsewhere), splits


def report_recording(path: str, sensor: str) -> None:
    """Print the three measurements of a recording."""
    scans = load_scans(path)
    angles, distances = neighbour_residuals(scans)
    print(f'{path}: {len(scans)} scans x {scans.ranges.shape[1]} beams, preset {sensor}\n')
    print(f'1. returns against the line through their neighbours ({distances.size} returns '
          f'with straight neighbours):\n')
    print('| from the seam, deg | returns | median, mm | 90 %, mm | over 1 cm |')
    print('|---|---|---|---|---|')
    for low, high in zip(ANGLE_BINS_DEG[:-1], ANGLE_BINS_DEG[1:]):
        inside = distances[(angles >= low) & (angles < high)]
        if inside.size:
            print(f'| {low:g}-{min(high, 180):g} | {inside.size} '
                  f'| {1e3 * np.median(inside):.1f} | {1e3 * np.percentile(inside, 90):.1f} '
                  f'| {100 * np.mean(inside > 0.01):.1f} % |')
    walls, elsewhere, splits = walls_across(scans, node_config(sensor=sensor))
    print(f'\n2. walls across the seam: {len(walls)} (in {len({w[0] for w in walls})} scans); '
          f'returns within {NEAR_SEAM_DEG:g} deg of the seam against the line through the '
          'others:\n')
    print('| scan | returns | median, mm | largest, mm | line rms, mm '
          '| seam beam from the normal, deg |')
    print('|---|---|---|---|---|---|')
    for k, near, median, largest, rms, normal_off in walls:
        print(f'| {k} | {near} | {1e3 * median:.1f} | {1e3 * largest:.1f} | {1e3 * rms:.1f} '
              f'| {math.degrees(normal_off):.0f} |')
    largest = np.array([wall[3] for wall in walls])
    print(f'\nlargest over 1 cm: {np.sum(largest > 0.01)} of {largest.size} walls at the seam, '
          f'{np.sum(elsewhere > 0.01)} of {elsewhere.size} at the middle of the other walls '
          f'(median largest {1e3 * np.median(largest):.1f} and '
          f'{1e3 * np.median(elsewhere):.1f} mm)')
    print(f'\n3. walls split at the seam: {len(splits)}')
    for k, a, b in splits:
        print(f'   scan {k}: beams {a[0]}-{a[1]} and {b[0]}-{b[1]}')


def wall_turn(samples_per_turn: int, distance_m: float, normal_rad: float) -> Turn:
    """Return one turn of exact ranges to a wall (published angle = pi - raw, sllidar's)."""
    raw_deg = (np.arange(samples_per_turn) + 0.3) * 360.0 / samples_per_turn
    facing = np.cos(math.pi - np.radians(raw_deg) - normal_rad)
    distance = np.where(facing > 0.35, distance_m / np.maximum(facing, 1e-9), 0.0)
    return Turn(angle_deg=raw_deg, distance_mm=distance * 1000.0,
                quality=np.full(samples_per_turn, 40), first_sample_s=0.0, period_s=0.1,
                last_byte_s=0.1)


def off_across(scan, probe_rad: float) -> float:
    """
    Return how far the returns within 3 deg on one side of a bearing lie off the other side's line.

    :param scan: the LaserScan fields
    :param probe_rad: the bearing probed (pi: the seam, split by array position)
    :return: the median distance, m
    """
    ranges = np.asarray(scan.ranges, dtype=float)
    index = np.arange(ranges.size)
    bearing = scan.angle_min + index * scan.angle_increment
    from_probe = np.degrees(np.angle(np.exp(1j * (bearing - probe_rad))))
    if probe_rad == math.pi:
        one_side = index < ranges.size / 2
    else:
        one_side = from_probe > 0.0
    valid = np.isfinite(ranges)
    x, y = ranges * np.cos(bearing), ranges * np.sin(bearing)
    reference = valid & ~one_side & (np.abs(from_probe) > NEAR_SEAM_DEG) & (
        np.abs(from_probe) < 15.0)
    near = valid & one_side & (np.abs(from_probe) <= NEAR_SEAM_DEG)
    line = line_through(x[reference], y[reference])
    return float(np.median(np.abs(off_line(x[near], y[near], line))))


def sllidar_compensated_scan(turn: Turn, multiple: int) -> ScanArrays:
    """
    Return sllidar_ros2's ``angle_compensate`` layout of a turn (sllidar frame, upright).

    Each sample with a return fills bin floor(raw deg * k) and the next k - 1 (later samples
    overwrite), the other bins +inf; the bins are published from -pi to pi in N - 1 increments,
    array reversed.

    :param turn: the assembled turn
    :param multiple: k, bins per degree
    :return: the LaserScan fields (timing fields 0)
    """
    bins = 360 * multiple
    ranges = np.full(bins, np.inf)
    order = np.argsort(turn.angle_deg, kind='stable')
    for angle_deg, distance_mm in zip(turn.angle_deg[order], turn.distance_mm[order]):
        if distance_mm > 0:
            first = int(angle_deg * multiple)
            ranges[np.minimum(np.arange(first, first + multiple), bins - 1)] = distance_mm / 1e3
    return ScanArrays(angle_min=-math.pi, angle_max=math.pi,
                      angle_increment=2.0 * math.pi / (bins - 1), time_increment=0.0,
                      scan_time=turn.period_s, ranges=ranges[::-1].astype(np.float32),
                      intensities=np.zeros(bins, np.float32))


def segment_count(scan, config) -> int:
    """Return how many segments the pipeline finds in a laid-out turn."""
    return len(extract_features(np.asarray(scan.ranges, dtype=float), scan.angle_min,
                                scan.angle_increment, config, 0.05, 40.0).segments)


def report_layout() -> None:
    """Print what each angle_compensate layout does to one wall across the seam."""
    print('| model | wall | sllidar_ros2 binned: at the seam, mm | away from it, mm | segments '
          '| rplidar_node binned: at the seam, mm | away from it, mm | segments '
          '| per sample: at the seam, mm | segments |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for model, us_per_sample, sensor in MODELS:
        samples = int(1e6 / us_per_sample / 10.0)
        multiple = compensation_multiple(us_per_sample, 10.0)
        config = node_config(sensor=sensor)
        for distance, angle_deg in WALLS:
            at_seam = wall_turn(samples, distance, math.pi - math.radians(angle_deg))
            away = wall_turn(samples, distance, -math.radians(angle_deg))
            cells = []
            for binned in (lambda turn: sllidar_compensated_scan(turn, multiple),
                           lambda turn: turn_to_scan(turn, True, False, multiple)):
                scan = binned(at_seam)
                cells += [f'{1e3 * off_across(scan, math.pi):.1f}',
                          f'{1e3 * off_across(binned(away), 0.0):.1f}',
                          str(segment_count(scan, config))]
            per_sample = turn_to_scan(at_seam, False, False, multiple)
            cells += [f'{1e3 * off_across(per_sample, math.pi):.1f}',
                      str(segment_count(per_sample, config))]
            print(f'| {model} (k = {multiple}) | {distance:g} m, {angle_deg:g} deg | '
                  + ' | '.join(cells) + ' |')


def room_turn(plan, samples: int, noise, rng) -> tuple:
    """
    Return one turn of a floor plan from a random pose near the plan's, and its true corners.

    :param plan: the floor plan
    :param samples: samples a turn, evenly spaced from a random phase
    :param noise: the simulator's sensor model
    :param rng: random generator
    :return: (the turn, the true corners in the sensor frame (C, 2) m)
    """
    x, y, _ = plan.sensor_pose
    pose = (x + rng.uniform(-ROOM_STRAY_M, ROOM_STRAY_M),
            y + rng.uniform(-ROOM_STRAY_M, ROOM_STRAY_M), rng.uniform(-math.pi, math.pi))
    raw_deg = (np.arange(samples) + rng.uniform()) * 360.0 / samples
    ranges = simulate_scan(plan.scene(pose), math.pi - np.radians(raw_deg), noise, rng)
    turn = Turn(angle_deg=raw_deg, distance_mm=np.where(np.isfinite(ranges), ranges * 1e3, 0.0),
                quality=np.full(samples, 40), first_sample_s=0.0, period_s=0.1, last_byte_s=0.1)
    return turn, plan.in_sensor_frame(pose)[1]


def copied_bins(turn: Turn, multiple: int) -> np.ndarray:
    """
    Return how far each of sllidar_ros2's copies lies from its sample's bearing, in bins.

    :param turn: the assembled turn
    :param multiple: k, bins per degree
    :return: one entry per bin holding a copy (not a sample of its own)
    """
    scan = sllidar_compensated_scan(turn, multiple)
    bins = len(scan.ranges)
    held = np.isfinite(scan.ranges[::-1])            # in bin order again
    has_return = turn.distance_mm > 0
    position = turn.angle_deg[has_return] * multiple
    order = np.argsort(position, kind='stable')
    position = position[order]
    # Each bin's copy or sample: the last sample with a return at or before the bin's end.
    holder = np.searchsorted(position, np.arange(1, bins + 1), side='left') - 1
    copy = held & (holder >= 0) & (np.floor(position[np.maximum(holder, 0)])
                                   < np.arange(bins))
    return (np.arange(bins) + 0.5 - position[holder])[copy]


def report_copies() -> None:
    """Print what sllidar_ros2's copies do to the features of emulated room turns."""
    plan = load_floor_plan('environment_a')
    print(f'{ROOM_TURNS} turns per sensor of environment_a, within {ROOM_STRAY_M:g} m of its '
          'pose, any heading\n')
    print('| sensor | layout | copies a turn | copy off its sample, bins: median, largest '
          '| segments a turn | range-noise estimate, mm | median chi2/dof | corners '
          f'| not within {100 * TRUE_CORNER_M:g} cm of a true one | corner NEES (x, y) |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for model, samples, sensor, noise_name, range_sigma_m in ROOM_SENSORS:
        noise = SENSOR_MODELS[noise_name]
        if range_sigma_m is not None:
            noise = replace(noise, range_sigma_m=range_sigma_m)
        multiple = compensation_multiple(1e5 / samples, 10.0)
        config = node_config(sensor=sensor)
        layouts = {'sllidar_ros2 binned': lambda turn: sllidar_compensated_scan(turn, multiple),
                   'rplidar_node binned': lambda turn: turn_to_scan(turn, True, False, multiple),
                   'per sample': lambda turn: turn_to_scan(turn, False, False, multiple)}
        rows = {name: {'segments': [], 'sigma': [], 'chi2': [], 'nees': [], 'corners': 0,
                       'off': 0} for name in layouts}
        copies, copy_off = [], []
        rng = np.random.default_rng(0)
        for _ in range(ROOM_TURNS):
            turn, true_corners = room_turn(plan, samples, noise, rng)
            off = copied_bins(turn, multiple)
            copies.append(off.size)
            copy_off.extend(off)
            for name, layout in layouts.items():
                scan = layout(turn)
                features = extract_features(np.asarray(scan.ranges, dtype=float), scan.angle_min,
                                            scan.angle_increment, config, 0.05, 40.0)
                row = rows[name]
                row['segments'].append(len(features.segments))
                row['sigma'].append(features.range_sigma_m)
                row['chi2'].extend(features.segments.residual_chi2_dof)
                for xy, covariance in zip(features.corners.xy_m, features.corners.covariance):
                    error = true_corners - xy
                    nearest = np.argmin(np.hypot(error[:, 0], error[:, 1]))
                    row['corners'] += 1
                    if np.hypot(*error[nearest]) < TRUE_CORNER_M:
                        row['nees'].append(float(error[nearest] @ np.linalg.solve(
                            covariance[:2, :2], error[nearest])))
                    else:
                        row['off'] += 1
        for name, row in rows.items():
            copied = (f'{np.mean(copies):.0f} | {np.median(copy_off):.2f}, {np.max(copy_off):.2f}'
                      if name.startswith('sllidar') else '0 | -')
            print(f'| {model} (k = {multiple}) | {name} | {copied} '
                  f'| {np.mean(row["segments"]):.1f} | {1e3 * np.mean(row["sigma"]):.1f} '
                  f'| {np.median(row["chi2"]):.2f} | {row["corners"]} | {row["off"]} '
                  f'| {np.mean(row["nees"]):.2f} |')


def main(argv=None) -> int:
    """Run the measurement the arguments ask for."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('recording', nargs='?', help='a bag of full turns, one scan layout')
    parser.add_argument('--sensor', default='generic', help='the sensor preset (segments)')
    parser.add_argument('--layout', action='store_true',
                        help="simulate sllidar_ros2's and rplidar_node's angle_compensate "
                             'layouts instead')
    parser.add_argument('--copies', action='store_true',
                        help="measure what sllidar_ros2's copies do to emulated room turns")
    args = parser.parse_args(argv)
    if args.layout:
        report_layout()
    elif args.copies:
        report_copies()
    elif args.recording:
        report_recording(args.recording, args.sensor)
    else:
        parser.error('give a recording, --layout or --copies')
    return 0


if __name__ == '__main__':
    sys.exit(main())
