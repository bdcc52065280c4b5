# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
process_bag --tracks: a LandmarkArray every scan and landmarks.csv, the ids the tracker gives.

On the still LMS1xx recording every scan gets one /landmarks message (empty ones too), the CSV
holds the issue's columns and the same ids, states and poses as the messages, the markers on
/landmark_markers label the same ids, and a still corner keeps its id through the recording.
On a slice of the moving RPLIDAR car, with its pose file, the ids are those the tracker library
gives with the same poses and step sigmas
(:func:`~wctls_lab.evaluation.tracks.run_tracker`): the tool composes the laser's offset and
the steps as the library does. Bad uses are refused with the reason.
"""

import csv
import math

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, Stores
from scan_bags import real_bag, real_scans_slice
from wctls_lab.evaluation import load_scans
from wctls_lab.evaluation.tracks import run_tracker
from wctls_ros.bags.process_bag import main
from wctls_ros.frontend.poses import load_poses, poses_at
from wctls_ros.landmark_messages import LANDMARK_COLUMNS
from wctls_ros.params import feature_settings, load_parameters

ISSUE_COLUMNS = ('stamp_s,id,kind,state,x_m,y_m,yaw_rad,cov_xx,cov_xy,cov_xyaw,cov_yy,'
                 'cov_yyaw,cov_yawyaw,hits')


def topic_messages(path, topic, msgtype):
    """Return the messages of one topic of an output bag, read with its own definitions."""
    with AnyReader([path], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        assert connections and connections[0].msgtype == msgtype
        return [reader.deserialize(raw, c.msgtype)
                for c, _, raw in reader.messages(connections=connections)]


def landmark_messages(path):
    return topic_messages(path, '/landmarks', 'wctls_msgs/msg/LandmarkArray')


def csv_rows(path):
    with open(path / 'landmarks.csv', newline='') as stream:
        return list(csv.DictReader(stream))


def test_tracks_give_a_landmark_array_every_scan_and_the_same_rows(tmp_path):
    out = tmp_path / 'out'
    assert main([str(real_bag('sick_lms1xx_static')), '-o', str(out), '--tracks', '-j',
                 '1']) == 0
    messages = landmark_messages(out)
    assert len(messages) == 89
    assert ','.join(LANDMARK_COLUMNS) == ISSUE_COLUMNS
    with open(out / 'landmarks.csv') as stream:
        assert stream.readline().strip() == ISSUE_COLUMNS
    rows = csv_rows(out)
    flat = [landmark for message in messages for landmark in message.landmarks]
    assert len(rows) == len(flat) > 89
    for row, landmark in zip(rows, flat):
        assert int(row['id']) == landmark.id >= 1
        assert row['kind'] == ('corner', 'line')[landmark.kind]
        assert row['state'] == ('tentative', 'confirmed')[landmark.state]
        assert int(row['hits']) == landmark.hits
        assert float(row['x_m']) == pytest.approx(landmark.pose.pose.position.x)
        assert float(row['cov_yawyaw']) == pytest.approx(landmark.pose.covariance[35])
    # The markers label every detection with its id, after a DELETEALL.
    markers = topic_messages(out, '/landmark_markers', 'visualization_msgs/msg/MarkerArray')
    assert [[int(m.text) for m in array.markers[1:]] for array in markers] == [
        [landmark.id for landmark in message.landmarks] for message in messages]
    assert all(array.markers[0].action == 3 for array in markers)        # DELETEALL
    # The labelled north-east corner is seen in nearly every scan, under one id.
    confirmed = [int(row['id']) for row in rows
                 if row['kind'] == 'corner' and row['state'] == 'confirmed']
    ids, counts = np.unique(confirmed, return_counts=True)
    assert counts.max() >= 80, dict(zip(ids, counts))


def test_tracks_with_poses_are_the_librarys(tmp_path):
    bag = real_scans_slice('rplidar_barc_moving', 0, 60, tmp_path / 'slice')
    poses_file = real_bag('rplidar_barc_moving') / 'poses.csv'
    out = tmp_path / 'out'
    assert main([str(bag), '-o', str(out), '--tracks', '--poses', str(poses_file),
                 '--laser-offset', '-0.12', '0', '0', '--step-sigma', '0.02', '1', '-j',
                 '2']) == 0
    rows = csv_rows(out)
    scans = load_scans(bag)
    poses = poses_at(load_poses(poses_file), scans.stamps_ns * 1e-9, (-0.12, 0.0, 0.0))
    config = feature_settings(load_parameters(None))[0]
    run = run_tracker(scans, config, poses, 0.02, math.radians(1.0))
    expected = [int(track) for scan in run.tracked
                for track in np.concatenate([scan.corners.ids, scan.lines.ids])]
    assert [int(row['id']) for row in rows] == expected
    assert len(set(expected)) < len(expected) / 3      # the ids recur: tracks, not detections


@pytest.mark.parametrize('arguments,message', [
    (['--tracks', '--method', 'all'], 'one method'),
    (['--tracks', '--poses', 'POSES'], 'not the scan at'),
    (['--tracks', '--step-sigma', '-1', '1'], 'two sigmas >= 0'),
])
def test_bad_uses_of_tracks_are_refused_with_the_reason(tmp_path, capsys, arguments, message):
    poses = tmp_path / 'poses.csv'
    poses.write_text('stamp_s,x_m,y_m,yaw_rad\n1,0,0,0\n2,1,0,0\n')
    arguments = [str(poses) if a == 'POSES' else a for a in arguments]
    assert main([str(real_bag('sick_lms1xx_static')), '-o', str(tmp_path / 'out'), '-j', '1']
                + arguments) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()
