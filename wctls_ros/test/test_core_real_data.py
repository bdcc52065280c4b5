# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The pipeline on real static SICK recordings: repeatable corners, and their real scatter.

The LMS111 file holds 175 scans of a lab box from a sensor that never moves, so the scan-to-scan
scatter of a corner is its real estimation error (up to a constant bias). With a range sigma
estimated from the same data (per-beam std over the scans, about 8 mm) and independent per-beam
noise, the propagated covariance is too small for this sensor: the far corner scatters 1.6-1.8
times its predicted std, median NEES 2.3 (a calibrated 2D estimate has median 2 ln 2 = 1.39 and
mean 2). The LMS111 adds a common-mode range offset to every beam of a scan (about 1 mm std,
slowly drifting: lag-1 correlation 0.8), which shifts every wall's radius together and which no
independent per-beam model can represent. The calibration tool of the evaluation package fits
that term; here the test pins down the measured gap so that a change in the propagation shows.
"""

from conftest import SHARED_DATA
import numpy as np
import pytest
from wctls_ros.core import extract_features, FeatureConfig, nees

LMS111 = SHARED_DATA / 'sick_lms111_static'

pytestmark = pytest.mark.skipif(not LMS111.is_dir(), reason=f'{LMS111} is absent')


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


@pytest.mark.parametrize('method', ['utls', 'wtls', 'wctls', 'ml'])
def test_the_box_corners_are_found_in_every_scan(scans, range_sigma, method):
    config = FeatureConfig(method=method, range_sigma_m=range_sigma, bearing_sigma_rad=0.0)
    reference, tracks = corner_tracks(scans, config)
    far_corner = int(np.argmax(reference[:, 0]))       # the box corner at (1.34, 0.93) m
    assert np.allclose(reference[far_corner], [1.34, 0.93], atol=0.02)
    assert len(tracks[far_corner]) == len(scans)
    # The near corner joins a wall that passes 5 cm from the sensor (beams at 5-25 degrees
    # incidence): it is missed in at most 3 of 175 scans.
    assert all(len(track) >= len(scans) - 3 for track in tracks)


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
    # Measured: scatter (2.2, 2.8) mm vs predicted (1.4, 1.5) mm, median NEES 2.25: the
    # independent-noise model is too small by a factor 1.6-1.8 in std on this sensor.
    assert np.all((1.3 < scatter / predicted) & (scatter / predicted < 2.5))
    assert 2.0 < median_nees < 4.0


def test_near_corner_scatter_is_segmentation_switching_not_the_utls_propagation(
        scans, range_sigma):
    # A small object stands between the near wall's end and the corner: its returns (beams
    # 78-85) lie 5-38 mm off the wall, inside the 40 mm IEPF threshold, and in some scans the
    # wall takes them in. The UTLS corner then moves far beyond its covariance, which describes
    # the noise of a fixed set of returns, not that switch; within each set it is calibrated.
    # (ML moves twice as far, and is overconfident even within a set: its variance model trusts
    # this wall's grazing returns, at 5-25 degrees incidence, more than the sensor deserves.)
    config = FeatureConfig(method='utls', range_sigma_m=range_sigma, bearing_sigma_rad=0.0)
    features = [extract_features(np.asarray(s.ranges), s.angle_min, s.angle_increment, config,
                                 s.range_min, s.range_max) for s in scans]
    xy, covariance, long_wall = [], [], []
    for f in features:
        k = int(np.argmin(np.hypot(*(f.corners.xy_m - [-0.05, -0.68]).T)))
        xy.append(f.corners.xy_m[k])
        covariance.append(f.corners.covariance[k, :2, :2])
        long_wall.append(f.segments.last_index[f.corners.first_segment[k]] >= 83)
    xy, covariance, long_wall = np.array(xy), np.array(covariance), np.array(long_wall)
    groups = (long_wall, ~long_wall)
    assert all(group.sum() >= 20 for group in groups)
    shift = np.hypot(*(xy[long_wall].mean(axis=0) - xy[~long_wall].mean(axis=0)))
    overall = np.mean(nees(xy - xy.mean(axis=0), covariance))
    within = [np.mean(nees(xy[g] - xy[g].mean(axis=0), covariance[g])) for g in groups]
    print(f'UTLS: {long_wall.sum()} of {len(scans)} scans with the object in the wall, '
          f'corner shift {shift * 1e3:.1f} mm, NEES {overall:.1f} overall, within '
          f'{within[0]:.2f} / {within[1]:.2f}')
    # Measured: 49 of 175 scans, shift 19 mm, NEES 112 overall, 1.6 / 2.8 within.
    assert shift > 0.015
    assert overall > 20.0
    assert all(1.0 < value < 3.5 for value in within)
