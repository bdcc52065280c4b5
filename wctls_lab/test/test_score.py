# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The score: exact answers on constructed detections, the truth format, and the command.

Detections are built by hand (positions and covariances), so every figure has a known value:
an injected false corner gives an exact precision, a missed corner an exact recall, a known
error over a known covariance an exact NEES, and hand-built presence patterns an exact
recurrence.
"""

import math
import subprocess
import sys

from conftest import REAL_DATA
import numpy as np
import pytest
from scan_bags import simulated_bag
from wctls_lab.evaluation import (load_truth, match_detections, ScanCorners, score_detections,
                                  score_scans, StaticScans, Truth, truth_from_dict,
                                  truth_from_recording, truth_to_yaml, TruthError)
from wctls_lab.simulation import load_floor_plan, NoiseModel, simulate_recording

SIGMA = 0.01                      # 1 cm per axis: every constructed covariance
TRUE_XY = np.array([[1.0, 0.0], [0.0, 2.0], [-1.5, 0.0], [0.0, -1.0]])


def detections(xy, sigma=SIGMA):
    """Return one scan's detections at the given positions with a round covariance."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    covariance = np.repeat(sigma ** 2 * np.eye(2)[None], len(xy), axis=0)
    return ScanCorners(xy, covariance, covariance, np.zeros((len(xy), 2), dtype=np.intp))


def static_truth(xy=TRUE_XY, visible=None):
    """Return a still sensor's truth of some corners (all visible unless said)."""
    xy = np.asarray(xy, dtype=float)
    visible = np.ones((1, len(xy)), dtype=bool) if visible is None else np.asarray(visible)
    return Truth(np.arange(len(xy)), ('inside',) * len(xy), xy[None], visible)


def test_perfect_detections_score_one_and_a_known_error_gives_its_nees():
    # Every corner found 1 cm off along x in 10 scans, sigma 1 cm: NEES exactly 1 each.
    per_scan = [detections(TRUE_XY + [SIGMA, 0.0]) for _ in range(10)]
    score = score_detections('wtls', per_scan, static_truth())
    assert score.precision == 1.0 and score.recall == 1.0
    np.testing.assert_allclose(score.nees_truth, 1.0)
    assert score.summary()['false_per_scan'] == 0.0
    assert all(c.rate == 1.0 for c in score.corner_rates)


def test_an_injected_false_corner_gives_the_exact_precision():
    per_scan = [detections(np.vstack([TRUE_XY, [[5.0, 5.0]]])) for _ in range(8)]
    score = score_detections('wtls', per_scan, static_truth())
    assert score.precision == pytest.approx(4 / 5)
    assert score.recall == 1.0 and score.summary()['false_per_scan'] == 1.0


def test_a_missed_corner_gives_the_exact_recall():
    per_scan = [detections(TRUE_XY[:3]) for _ in range(6)] + [detections(TRUE_XY)] * 2
    score = score_detections('wtls', per_scan, static_truth())
    assert score.recall == pytest.approx((6 * 3 + 2 * 4) / (8 * 4))
    assert score.precision == 1.0
    assert [c.rate for c in score.corner_rates] == [1.0, 1.0, 1.0, 0.25]


def test_a_corner_not_visible_counts_for_precision_but_not_for_recall():
    visible = [[True, True, False, False]]
    score = score_detections('wtls', [detections(TRUE_XY[:3])] * 4,
                             static_truth(visible=visible))
    assert score.precision == 1.0                # the third corner is real, merely hard
    assert score.recall == 1.0                   # only the two visible ones are asked for
    assert [c.visible_scans for c in score.corner_rates] == [4, 4, 0, 0]


