# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``calibrate``, ``evaluate`` and ``score`` decide with one stillness test and one association rule.

On a real moving recording (the part of ``urg04lx_office`` where the sensor is carried, copied
into a bag as recorded) every tool refuses with the measured drift against its bound and exit
status 2; on the same still recording and configuration they report the same corners per scan;
and a tool that has nothing to measure a NEES on says so with a non-zero status instead of
printing NaN or skipping its check.
"""

import math
import re

from conftest import REAL_DATA
import pytest
from scan_bags import real_scans_slice
from wctls_lab.evaluation import check_still, load_scans

pytestmark = pytest.mark.slow

# Scans 100-229 of the office recording: carried across the room, 20 cm of drift.
CARRIED = (100, 230)
LMS1XX = REAL_DATA / 'sick_lms1xx_static'
# A still sensor in front of one straight wall: no corner anywhere.
ONE_WALL = {'name': 'one_wall', 'polylines': [{'closed': False,
                                               'points': [[-3.0, 1.5], [3.0, 1.5]]}],
            'sensor': {'x': 0.0, 'y': 0.0, 'yaw_deg': 0.0}}


@pytest.fixture(scope='module')
def carried_bag(tmp_path_factory):
    pytest.importorskip('rclpy')
    return real_scans_slice('urg04lx_office', *CARRIED,
                            tmp_path_factory.mktemp('carried') / 'office_carried')


@pytest.fixture(scope='module')
def one_wall_bag(tmp_path_factory):
    pytest.importorskip('rclpy')
    import yaml
    from wctls_lab.evaluation.simulate_cli import main
    plan = tmp_path_factory.mktemp('plans') / 'one_wall.yaml'
    plan.write_text(yaml.safe_dump(ONE_WALL))
    path = tmp_path_factory.mktemp('bags') / 'one_wall'
    assert main([str(plan), str(path), '--scans', '30', '--seed', '2', '--range-sigma', '0.01',
                 '--bearing-sigma-deg', '0.05']) == 0
    return path


def _refusal(capsys, tool):
    error = capsys.readouterr().err.strip().splitlines()
    assert error, f'{tool} printed no reason'
    return error[-1]


def test_the_carried_part_of_the_office_recording_is_moving(carried_bag):
    check = check_still(load_scans(carried_bag))
    assert not check.still
    assert check.drifted_fraction > 0.5
    assert check.median_drift_m > 0.1 > 2 * check.median_bound_m


def test_keyframes_far_apart_are_moving_though_no_drift_stands_out():
    from wctls_lab.evaluation import StaticScans
    from wctls_lab.evaluation.rules import MOVING_FRACTION, MOVING_NOISE_RATIO
    office = load_scans(REAL_DATA / 'urg04lx_office')
    # Every 10th scan of the carried part: 22 keyframes, 10-40 cm apart.
    keyframes = StaticScans(office.ranges[30:250:10], office.angle_min, office.angle_increment,
                            office.range_min, office.range_max, office.stamps_ns[30:250:10])
    check = check_still(keyframes)
    assert check.drifted_fraction <= MOVING_FRACTION          # the drift alone would pass it
    assert check.noise_ratio > MOVING_NOISE_RATIO and not check.still
    for still in ('sick_lms1xx_static', 'sick_lms111_static'):
        assert check_still(load_scans(REAL_DATA / still)).noise_ratio < MOVING_NOISE_RATIO / 1.5


def test_a_car_driving_laps_has_no_beam_to_compare_and_says_so():
    # The moving RPLIDAR: no beam returns in nearly every scan, so no drift can be measured;
    # the figures of a comparison (100 % of 0 beams, an infinite median drift) would say nothing.
    check = check_still(load_scans(REAL_DATA / 'rplidar_barc_moving'))
    assert (check.steady_beams, check.still) == (0, False)
    assert check.describe().endswith('not shown to be still') and 'inf' not in check.describe()


@pytest.mark.parametrize('tool', ['calibrate', 'evaluate', 'score'])
def test_every_tool_refuses_a_moving_sensor_with_the_drift_and_its_bound(carried_bag, tmp_path,
                                                                         capsys, tool):
    from wctls_lab.evaluation import calibrate_cli, evaluate_cli, score_cli
    run = {'calibrate': lambda: calibrate_cli.main([str(carried_bag)]),
           'evaluate': lambda: evaluate_cli.main([str(carried_bag), '--out',
                                                  str(tmp_path / 'out')]),
           'score': lambda: score_cli.main([str(carried_bag), '--methods', 'wctls'])}[tool]
    capsys.readouterr()
    assert run() == 2
    captured = capsys.readouterr()
    error = captured.err.strip().splitlines()[-1]
    assert error.startswith(f'{tool}: error:'), error
    assert 'moved' in error or 'not still' in error, error
    drift = re.search(r'median drift ([\d.]+) mm against a bound of ([\d.]+) mm', error)
    assert drift, error
    assert float(drift[1]) > 100.0 and float(drift[2]) < 60.0, error
    assert 'feature_node:' not in captured.out               # calibrate: no model printed
    assert not (tmp_path / 'out').exists()


def _corners_per_scan(text, pattern):
    found = re.findall(pattern, text)
    assert found, text
    return {float(value) for value in found}


def test_the_three_tools_report_the_same_corners_per_scan(capsys, tmp_path):
    from wctls_lab.evaluation import calibrate_cli, evaluate_cli, score_cli
    from wctls_lab.evaluation.score_cli import node_config
    method = node_config(None, 'sick_lms1xx').method
    capsys.readouterr()
    calibrate_cli.main(['--sensor', 'sick_lms1xx', '--validate', str(LMS1XX)])
    calibrated = _corners_per_scan(capsys.readouterr().out, r'# corners per scan ([\d.]+) with')
    assert evaluate_cli.main([str(LMS1XX), '--sensor', 'sick_lms1xx', '--methods', method,
                              '--out', str(tmp_path / 'evaluate')]) == 0
    evaluated = _corners_per_scan(capsys.readouterr().out,
                                  rf'{method}\s+corners per scan ([\d.]+)')
    assert score_cli.main([str(LMS1XX), '--sensor', 'sick_lms1xx', '--methods', method]) == 0
    scored = _corners_per_scan(capsys.readouterr().out,
                               rf'# {method}: corners per scan ([\d.]+)')
    assert calibrated == evaluated == scored, (calibrated, evaluated, scored)
    assert math.isfinite(calibrated.pop())


def test_evaluate_without_an_associated_corner_exits_non_zero(one_wall_bag, tmp_path, capsys):
    from wctls_lab.evaluation.evaluate_cli import main, NO_CORNER_EXIT
    capsys.readouterr()
    assert main([str(one_wall_bag), '--out', str(tmp_path / 'out'), '--methods', 'wctls',
                 '--range-sigma', '0.01']) == NO_CORNER_EXIT
    error = capsys.readouterr().err
    assert 'no NEES for wctls' in error and 'no corner' in error
    assert not (tmp_path / 'out').exists()


def test_calibrate_without_a_stable_corner_cannot_validate_and_exits_non_zero(
        one_wall_bag, capsys):
    from wctls_lab.evaluation.calibrate_cli import IMPLAUSIBLE_EXIT, main
    capsys.readouterr()
    assert main([str(one_wall_bag)]) == IMPLAUSIBLE_EXIT
    captured = capsys.readouterr()
    assert 'no stable corner' in captured.err and 'cannot be validated' in captured.err
    assert 'feature_node:' not in captured.out


def test_score_tests_a_moving_sensors_re_observations_when_told_it_moves(carried_bag, capsys):
    from wctls_lab.evaluation.score_cli import main
    capsys.readouterr()
    assert main([str(carried_bag), '--methods', 'wctls', '--still', 'no']) == 0
    out = capsys.readouterr().out
    assert 'recurrence refused: it needs a still sensor' in out
    tested = re.search(r'corner distances [\d.]+ % of (\d+), line angles [\d.]+ % of (\d+), '
                       r'corner-line distances [\d.]+ % of (\d+)', out)
    assert tested and min(int(n) for n in tested.groups()) >= 100, out
