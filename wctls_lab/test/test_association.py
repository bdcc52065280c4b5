# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The association of corners across scans (score, evaluate, calibrate): same clusters, less memory.

:func:`wctls_lab.evaluation.associate` compares only corners of neighbouring cells. Its clusters
must be exactly those of the plain rule computed over every pair of corners (the reference
below, which allocates an N x N array), and its memory must grow with the recording, not with
its square.
"""

import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from wctls_lab.evaluation import assign, associate
from wctls_lab.evaluation.samples import ScanCorners
from wctls_ros.core import ellipse


def all_pairs_associate(per_scan, min_presence):
    """Associate by the rule over every pair of corners, plainly: the reference."""
    count = len(per_scan)
    xy = np.concatenate([c.xy for c in per_scan]) if count else np.zeros((0, 2))
    scan_of = np.concatenate([np.full(len(c), t) for t, c in enumerate(per_scan)]
                             ).astype(np.intp) if count else np.zeros(0, np.intp)
    cov = np.concatenate([c.covariance for c in per_scan]) if count else np.zeros((0, 2, 2))
    gates = np.array([float(np.clip(5.0 * ellipse(c).semi_major, 0.02, 0.25)) for c in cov])
    free = np.ones(len(xy), dtype=bool)
    distance = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    centers, radii = [], []
    needed = max(1, int(math.ceil(min_presence * count)))
    while free.any():
        within = (distance <= gates[:, None]) & free[None, :] & free[:, None]
        support = np.array([len(np.unique(scan_of[row])) for row in within])
        seed = int(np.argmax(support))
        if support[seed] < needed:
            break
        best = {}
        for i in np.flatnonzero(within[seed]):
            if scan_of[i] not in best or distance[seed, i] < distance[seed, best[scan_of[i]]]:
                best[scan_of[i]] = i
        members = np.array(sorted(best.values()), dtype=np.intp)
        free[members] = False
        free[seed] = False
        centers.append(xy[members].mean(axis=0))
        radii.append(gates[seed])
    centers, radii = np.array(centers).reshape(-1, 2), np.array(radii)
    if len(centers):
        assignment = assign(per_scan, centers, radii)
        for k in range(len(centers)):
            centers[k] = np.mean([per_scan[t].xy[i] for t, i in enumerate(assignment[:, k])
                                  if i >= 0], axis=0)
    order = np.argsort(np.mod(-np.arctan2(centers[:, 1], centers[:, 0]), 2 * math.pi),
                       kind='stable')
    return centers[order], radii[order]


def random_scans(rng, scans, corners, spread_m, clutter, snap_m=0.0, broken=False):
    """
    Corners of a static scene seen in ``scans`` scans, with clutter, in shuffled order.

    :param snap_m: round positions to this grid (equal distances: the tie-breaks), m
    :param broken: put a NaN position and a NaN covariance in every scan
    """
    truth = rng.uniform(-3.0, 3.0, (corners, 2))
    per_scan = []
    for _ in range(scans):
        seen = rng.random(corners) < 0.9
        xy = np.vstack([truth[seen] + rng.normal(0.0, spread_m, (seen.sum(), 2)),
                        rng.uniform(-3.0, 3.0, (rng.integers(0, clutter + 1), 2))])
        if snap_m:
            xy = np.round(xy / snap_m) * snap_m
        rng.shuffle(xy)
        sigma = rng.uniform(0.001, 0.06, len(xy))
        covariance = np.zeros((len(xy), 2, 2))
        covariance[:, 0, 0] = sigma ** 2
        covariance[:, 1, 1] = (sigma * rng.uniform(0.3, 1.0, len(xy))) ** 2
        if broken and len(xy):
            xy[rng.integers(len(xy))] = np.nan
            covariance[rng.integers(len(xy))] = np.nan
        per_scan.append(ScanCorners(xy, covariance, covariance, np.zeros((len(xy), 2), int)))
    return per_scan


@pytest.mark.parametrize('seed', range(60))
def test_the_clusters_are_those_of_the_all_pairs_rule(seed):
    rng = np.random.default_rng(seed)
    per_scan = random_scans(rng, int(rng.integers(0, 40)), int(rng.integers(1, 12)),
                            float(rng.choice([0.005, 0.03, 0.1])), int(rng.integers(0, 5)),
                            snap_m=0.01 if seed % 4 == 1 else 0.0, broken=seed % 3 == 0)
    min_presence = float(rng.choice([0.3, 0.5, 0.8, 0.9]))
    expected_centers, expected_radii = all_pairs_associate(per_scan, min_presence)
    centers, radii = associate(per_scan, min_presence)
    np.testing.assert_array_equal(centers, expected_centers)
    np.testing.assert_array_equal(radii, expected_radii)


# 3000 scans of a 5-corner scene: the all-pairs rule needs 15000^2 distances, 1.8 GB.
MEMORY_CHILD = textwrap.dedent("""
    import resource
    import numpy as np
    from wctls_lab.evaluation import associate, score_detections
    from wctls_lab.evaluation.samples import ScanCorners

    rng = np.random.default_rng(0)
    truth = np.array([[2.0, 1.0], [2.0, -1.5], [-1.0, 2.5], [-3.0, -1.0], [0.5, -3.0]])
    covariance = np.tile(np.eye(2) * 1e-4, (5, 1, 1))
    per_scan = [ScanCorners(truth + rng.normal(0.0, 0.01, (5, 2)), covariance, covariance,
                            np.zeros((5, 2), int)) for _ in range(3000)]
    with open('/proc/self/status') as status:
        size_kib = next(int(line.split()[1]) for line in status if line.startswith('VmSize'))
    limit = size_kib * 1024 + {budget}
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    centers, _ = associate(per_scan, 0.9)
    score = score_detections('wctls', per_scan)
    print(len(centers), len(score.recurring))
""")


def test_association_memory_grows_with_the_recording_not_its_square():
    budget = 256 * 2 ** 20     # beyond what the process held before associating, bytes
    result = subprocess.run([sys.executable, '-c', MEMORY_CHILD.format(budget=budget)],
                            capture_output=True, text=True, timeout=600, env=os.environ)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ['5', '5']