def test_matching_is_nearest_first_one_to_one_within_max_of_3_sigma_and_5_cm():
    truth = np.array([[0.0, 0.0], [1.0, 0.0]])
    # Two detections near the first corner: the nearer takes it, the other matches nothing.
    match = match_detections([[0.03, 0.0], [0.01, 0.0], [1.049, 0.0]],
                             np.repeat(1e-6 * np.eye(2)[None], 3, axis=0), truth)
    assert match.tolist() == [-1, 0, 1]
    # 6 cm off: outside the 5 cm floor with sigma 1 mm, inside 3 sigma with sigma 3 cm.
    far = [[0.06, 0.0]]
    assert match_detections(far, [1e-6 * np.eye(2)], truth).tolist() == [-1]
    assert match_detections(far, [9e-4 * np.eye(2)], truth).tolist() == [0]
    # The major axis sets the gate whatever its direction.
    elongated = np.array([[[9e-4, 0.0], [0.0, 1e-8]]])
    assert match_detections([[0.0, 0.06]], elongated, truth).tolist() == [0]
    assert match_detections([[0.0, 0.06]], [np.eye(2) * 1e-8], truth).tolist() == [-1]


def test_recurrence_counts_detections_of_corners_present_in_90_percent_of_scans():
    rng = np.random.default_rng(0)
    scans = 20
    per_scan = []
    for t in range(scans):
        xy = [TRUE_XY[0]]                                 # in every scan
        if t < 18:
            xy.append(TRUE_XY[1])                         # in 90 % of the scans
        if t < 17:
            xy.append(TRUE_XY[2])                         # in 85 %: not recurring
        if t % 4 == 0:
            xy.append(rng.uniform(3.0, 9.0, 2))           # scattered false corners
        per_scan.append(detections(np.array(xy) + rng.normal(0.0, 1e-4, (len(xy), 2))))
    score = score_detections('wtls', per_scan)
    assert len(score.recurring) == 2
    assert score.recurrence == pytest.approx((20 + 18) / (20 + 18 + 17 + 5))
    assert sorted(c.scans for c in score.recurring) == [18, 20]
    assert score.precision != score.precision               # no truth: not measured (NaN)


def test_nees_against_the_mean_of_a_recurring_corner():
    # Alternating +-e along x: the mean is the true spot, every NEES is (e / sigma)^2.
    error = 0.5 * SIGMA
    per_scan = [detections([[1.0 + (error if t % 2 else -error), 2.0]]) for t in range(10)]
    score = score_detections('ml', per_scan)
    assert score.recurring[0].nees == pytest.approx((error / SIGMA) ** 2)
    np.testing.assert_allclose(score.recurring[0].xy_m, [1.0, 2.0])
    assert score.summary()['nees_vs_mean_pooled'] == pytest.approx(0.25)


def test_without_a_static_recording_recurrence_is_not_measured():
    score = score_detections('wtls', [detections(TRUE_XY)] * 3, static_truth(), static=False)
    assert score.recurring is None and math.isnan(score.recurrence)
    assert score.recall == 1.0


def test_truth_files_round_trip_and_select_scans():
    plan = load_floor_plan('environment_a_cluttered')
    recording = simulate_recording(plan, NoiseModel(0.01, 0.0), 6, seed=1)
    truth = truth_from_recording(recording, description='six scans')
    again = truth_from_dict(__import__('yaml').safe_load(truth_to_yaml(truth, 'header')))
    np.testing.assert_array_equal(again.xy_m, truth.xy_m)
    np.testing.assert_array_equal(again.visible, truth.visible)
    assert again.kinds == truth.kinds and again.description == 'six scans'
    assert truth.visible.shape == (6, len(plan.corners_m))      # the walker changes them
    part = truth.select(2, 3)
    np.testing.assert_array_equal(part.at(0)[1], truth.at(2)[1])
    assert part.covered(3) == (0, 2)
    moving = simulate_recording(plan, NoiseModel(0.01, 0.0), 3, velocity=(0.1, 0.0, 0.0))
    per_scan = truth_from_recording(moving)
    assert per_scan.per_scan
    again = truth_from_dict(__import__('yaml').safe_load(truth_to_yaml(per_scan)))
    np.testing.assert_allclose(again.xy_m, per_scan.xy_m)


