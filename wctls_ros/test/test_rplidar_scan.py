# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Turns, and the LaserScan layouts of both outputs.

Turn assembly and timing, sllidar_ros2's LaserScan layout (against a port of its loops; the
binned one keeps its beams and order but each at its own bearing, without copies: walls across
the seam stay on their lines), the fixed-count scan and the two laser frame orientations
(against angles worked out by hand).
"""

import math

import numpy as np
import pytest
from wctls_lab.evaluation.score_cli import node_config
from wctls_ros.core import extract_features
from wctls_rplidar.laserscan import compensation_multiple, fixed_scan, turn_to_scan
from wctls_rplidar.protocol import Samples
from wctls_rplidar.turns import SampleClock, Turn, TurnAssembler


def sllidar_reference(angle_deg, dist_mm, quality, angle_compensate, inverted, multiple):
    """
    Port of sllidar_node.cpp: ascend, bin (or trim), then publish_scan's layout.

    :return: angle_min, angle_max, angle_increment, ranges, intensities and the raw angle of the
        sample each beam holds (deg; 0 for an empty bin)
    """
    order = np.argsort(angle_deg, kind='stable')
    nodes = [(float(angle_deg[i]), float(dist_mm[i]), int(quality[i])) for i in order]
    if angle_compensate:
        count = 360 * multiple
        binned = [(0.0, 0.0, 0)] * count
        for angle, dist, qual in nodes:
            if dist != 0:
                value = int(angle * multiple)
                for j in range(multiple):
                    binned[min(value + j, count - 1)] = (angle, dist, qual)
        nodes, angle_min, angle_max = binned, 0.0, math.radians(360.0)
    else:
        first = next(i for i, n in enumerate(nodes) if n[1] != 0)
        last = max(i for i, n in enumerate(nodes) if n[1] != 0)
        nodes = nodes[first:last + 1]
        angle_min, angle_max = math.radians(nodes[0][0]), math.radians(nodes[-1][0])
    reversed_ = angle_max > angle_min
    lo, hi = (math.pi - angle_max, math.pi - angle_min) if reversed_ else (
        math.pi - angle_min, math.pi - angle_max)
    ranges = [math.inf if n[1] == 0 else n[1] / 1000.0 for n in nodes]
    intensities = [float(n[2]) for n in nodes]
    sample_deg = [n[0] for n in nodes]
    if (not inverted and reversed_) or (inverted and not reversed_):
        ranges, intensities, sample_deg = ranges[::-1], intensities[::-1], sample_deg[::-1]
    return lo, hi, (hi - lo) / (len(nodes) - 1), ranges, intensities, np.array(sample_deg)


def random_turn(rng, count, gaps=0.1):
    """Return a turn of ``count`` samples at random angles, some without a return."""
    angle = np.sort(rng.uniform(0.0, 360.0, count))
    distance = np.where(rng.random(count) < gaps, 0.0, rng.uniform(100.0, 9000.0, count))
    distance[[0, -1]] = 0.0                                  # exercise the trimming
    return Turn(angle_deg=rng.permutation(angle), distance_mm=distance,
                quality=rng.integers(0, 64, count).astype(np.uint8), first_sample_s=1.0,
                period_s=0.1, last_byte_s=1.1)


@pytest.mark.parametrize('inverted', [False, True])
@pytest.mark.parametrize('count', [411, 926, 1500])
def test_per_sample_layout_of_a_uniform_turn_matches_sllidar(inverted, count):
    # Dense capsules and standard nodes sample a uniform grid: one beam per sample, at its own
    # bearing, as sllidar_ros2 lays them out.
    rng = np.random.default_rng(count)
    angle = 0.2 + np.arange(count) * (359.6 / count)
    distance = np.where(rng.random(count) < 0.1, 0.0, rng.uniform(100.0, 9000.0, count))
    distance[[0, -1]] = 0.0                                  # exercise the trimming
    turn = Turn(angle_deg=angle, distance_mm=distance,
                quality=rng.integers(0, 64, count).astype(np.uint8), first_sample_s=1.0,
                period_s=0.1, last_byte_s=1.1)
    scan = turn_to_scan(turn, False, inverted, multiple=3)
    lo, hi, increment, ranges, intensities, _ = sllidar_reference(
        turn.angle_deg, turn.distance_mm, turn.quality, False, inverted, 3)
    assert (scan.angle_min, scan.angle_max) == pytest.approx((lo, hi), abs=1e-9)
    assert scan.angle_increment == pytest.approx(increment, rel=1e-9)
    np.testing.assert_array_equal(scan.ranges, np.float32(ranges))
    np.testing.assert_array_equal(scan.intensities, np.float32(intensities))
    assert scan.scan_time == 0.1
    assert scan.time_increment == pytest.approx(increment / (2 * math.pi) * 0.1)


@pytest.mark.parametrize('inverted', [False, True])
@pytest.mark.parametrize('count', [411, 926, 1500])
def test_per_sample_layout_puts_each_beam_within_half_a_step_of_its_own_sample(
        inverted, count):
    # Angles that do not lie on a grid (corrected, or a frame lost): sllidar_ros2 spreads the
    # samples evenly between the first and the last return, degrees off their own bearings.
    turn = random_turn(np.random.default_rng(count), count)
    # In measurement order: the step is the median advance from one sample to the next.
    turn = Turn(np.sort(turn.angle_deg), turn.distance_mm, turn.quality, 1.0, 0.1, 1.1)
    scan = turn_to_scan(turn, False, inverted, multiple=3)
    bearing = scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
    if inverted:
        bearing = bearing[::-1]
    sample_bearing = math.pi - np.radians(turn.angle_deg)
    filled = np.isfinite(scan.ranges)
    assert filled.sum() > 0.3 * count
    for beam in np.flatnonzero(filled):
        # The sample this beam holds: the one of its range (random distances are distinct).
        sample = np.flatnonzero(np.float32(turn.distance_mm / 1000.0) == scan.ranges[beam])
        assert len(sample) == 1
        assert abs(sample_bearing[sample[0]] - bearing[beam]) <= 0.5 * scan.angle_increment + 1e-9
    assert scan.time_increment == pytest.approx(scan.angle_increment / (2 * math.pi) * 0.1)


@pytest.mark.parametrize('inverted', [False, True])
@pytest.mark.parametrize('count', [411, 926, 1500])
def test_compensated_layout_keeps_sllidars_beams_without_its_copies_or_drift(inverted, count):
    # sllidar_ros2 spreads its 360 k bins over 2 pi in N - 1 increments (bearings drift by a bin
    # along the turn) and copies each sample into the next k - 1 bins. rplidar_node keeps its
    # beam count and array order (a sample alone in its bin is in the same beam) but publishes
    # each bin at its centre, 2 pi / N apart, and each sample once: a bin without a sample of
    # its own is NaN, no measurement (REP-117).
    multiple = 3
    turn = random_turn(np.random.default_rng(count), count)
    scan = turn_to_scan(turn, True, inverted, multiple)
    lo, _, _, ranges, intensities, sample_deg = sllidar_reference(
        turn.angle_deg, turn.distance_mm, turn.quality, True, inverted, multiple)
    bins = 360 * multiple
    width = 2 * math.pi / bins
    assert len(scan.ranges) == len(scan.intensities) == bins
    assert scan.angle_increment == pytest.approx(width, rel=1e-12)
    assert scan.angle_min == pytest.approx(lo + width / 2, abs=1e-12)
    assert scan.angle_max == pytest.approx(scan.angle_min + (bins - 1) * width, abs=1e-12)
    assert scan.time_increment == pytest.approx(0.1 / bins)
    bin_of_beam = np.arange(bins) if inverted else bins - 1 - np.arange(bins)
    samples_per_bin = np.bincount(np.floor(turn.angle_deg * multiple).astype(int),
                                  minlength=bins)[bin_of_beam]
    own = (np.floor(sample_deg * multiple) == bin_of_beam) & np.isfinite(ranges)
    alone = own & (samples_per_bin == 1)
    assert alone.sum() > 0.3 * min(count, bins)
    np.testing.assert_array_equal(scan.ranges[alone], np.float32(ranges)[alone])
    np.testing.assert_array_equal(scan.intensities[alone], np.float32(intensities)[alone])
    # sllidar's copies: bins no sample fell in.
    assert np.isnan(scan.ranges[samples_per_bin == 0]).all()
    assert not np.isnan(scan.ranges[samples_per_bin > 0]).any()


def test_compensated_scan_is_1080_beams_at_their_bin_centres_in_denseboost():
    multiple = compensation_multiple(108.0, 10.0)
    assert (multiple, compensation_multiple(244.0, 10.0)) == (3, 2)
    scan = turn_to_scan(random_turn(np.random.default_rng(1), 926), True, False, multiple)
    assert len(scan.ranges) == 1080
    # Not sllidar_ros2's -pi to pi in 1079 increments: 1080 bins of 1/3 deg span 2 pi, so their
    # centres run from -pi + 1/6 deg to pi - 1/6 deg in 1079 increments of 2 pi / 1080.
    half_bin = math.pi / 1080
    assert (scan.angle_min, scan.angle_max) == pytest.approx((-math.pi + half_bin,
                                                              math.pi - half_bin))
    assert scan.angle_increment == pytest.approx(2 * math.pi / 1080)


def test_a_turn_without_returns_has_no_finite_range():
    turn = Turn(np.linspace(0, 359, 50), np.zeros(50), np.zeros(50, np.uint8), 0.0, 0.1, 0.1)
    assert np.isinf(turn_to_scan(turn, False, False, 3).ranges).all()
    binned = turn_to_scan(turn, True, False, 3).ranges
    # +inf (no return) in the 50 bins holding a sample, NaN (no measurement) in the others.
    assert len(binned) == 1080 and np.isinf(binned).sum() == 50 and np.isnan(binned).sum() == 1030


@pytest.mark.parametrize('orientation', ['sllidar', 'rep103'])
@pytest.mark.parametrize('inverted', [False, True])
def test_each_binned_beam_is_published_at_its_samples_bearing(inverted, orientation):
    # One sample at each bin's centre, told apart by its range: the beam holding it must be
    # published at its bearing, offset - raw (raw - offset mirrored), whatever the array order.
    multiple, bins = 3, 1080
    raw_deg = (np.arange(bins) + 0.5) / multiple
    turn = Turn(raw_deg, 1000.0 + np.arange(bins), np.full(bins, 40, np.uint8), 0.0, 0.1, 0.1)
    scan = turn_to_scan(turn, True, inverted, multiple, orientation)
    sample = np.rint(np.asarray(scan.ranges, float) * 1000.0 - 1000.0).astype(int)
    assert sorted(sample) == list(range(bins))
    offset = {'sllidar': math.pi, 'rep103': 0.0}[orientation]
    true_rad = offset - np.radians(raw_deg[sample])
    if inverted:
        true_rad = -true_rad
    published = scan.angle_min + scan.angle_increment * np.arange(bins)
    bearing_error = np.angle(np.exp(1j * (published - true_rad)))
    assert np.abs(bearing_error).max() < 0.1 * scan.angle_increment


SEAM_WALL_M = 3.0


def seam_wall_turn(samples, from_normal_deg, phase):
    """
    Return a turn of exact ranges to one flat wall SEAM_WALL_M away, across the seam.

    The seam (raw angle 0, published angle pi in sllidar's frame) lies ``from_normal_deg`` from
    the wall's normal; the wall returns where it is seen within 69 deg of its normal. Sample s
    is at raw angle (s + ``phase``) 360 / ``samples`` deg.
    """
    raw_deg = (np.arange(samples) + phase) * 360.0 / samples
    facing = np.cos(np.radians(from_normal_deg - raw_deg))
    distance_mm = np.where(facing > 0.35, 1000.0 * SEAM_WALL_M / np.maximum(facing, 1e-9), 0.0)
    return Turn(raw_deg, distance_mm, np.full(samples, 40, np.uint8), 0.0, 0.1, 0.1)


def off_the_wall_m(scan, from_normal_deg):
    """Return each finite return's distance from the wall of :func:`seam_wall_turn`, m."""
    ranges = np.asarray(scan.ranges, float)
    bearing = scan.angle_min + scan.angle_increment * np.arange(len(ranges))
    valid = np.isfinite(ranges)
    normal = math.pi - math.radians(from_normal_deg)
    return np.abs(ranges[valid] * np.cos(bearing[valid] - normal) - SEAM_WALL_M)


def one_segment_across_the_seam(scan):
    """Return whether the rplidar_a2 preset finds one segment in the scan, across its seam."""
    segments = extract_features(np.asarray(scan.ranges, float), scan.angle_min,
                                scan.angle_increment, node_config(sensor='rplidar_a2'), 0.05,
                                40.0).segments
    return len(segments) == 1 and segments.first_index[0] > segments.last_index[0]


@pytest.mark.parametrize('from_normal_deg', [45.0, 60.0])
@pytest.mark.parametrize('multiple', [2, 3])
def test_a_wall_sampled_at_the_bin_centres_lies_on_its_line_across_the_seam(
        multiple, from_normal_deg):
    # One sample at the centre of each bin: any bearing error is the layout's own. sllidar_ros2's
    # increment of 2 pi / (N - 1) put the beams next to the seam a whole bin off, 1.7-3.0 cm off
    # the wall at 3 m (docs/sensors.md#the-seam-of-a-turn), and split it at 60 deg.
    bins = 360 * multiple
    turn = seam_wall_turn(bins, from_normal_deg, phase=0.5)
    scan = turn_to_scan(turn, True, False, multiple)
    # Beam i holds bin N - 1 - i, whose only sample is sample N - 1 - i.
    sample = bins - 1 - np.arange(bins)
    np.testing.assert_array_equal(
        scan.ranges, np.float32(np.where(turn.distance_mm > 0, turn.distance_mm / 1e3,
                                         np.inf))[sample])
    published = scan.angle_min + scan.angle_increment * np.arange(bins)
    bearing_error = np.angle(np.exp(1j * (published - (math.pi - np.radians(
        turn.angle_deg[sample])))))
    assert np.abs(bearing_error).max() < 0.1 * scan.angle_increment
    assert off_the_wall_m(scan, from_normal_deg).max() < 0.002
    assert one_segment_across_the_seam(scan)


@pytest.mark.parametrize('from_normal_deg', [45.0, 60.0])
@pytest.mark.parametrize('samples, us_per_sample', [(800, 125.0), (500, 200.0)])
def test_each_binned_beam_holds_the_sample_nearest_its_bearing_across_the_seam(
        samples, us_per_sample, from_normal_deg):
    # An A2 (8000 samples a second, k = 3) and a C1 (5000, k = 2) at 10 Hz: the samples fall
    # anywhere in their bins, so each return is up to half a bin off its beam's bearing, and no
    # more on either side of the seam.
    multiple = compensation_multiple(us_per_sample, 10.0)
    assert 360 * multiple > samples
    turn = seam_wall_turn(samples, from_normal_deg, phase=0.3)
    scan = turn_to_scan(turn, True, False, multiple)
    ranges = np.asarray(scan.ranges)
    published = scan.angle_min + scan.angle_increment * np.arange(len(ranges))
    sample_bearing = math.pi - np.radians(turn.angle_deg)
    apart = np.abs(np.angle(np.exp(1j * (published[:, None] - sample_bearing[None, :]))))
    nearest = apart.argmin(axis=1)
    held = ~np.isnan(ranges)
    assert held.sum() == samples
    assert (apart[held, nearest[held]] <= 0.5 * scan.angle_increment * (1 + 1e-9)).all()
    sample_ranges = np.float32(np.where(turn.distance_mm > 0, turn.distance_mm / 1e3, np.inf))
    np.testing.assert_array_equal(ranges[held], sample_ranges[nearest[held]])
    assert one_segment_across_the_seam(scan)


def wall_turn(wall_deg, count=360, wall_mm=1500.0, far_mm=8000.0):
    """
    Return a turn of evenly spaced samples, far everywhere but at one wall sample.

    The wall sample is the one nearest raw angle ``wall_deg`` (clockwise, the device's own
    angle). The samples lie 0.2 degree past whole degrees: with 360 of them, one in each one-degree
    bin, never on a bin's edge.
    """
    angle = np.arange(count) * 360.0 / count + 0.2
    distance = np.full(count, far_mm)
    distance[np.argmin(np.abs(angle - wall_deg))] = wall_mm
    return Turn(angle, distance, np.full(count, 40, np.uint8), 2.0, 0.1, 2.1)


# Raw (clockwise) wall angle -> the beam it must land in among 360 one-degree bins from -180
# degrees, worked out by hand: sllidar publishes 180 - raw, REP-103 -raw (both wrapped to
# [-180, 180)); the bin is floor(published + 180).
WALL_BINS = [
    # raw 30.2: sllidar 149.8 -> bin 329; rep103 -30.2 -> bin 149
    (30.2, 'sllidar', 329), (30.2, 'rep103', 149),
    # raw 90.5 (the device's right): sllidar 89.5 -> 269; rep103 -90.5 -> 89
    (90.5, 'sllidar', 269), (90.5, 'rep103', 89),
    # raw 200.6: sllidar -20.6 -> 159; rep103 -200.6 = 159.4 -> 339
    (200.6, 'sllidar', 159), (200.6, 'rep103', 339),
    # raw 0.1 (the front): sllidar 179.9 -> 359; rep103 -0.1 -> 179
    (0.1, 'sllidar', 359), (0.1, 'rep103', 179),
]


@pytest.mark.parametrize('wall_deg, orientation, beam', WALL_BINS)
def test_a_wall_lands_in_the_right_fixed_beam_in_both_orientations(
        wall_deg, orientation, beam):
    turn = wall_turn(wall_deg)
    scan = fixed_scan(turn, 360, inverted=False, orientation=orientation)
    assert len(scan.ranges) == 360
    assert np.flatnonzero(scan.ranges < 2.0).tolist() == [beam]
    assert scan.ranges[beam] == pytest.approx(1.5)
    # The beam's published angle is its bin centre: within half a degree of the wall's.
    published = {'sllidar': 180.0 - wall_deg, 'rep103': -wall_deg}[orientation]
    centre_deg = math.degrees(scan.angle_min + beam * scan.angle_increment)
    assert (centre_deg - published + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=0.5)


@pytest.mark.parametrize('orientation', ['sllidar', 'rep103'])
def test_inverted_mirrors_the_fixed_beams(orientation):
    upright = fixed_scan(wall_turn(30.2), 360, False, orientation)
    inverted = fixed_scan(wall_turn(30.2), 360, True, orientation)
    # A bin centred at a is centred at -a mirrored: beam i <-> beam 359 - i.
    np.testing.assert_array_equal(inverted.ranges, upright.ranges[::-1])


def test_the_fixed_scan_has_the_same_beams_every_turn_whatever_the_samples():
    rng = np.random.default_rng(5)
    for count in (411, 926, 1500, 2000):
        scan = fixed_scan(random_turn(rng, count), 720, False, 'sllidar')
        assert len(scan.ranges) == len(scan.intensities) == 720
        assert scan.angle_increment == pytest.approx(math.pi / 360)
        assert (scan.angle_min, scan.angle_max) == pytest.approx(
            (-math.pi + math.pi / 720, math.pi - math.pi / 720))
        assert scan.time_increment == pytest.approx(0.1 / 720) and scan.scan_time == 0.1


def test_each_fixed_beam_holds_the_sample_nearest_its_centre():
    # Bin 0 of 4 spans [-180, -90) degrees published, centre -135: in sllidar's frame raw
    # 180 - published, so raw 315 is the centre, raw 300 and 340 off by 15 and 25 degrees.
    turn = Turn(np.array([300.0, 340.0, 100.0, 101.0]), np.array([1000.0, 2000.0, 0.0, 3000.0]),
                np.array([10, 20, 30, 40], np.uint8), 0.0, 0.1, 0.1)
    scan = fixed_scan(turn, 4, False, 'sllidar')
    assert scan.ranges[0] == pytest.approx(1.0) and scan.intensities[0] == 10
    # Bin 2 spans [0, 90): raw (90, 180]; raw 101 is nearer its centre (raw 135) than raw 100,
    # which had no return anyway.
    assert scan.ranges[2] == pytest.approx(3.0)
    # No sample in bins 1 ([-90, 0): raw (180, 270]) and 3 ([90, 180): raw (0, 90]): NaN, no
    # measurement (REP-117); a sample without a return is +inf.
    assert np.isnan(scan.ranges[[1, 3]]).all()
    alone = Turn(np.array([100.0]), np.array([0.0]), np.array([5], np.uint8), 0.0, 0.1, 0.1)
    assert np.isinf(fixed_scan(alone, 4, False, 'sllidar').ranges[2])


def test_rep103_turns_the_per_sample_scan_by_pi_and_keeps_its_ranges():
    turn = random_turn(np.random.default_rng(9), 926)
    for compensate in (False, True):
        sllidar = turn_to_scan(turn, compensate, False, 3, 'sllidar')
        rep103 = turn_to_scan(turn, compensate, False, 3, 'rep103')
        assert rep103.angle_min == pytest.approx(sllidar.angle_min - math.pi)
        assert rep103.angle_max == pytest.approx(sllidar.angle_max - math.pi)
        np.testing.assert_array_equal(rep103.ranges, sllidar.ranges)


def test_an_unknown_orientation_is_refused():
    with pytest.raises(ValueError, match='orientation must be one of'):
        fixed_scan(wall_turn(10.0), 360, False, 'ned')
    with pytest.raises(ValueError, match='orientation must be one of'):
        turn_to_scan(wall_turn(10.0), False, False, 3, 'ned')


def stream(angles, start=None, slot=None):
    """Return samples (one per 5-byte frame) at the given angles, in the given slots."""
    n = len(angles)
    slot = np.arange(n) if slot is None else np.asarray(slot)
    return Samples(angle_deg=np.asarray(angles, float), distance_mm=np.full(n, 1000.0),
                   quality=np.full(n, 47, np.uint8),
                   start=np.zeros(n, bool) if start is None else np.asarray(start),
                   frame_end=(slot + 1) * 5, samples_after=np.zeros(n, np.int64), slot=slot)


def push_in_pieces(assembler, samples, received, pieces):
    """Push samples in ``pieces`` consecutive parts, as reads deliver them; return the turns."""
    turns = []
    for part in np.array_split(np.arange(len(samples)), pieces):
        piece = Samples(*(getattr(samples, f)[part] for f in Samples.__dataclass_fields__))
        turns += assembler.push(piece, received[part])
    return turns


def test_turns_split_at_the_wrap_and_the_first_partial_turn_is_dropped():
    step = 360.0 / 400
    angles = (200.0 + step * np.arange(1300)) % 360.0
    samples = stream(angles, start=np.r_[False, np.diff(angles) < 0])
    turns = push_in_pieces(TurnAssembler(244.0, 0.0), samples, np.zeros(1300), 7)
    assert [len(t.angle_deg) for t in turns] == [400, 400]
    for turn in turns:
        assert turn.angle_deg[0] < step and turn.angle_deg[-1] > 360.0 - step
        assert turn.period_s == pytest.approx(400 * 244e-6)


def test_a_corrupted_start_flag_does_not_split_and_a_lost_start_sample_does_not_merge():
    step = 360.0 / 400
    angles = (step * np.arange(1, 1601)) % 360.0
    start = np.r_[False, np.diff(angles) < 0]
    start[600] = True                  # an S bit set by corruption in mid-turn
    lost = 799                         # the start node of the second full turn never arrives
    assert start[lost] and start[399] and start[1199]
    keep = np.arange(1600) != lost
    samples = stream(angles[keep], start[keep])
    turns = TurnAssembler(244.0, 0.0).push(samples, np.zeros(keep.sum()))
    # The partial turn before the first wrap is dropped; the second lost its first sample.
    assert [len(t.angle_deg) for t in turns] == [400, 399, 400]


def test_a_gap_longer_than_a_turn_still_ends_the_turn():
    step, sample_s = 360.0 / 400, 244e-6
    index = np.arange(2000)
    keep = (index < 1000) | (index > 1450)      # 1.1 turns lost: from 180 deg to 225 deg
    angles = (step * index[keep]) % 360.0
    samples = stream(angles, np.r_[False, np.diff(angles) < 0], slot=index[keep])
    # In pieces: the angle per sample is known once the first turn has closed.
    turns = push_in_pieces(TurnAssembler(244.0, 0.0), samples, index[keep] * sample_s, 20)
    # After the dropped partial turn: one whole turn, one cut short at 179.1 deg by the gap,
    # then the turn after the lost one, from 225.9 deg (not merged with the one before).
    assert [len(t.angle_deg) for t in turns] == [400, 200, 149]
    assert turns[2].angle_deg[0] == pytest.approx(225.9)


def test_stamp_is_the_first_sample_time_despite_late_reads():
    rng = np.random.default_rng(3)
    sample_s, per_frame = 108e-6, 40
    n_frames = 100
    angles = (np.arange(n_frames * per_frame) * 0.3887) % 360.0
    measured = np.arange(n_frames * per_frame) * sample_s + 5.0          # true sample times
    frame_last = measured.reshape(n_frames, per_frame)[:, -1]
    # Frames arrive after transmission; reads see them up to 10 ms late, never early.
    received = np.repeat(frame_last + 0.003 + rng.uniform(0, 0.01, n_frames), per_frame)
    received[::per_frame * 7] = np.repeat(frame_last + 0.003, per_frame)[::per_frame * 7]
    samples = Samples(angle_deg=angles, distance_mm=np.ones(angles.size),
                      quality=np.ones(angles.size, np.uint8), start=np.zeros(angles.size, bool),
                      frame_end=np.repeat(np.arange(1, n_frames + 1) * 84, per_frame),
                      samples_after=np.tile(np.arange(per_frame - 1, -1, -1), n_frames),
                      slot=np.arange(angles.size))
    turns = TurnAssembler(108.0, 0.003).push(samples, received)
    assert len(turns) == 3           # 4.3 turns, of which the first is partial
    for turn in turns:
        first = measured[np.flatnonzero(angles == turn.angle_deg[0])[0]]
        assert turn.first_sample_s == pytest.approx(first, abs=1e-6)
        assert turn.period_s == pytest.approx(360.0 / 0.3887 * sample_s)


def test_a_turn_that_never_ends_is_dropped_not_grown():
    assembler = TurnAssembler(108.0, 0.0, max_samples=1000)
    angles = np.linspace(10.0, 20.0, 3000)
    assert assembler.push(stream(angles), np.zeros(3000)) == []
    assert assembler.dropped_turns >= 1


@pytest.mark.parametrize('rate_error', [0.0, 0.005, -0.005])
def test_the_sample_clock_holds_through_late_reads_and_follows_the_devices_rate(rate_error):
    rng = np.random.default_rng(4)
    nominal_s = 108e-6
    clock = SampleClock(nominal_s)
    true_s = nominal_s * (1.0 + rate_error)
    # 15 s of reads every 50 ms, each of 12 capsules; the reads are 0-30 ms late (a loaded
    # reader), 1 in 10 prompt.
    for read in range(300):
        slots = read * 480 + np.arange(480)
        late = rng.uniform(0.0, 0.03) if read % 10 else rng.uniform(0.0, 2e-4)
        clock.add(slots, 5.0 + (slots + 1) * true_s + late)
        if read > 20:
            # Stamps exact to the late reads' noise: a prompt read within the last 2 s holds.
            assert clock.time_s(slots[0]) - (5.0 + (slots[0] + 1) * true_s) == pytest.approx(
                0.0, abs=3e-4 if read > 220 or not rate_error else 0.011)
    assert clock.period_s == pytest.approx(true_s, rel=1e-4)
