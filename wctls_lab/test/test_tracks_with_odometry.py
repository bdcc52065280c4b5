# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The tracker driven by the odometry's own steps (``score --tracks --odometry``).

run_tracker takes the motions it is given instead of the poses' steps: given those very steps
it tracks as it does from the poses, and the poses then only judge. On a slice of the RPLIDAR
car, score prints the tracks twice, from the poses' steps and from the odometry's.
"""

import math
import re

import pytest
from scan_bags import real_bag
from wctls_lab.evaluation import load_scans
from wctls_lab.evaluation.score_cli import main
from wctls_lab.evaluation.tracks import run_tracker
from wctls_ros.frontend.poses import load_poses, poses_at
from wctls_ros.frontend.tracking import steps_from_poses
from wctls_ros.params import feature_settings, load_parameters

CAR = 'rplidar_barc_moving'
SCANS = 60
STEP_SIGMA_M, STEP_SIGMA_RAD = 0.02, math.radians(1.0)


@pytest.fixture(scope='module')
def car():
    """Return the car's first scans, the laser's poses at them and the rplidar_a2 settings."""
    scans = load_scans(real_bag(CAR), limit=SCANS)
    poses = poses_at(load_poses(real_bag(CAR) / 'poses.csv'), scans.stamps_ns * 1e-9,
                     (-0.12, 0.0, 0.0))
    return scans, poses, feature_settings(load_parameters(None))[0]


def test_given_the_poses_steps_the_tracker_tracks_as_from_the_poses(car):
    scans, poses, config = car
    from_poses = run_tracker(scans, config, poses, STEP_SIGMA_M, STEP_SIGMA_RAD)
    given = run_tracker(scans, config, poses,
                        motions=steps_from_poses(poses, STEP_SIGMA_M, STEP_SIGMA_RAD))
    assert sum(len(scan.lines.ids) for scan in from_poses.tracked) > SCANS   # lines tracked

    def identities(run):
        return [(list(scan.corners.ids), list(scan.lines.ids)) for scan in run.tracked]
    assert identities(given) == identities(from_poses)
    with pytest.raises(ValueError, match='59 motions for 60 scans'):
        run_tracker(scans, config, poses, motions=steps_from_poses(poses[1:], 0.0, 0.0))


def test_score_tracks_the_landmarks_from_the_poses_and_from_the_odometry(capsys):
    bag = real_bag(CAR)
    assert main([str(bag), '--still', 'no', '--poses', str(bag / 'poses.csv'),
                 '--laser-offset', '-0.12', '0', '0', '--methods', 'wctls', '--scans',
                 f'0-{SCANS - 1}', '--tracks', '--odometry']) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if ' tracks: ' in line]
    headers = [line for line in lines if 'tracker' in line and 'ms per scan' in line]
    assert len(headers) == 2 and 'steps of sigma' in headers[0]
    assert 'steps and covariances of the odometry' in headers[1]
    figures = [line for line in lines if re.search(r': (corner|line): \d+ confirmed', line)]
    assert len(figures) == 4
    # The odometry's steps keep the car's line landmarks: some are confirmed.
    assert int(re.search(r'line: (\d+) confirmed', figures[3]).group(1)) > 0