@pytest.mark.parametrize('document, message', [
    ({'corners': [{'id': 0, 'x_m': 1.0, 'y_m': 0.0, 'kind': 'corner'}]}, 'kind'),
    ({'corners': [{'id': 0, 'x_m': 1.0, 'y_m': 0.0, 'kind': 'inside'}] * 2}, 'given twice'),
    ({'corners': [{'id': 0, 'x_m': 'far', 'y_m': 0.0, 'kind': 'inside'}]}, 'x_m'),
    ({'corners': [], 'visible': [[3]]}, 'not among'),
    ({'corners': [], 'labels': []}, 'unknown keys'),
    ({'corners': [], 'scans': [5, 2]}, 'first <= last'),
    ({'frame_id': 'laser'}, "either 'corners'"),
    ('just text', 'mapping'),
])
def test_malformed_truth_is_refused_with_where_and_why(document, message):
    with pytest.raises(TruthError, match=message):
        truth_from_dict(document, 'labels.yaml')


def test_score_scans_on_simulated_scans_finds_the_walls_corners():
    plan = load_floor_plan('environment_a')
    recording = simulate_recording(plan, NoiseModel(0.01, math.radians(0.05)), 12, seed=2)
    scans = StaticScans(recording.ranges, recording.angle_min, recording.angle_increment, 0.05,
                        40.0, np.arange(12))
    from wctls_ros.core import FeatureConfig
    config = FeatureConfig(range_sigma_m=0.01, bearing_sigma_rad=math.radians(0.05))
    table = score_scans(scans, {'wtls': config.replace(method='wtls')},
                        truth_from_recording(recording))
    score = table.methods[0]
    print(score.summary())
    # The clean room at 1 cm: (nearly) every visible corner found, (nearly) nothing false.
    assert score.recall > 0.95 and score.precision > 0.95 and table.static
    assert 1.0 < score.summary()['nees_truth_mean'] < 4.0 and score.recurrence > 0.9


@pytest.fixture(scope='module')
def cluttered_bag(tmp_path_factory):
    pytest.importorskip('rclpy')
    return simulated_bag(tmp_path_factory.mktemp('score'), 'environment_a_cluttered', 12, 4,
                         's1_like')


