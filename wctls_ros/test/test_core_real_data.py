# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The pipeline on real static SICK recordings: repeatable corners, and their real scatter.

The LMS111 file holds 175 scans of a lab box from a sensor that never moves, so the scan-to-scan
scatter of a corner is its real estimation error (up to a constant bias). With a range sigma
estimated from the same data (per-beam std over the scans, about 8 mm) and independent per-beam
noise, the propagated covariance is too small for this sensor: the far corner scatters 1.5-1.7
times its predicted std, median NEES 1.9 (a calibrated 2D estimate has median 2 ln 2 = 1.39 and
mean 2). The LMS111 adds a common-mode range offset to every beam of a scan (about 1 mm std,
slowly drifting: lag-1 correlation 0.8), which shifts every wall's radius together and which no
independent per-beam model can represent. The calibration tool of the evaluation package fits
that term; here the test pins down the measured gap so that a change in the propagation shows.
"""

from conftest import REAL_DATA
import numpy as np
import pytest
from wctls_ros.core import extract_features, FeatureConfig, nees

LMS111 = REAL_DATA / 'sick_lms111_static'


@pytest.fixture(scope='module')
def scans():
    rosbags = pytest.importorskip('rosbags.highlevel')
    from rosbags.typesys import get_typestore, Stores
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with rosbags.AnyReader([LMS111], default_typestore=typestore) as reader:
        return [reader.deserialize(raw, connection.msgtype)
                for connection, _, raw in reader.messages()]


@pytest.fixture(scope='module')
def range_sigma(scans):
    ranges = np.array([scan.ranges for scan in scans], dtype=float)
    steady = np.isfinite(ranges).all(axis=0)
    return float(np.median(ranges[:, steady].std(axis=0)))


def corner_tracks(scans, config):
    """Match every scan's corners to the first scan's (within 5 cm)."""
    features = [extract_features(np.asarray(s.ranges), s.angle_min, s.angle_increment, config,
                                 s.range_min, s.range_max) for s in scans]
    reference = features[0].corners.xy_m
    tracks = []
    for xy in reference:
        hits = []
        for f in features:
            distance = np.hypot(*(f.corners.xy_m - xy).T)
            if distance.size and distance.min() < 0.05:
                j = int(distance.argmin())
                hits.append((f.corners.xy_m[j], f.corners.covariance[j, :2, :2]))
        tracks.append(hits)
    return reference, tracks


def test_range_noise_estimated_from_the_data(range_sigma):
    assert 0.006 < range_sigma < 0.010      # the LMS111's ~8 mm


NEAR_CORNER = np.array([-0.05, -0.68])       # behind a small object, hand-labelled "hidden"


@pytest.mark.parametrize('method', ['utls', 'wtls', 'wctls', 'ml'])
def test_the_box_corner_in_view_is_found_in_every_scan_the_hidden_one_in_none(scans,
                                                                              range_sigma,
                                                                              method):
    config = FeatureConfig(method=method, range_sigma_m=range_sigma, bearing_sigma_rad=0.0)
    reference, tracks = corner_tracks(scans, config)
    far_corner = int(np.argmax(reference[:, 0]))       # the box corner at (1.34, 0.93) m
    assert np.allclose(reference[far_corner], [1.34, 0.93], atol=0.02)
    assert len(tracks[far_corner]) == len(scans)
    # The near corner joins a wall that passes 5 cm from the sensor to one behind a small
    # object whose returns, 5-38 mm in front of the first wall, stand between its end and the
    # corner: an occluded end, not a corner end. Before the corner end rule it was reported
    # in 172 of 175 scans, at times with the object's returns in the wall.
    features = [extract_features(np.asarray(s.ranges), s.angle_min, s.angle_increment, config,
                                 s.range_min, s.range_max) for s in scans]
    near = sum(bool(len(f.corners)) and np.hypot(*(f.corners.xy_m - NEAR_CORNER).T).min() < 0.05
               for f in features)
    assert near <= 3


def test_propagated_covariance_against_real_scatter(scans, range_sigma):
    config = FeatureConfig(method='wctls', range_sigma_m=range_sigma, bearing_sigma_rad=0.0)
    reference, tracks = corner_tracks(scans, config)
    track = tracks[int(np.argmax(reference[:, 0]))]
    xy = np.array([hit[0] for hit in track])
    covariance = np.array([hit[1] for hit in track])
    error = xy - xy.mean(axis=0)
    median_nees = float(np.median(nees(error, covariance)))
    predicted = np.sqrt(np.diag(covariance.mean(axis=0)))
    scatter = error.std(axis=0)
    print(f'far corner: scatter {scatter * 1e3} mm, predicted {predicted * 1e3} mm, '
          f'median NEES {median_nees:.2f}')
    # Measured: scatter (2.3, 2.4) mm vs predicted (1.4, 1.6) mm, median NEES 1.93: the
    # independent-noise model is too small by a factor 1.5-1.7 in std on this sensor.
    assert np.all((1.3 < scatter / predicted) & (scatter / predicted < 2.5))
    assert 1.6 < median_nees < 3.0


def near_wall_end(scans, config):
    """Return the last beam of the wall that ends at the object beside the near corner."""
    ends = []
    for s in scans:
        f = extract_features(np.asarray(s.ranges), s.angle_min, s.angle_increment, config,
                             s.range_min, s.range_max)
        k = int(np.argmin(np.hypot(*(f.segments.end_xy_m - NEAR_CORNER).T)))
        ends.append(f.segments.last_index[k])
    return np.array(ends)


def test_an_object_beside_the_near_corner_no_longer_joins_the_wall(scans, range_sigma):
    # A small object stands between the near wall's end and the corner: its 8 returns (beams
    # 78-85) lie 5-38 mm off the wall, inside the 40 mm IEPF threshold. Without the end offset
    # cut the wall takes all of them in some scans (in 49 of 175, measured); with the cut (the
    # default) it never reaches the object's far end.
    config = FeatureConfig(method='utls', range_sigma_m=range_sigma, bearing_sigma_rad=0.0,
                           end_offset_sigmas=0.0)
    uncut = near_wall_end(scans, config)
    cut = near_wall_end(scans, config.replace(end_offset_sigmas=FeatureConfig().end_offset_sigmas))
    print(f'without the cut the wall ends at beam 83 or later in {np.sum(uncut >= 83)} scans; '
          f'with it at beams {cut.min()}-{cut.max()}')
    assert np.sum(uncut >= 83) >= 20
    assert cut.max() < 83