def test_the_command_finds_the_truth_beside_the_bag_and_writes_the_report(cluttered_bag,
                                                                          tmp_path, capsys):
    from wctls_lab.evaluation.score_cli import main
    truth = load_truth(cluttered_bag / 'truth.yaml')
    assert truth.visible.shape[0] == 12 and 'environment_a_cluttered' in truth.description
    out = tmp_path / 'report'
    assert main([str(cluttered_bag), '--methods', 'wtls,ml', '--range-sigma', '0.02',
                 '--bearing-sigma-deg', '0.1', '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    assert '| wtls | 12 |' in printed and '| ml | 12 |' in printed
    assert 'truth.yaml (38 corners)' in printed
    rows = (out / 'table.csv').read_text().splitlines()
    assert len(rows) == 3 and rows[0].startswith('method,scans,detections_per_scan')
    assert (out / 'score.png').read_bytes().startswith(b'\x89PNG')
    assert 'score ' in (out / 'table.md').read_text()


@pytest.mark.parametrize('arguments, message', [
    (['{bag}', '--labels', '{tmp}/none.yaml'], 'no such label'),
    (['{tmp}/no_bag'], 'no such bag'),
    (['{bag}', '--methods', 'tls'], 'unknown methods'),
    (['{bag}', '--scans', '3-1'], 'FIRST-LAST'),
    (['{bag}', '--scans', '0-40'], 'has 12'),
    (['{bag}', '--labels', '{tmp}/bad.yaml'], 'kind'),
    (['{bag}', '--config', '{tmp}/bad.yaml'], 'feature_node'),
    (['{bag}', '--range-sigma', '-1'], 'range_sigma_m'),
])
def test_bad_input_exits_2_with_one_line(cluttered_bag, tmp_path, capsys, arguments, message):
    from wctls_lab.evaluation.score_cli import main
    (tmp_path / 'bad.yaml').write_text('corners: [{id: 0, x_m: 1, y_m: 0, kind: odd}]\n')
    argv = [a.format(bag=cluttered_bag, tmp=tmp_path) for a in arguments]
    assert main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith('score: error:') and len(error.splitlines()) == 1
    assert message in error


def test_a_moving_sensor_without_truth_is_refused(tmp_path, capsys):
    pytest.importorskip('rclpy')
    from wctls_lab.evaluation.score_cli import main
    from wctls_lab.evaluation.simulate_cli import main as simulate
    bag = tmp_path / 'moving'
    assert simulate(['environment_a', str(bag), '--scans', '12', '--sensor', '1cm',
                     '--velocity', '0.2', '0.0', '0.1']) == 0
    (bag / 'truth.yaml').unlink()
    capsys.readouterr()
    assert main([str(bag)]) == 2
    assert 'not still' in capsys.readouterr().err


def test_the_command_runs_without_ros_and_documents_its_defaults(cluttered_bag):
    code = ('import sys; from wctls_lab.evaluation.score_cli import main; '
            f'code = main([{str(cluttered_bag)!r}, "--methods", "wtls", "--scans", "0-5"]); '
            'assert "rclpy" not in sys.modules, "rclpy imported"; sys.exit(code)')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    from wctls_lab.evaluation.score_cli import parser
    text = parser().format_help()
    assert '(default: utls,wtls,wctls,ml)' in text and '(default: 0.9)' in text


LABELS = REAL_DATA / 'labels'


@pytest.mark.parametrize('name', ['sick_lms111_static', 'sick_lms1xx_static', 'urg04lx_office'])
def test_hand_labels_are_the_intersections_of_their_listed_walls(name):
    import yaml
    from wctls_lab.evaluation import load_scans
    from wctls_lab.evaluation.truth import corner_from_beams, median_scan
    path = LABELS / f'{name}.yaml'
    truth = load_truth(path)
    document = yaml.safe_load(path.read_text())
    scans = load_scans(path.parent / document['recording'])
    first, last = truth.covered(len(scans))
    ranges = median_scan(scans.ranges[first:last + 1], scans.valid()[first:last + 1])
    for corner, xy in zip(document['corners'], truth.xy_m[0]):
        np.testing.assert_allclose(corner_from_beams(ranges, scans.bearings, corner['walls']),
                                   xy, atol=1e-4)
    # Every corner the labeller saw: the current extractor finds it in nearly every scan.
    from wctls_ros.core import FeatureConfig
    table = score_scans(StaticScans(scans.ranges[first:last + 1], scans.angle_min,
                                    scans.angle_increment, scans.range_min, scans.range_max,
                                    scans.stamps_ns[first:last + 1]),
                        {'wtls': FeatureConfig(method='wtls')},
                        truth.select(first, last - first + 1), static=False)
    rates = [c.rate for c in table.methods[0].corner_rates if c.visible_scans]
    assert rates and min(rates) >= 0.9, rates


@pytest.mark.parametrize('name,recurrence', [('sick_lms111_static', 0.5),
                                             ('sick_lms1xx_static', 0.75)])
def test_the_shipped_default_meets_the_real_static_targets(name, recurrence):
    # The corner targets on the real static recordings, with what a user gets out of the box: every
    # labelled visible corner in >= 95 % of the scans, and most detections on corners present
    # in most scans (recurrence), for every method. Measured 0.53-0.99 and 0.78: the LMS111's
    # two corners hidden behind small objects (labelled real) pass the corner tests in about
    # half the scans since the decisions tolerate the model error (precision stays 1.000).
    from wctls_lab.evaluation import load_scans
    from wctls_ros.params import feature_settings, load_parameters
    truth = load_truth(LABELS / f'{name}.yaml')
    scans = load_scans(REAL_DATA / name)
    default = feature_settings(load_parameters(None))[0]
    methods = {method: default.replace(method=method) for method in ('utls', 'wtls', 'ml')}
    table = score_scans(scans, methods, truth, static=True)
    for method in table.methods:
        summary = method.summary()
        assert summary['min_corner_rate'] >= 0.95, (method.method, summary)
        assert summary['recurrence'] >= recurrence, (method.method, summary)
        assert summary['precision'] >= 0.9, (method.method, summary)
