# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The landmark tracker's steps compiled: prediction, gating, joint compatibility, correction.

The compiled twin of :class:`wctls_ros.frontend.tracking.Tracker`'s numpy steps, which stay the
specification (docs/derivation.md#landmark-tracks): one compiled call per kind of landmark and
scan (:func:`update_tracks`) moves the tracks by the step, gates every (detection, track) pair,
resolves the ambiguous clusters by joint compatibility (JCBB), fuses each matched detection
into its track and ages the tracks, on the tracker's arrays in place; the tracker itself starts
the new tracks and hands out the ids. Corners and lines run through the same code (the corner's
third coordinate, its yaw, is carried but not gated), so numba compiles it once.

Where the numpy tracker solves the stacked innovation of a hypothesis from scratch, the search
here keeps the Cholesky factor L of the stacked covariance S and y = L^-1 e along its path:
pairing one more detection costs a Schur complement (B = L^-1 C with C the shared step's
blocks G_j Q G_k^T against the pairs already made, then the 2x2 factor of D - B^T B) instead of
a new solve, and the joint distance e^T S^-1 e = |y|^2 grows by the new pair's share. Both give
the same distances to rounding (the tests hold the two trackers to the same ids and estimates
within 1e-9); a hypothesis whose Schur complement is not positive definite (S is, exactly) is
incompatible here.
"""

import math

import numpy as np

from ._jit import jit
from ._order import stable_order
from ..rules import CONFIRMED, LOST, TENTATIVE


@jit
def wrap_angle(angle):
    """Compiled twin of :func:`wctls_ros.frontend.frames.wrap_angle` for one angle, rad."""
    return math.pi - (math.pi - angle) % (2.0 * math.pi)


@jit
def predict(is_line, mean, cov, persistent, ends, step, step_cov):
    """
    Compiled twin of ``Tracker._predict``: move the tracks by the step, in place.

    As ``frames.step_corners``, ``step_lines`` and ``step_points`` move them: the mean, the
    covariance F P F^T + G Q G^T, the persistent part F P F^T and the ends of the stretch seen.

    :param is_line: the tracks are lines (alpha rad, r m), else corners (x m, y m, yaw rad)
    :param mean: shape (K, d)
    :param cov: shape (K, d, d)
    :param persistent: shape (K, d, d)
    :param ends: shape (K, 2, 2), m
    :param step: the sensor's step (dx m, dy m, dyaw rad) in the previous frame
    :param step_cov: its covariance Q, shape (3, 3)
    :return: d track / d step G, shape (K, d, 3)
    """
    count, dims = mean.shape
    dx, dy, dyaw = step[0], step[1], step[2]
    cos, sin = math.cos(dyaw), math.sin(dyaw)
    by_step = np.zeros((count, dims, 3))
    for k in range(count):
        by_track = np.zeros((dims, dims))
        if is_line:
            line_cos, line_sin = math.cos(mean[k, 0]), math.sin(mean[k, 0])
            radius = mean[k, 1] - dx * line_cos - dy * line_sin
            by_track[0, 0] = 1.0
            by_track[1, 0] = dx * line_sin - dy * line_cos
            by_track[1, 1] = 1.0
            by_step[k, 0, 2] = -1.0
            by_step[k, 1, 0] = -line_cos
            by_step[k, 1, 1] = -line_sin
            if radius < 0.0:            # the sensor crossed the line: the normal turns round
                for column in range(2):
                    by_track[1, column] = -by_track[1, column]
                for column in range(3):
                    by_step[k, 1, column] = -by_step[k, 1, column]
                mean[k, 0] = wrap_angle(mean[k, 0] - dyaw + math.pi)
            else:
                mean[k, 0] = wrap_angle(mean[k, 0] - dyaw)
            mean[k, 1] = abs(radius)
        else:
            offset_x, offset_y = mean[k, 0] - dx, mean[k, 1] - dy
            mean[k, 0] = offset_x * cos + offset_y * sin
            mean[k, 1] = offset_x * -sin + offset_y * cos
            mean[k, 2] = wrap_angle(mean[k, 2] - dyaw)
            by_track[0, 0], by_track[0, 1] = cos, sin
            by_track[1, 0], by_track[1, 1] = -sin, cos
            by_track[2, 2] = 1.0
            by_step[k, 0, 0], by_step[k, 0, 1] = -cos, -sin
            by_step[k, 1, 0], by_step[k, 1, 1] = sin, -cos
            by_step[k, 0, 2] = offset_x * -sin + offset_y * cos
            by_step[k, 1, 2] = offset_x * -cos + offset_y * -sin
            by_step[k, 2, 2] = -1.0
        _congruence(by_track, cov[k], cov[k])
        _add_congruence(by_step[k], step_cov, cov[k])
        _congruence(by_track, persistent[k], persistent[k])
        for e in range(2):
            offset_x, offset_y = ends[k, e, 0] - dx, ends[k, e, 1] - dy
            ends[k, e, 0] = offset_x * cos + offset_y * sin
            ends[k, e, 1] = offset_x * -sin + offset_y * cos
    return by_step


@jit
def _congruence(a, p, out):
    """Write A P A^T into ``out`` (which may be ``p``); A square."""
    size = a.shape[0]
    product = np.zeros((size, size))
    for i in range(size):
        for j in range(size):
            total = 0.0
            for m in range(size):
                total += a[i, m] * p[m, j]
            product[i, j] = total
    for i in range(size):
        for j in range(size):
            total = 0.0
            for m in range(size):
                total += product[i, m] * a[j, m]
            out[i, j] = total


@jit
def _add_congruence(g, q, out):
    """Add G Q G^T to ``out``; G of shape (d, 3), Q (3, 3)."""
    rows, inner = g.shape
    for i in range(rows):
        for j in range(rows):
            total = 0.0
            for m in range(inner):
                row = 0.0
                for n in range(inner):
                    row += g[i, n] * q[n, m]
                total += row * g[j, m]
            out[i, j] += total


@jit
def overlapping(ends, track_ends):
    """
    Compiled twin of :func:`wctls_ros.frontend.frames.overlapping` for one pair.

    :param ends: a segment's ends, shape (2, 2), m
    :param track_ends: a track's stretch, shape (2, 2), m
    :return: the two extents share a stretch of positive length along the segment's line
    """
    direction_x, direction_y = ends[1, 0] - ends[0, 0], ends[1, 1] - ends[0, 1]
    norm = max(math.sqrt(direction_x * direction_x + direction_y * direction_y), 1e-12)
    direction_x, direction_y = direction_x / norm, direction_y / norm
    own_a = ends[0, 0] * direction_x + ends[0, 1] * direction_y
    own_b = ends[1, 0] * direction_x + ends[1, 1] * direction_y
    other_a = track_ends[0, 0] * direction_x + track_ends[0, 1] * direction_y
    other_b = track_ends[1, 0] * direction_x + track_ends[1, 1] * direction_y
    return (min(max(own_a, own_b), max(other_a, other_b))
            > max(min(own_a, own_b), min(other_a, other_b)))


@jit
def innovations(is_line, value, cov, white_share, mean, track_cov):
    """
    Compiled twin of ``Tracker._innovation``: every pair's gated innovation and distance.

    :param is_line: lines (the first coordinate, an angle, is wrapped), else corners
    :param value: the detections, shape (N, d)
    :param cov: their covariances, shape (N, d, d)
    :param white_share: the share of an observation's covariance new in every scan
    :param mean: the predicted tracks, shape (K, d)
    :param track_cov: their covariances, shape (K, d, d)
    :return: (innovations (N, K, 2), their covariances (N, K, 2, 2), squared Mahalanobis
        distances (N, K))
    """
    count, tracks = value.shape[0], mean.shape[0]
    error = np.empty((count, tracks, 2))
    innovation = np.empty((count, tracks, 2, 2))
    squared = np.empty((count, tracks))
    for n in range(count):
        for k in range(tracks):
            e0, e1 = value[n, 0] - mean[k, 0], value[n, 1] - mean[k, 1]
            if is_line:
                e0 = wrap_angle(e0)
            s00 = white_share * cov[n, 0, 0] + track_cov[k, 0, 0]
            s01 = white_share * cov[n, 0, 1] + track_cov[k, 0, 1]
            s10 = white_share * cov[n, 1, 0] + track_cov[k, 1, 0]
            s11 = white_share * cov[n, 1, 1] + track_cov[k, 1, 1]
            error[n, k, 0], error[n, k, 1] = e0, e1
            innovation[n, k, 0, 0], innovation[n, k, 0, 1] = s00, s01
            innovation[n, k, 1, 0], innovation[n, k, 1, 1] = s10, s11
            squared[n, k] = (e0 * (s11 * e0 - s01 * e1) + e1 * (s00 * e1 - s10 * e0)) / (
                s00 * s11 - s01 * s10)
    return error, innovation, squared


@jit
def gate(is_line, squared, single_gate, ends, track_ends):
    """
    Compiled twin of the gate of ``Tracker._associate``: which pairs may be one landmark.

    :param is_line: lines, which must also overlap their track's stretch of wall
    :param squared: each pair's squared distance, shape (N, K)
    :param single_gate: chi2(2, p)
    :param ends: the detections' ends, shape (N, 2, 2), m
    :param track_ends: the tracks' stretches, shape (K, 2, 2), m
    :return: shape (N, K)
    """
    count, tracks = squared.shape
    gated = np.zeros((count, tracks), np.bool_)
    for n in range(count):
        for k in range(tracks):
            gated[n, k] = squared[n, k] <= single_gate and (
                not is_line or overlapping(ends[n], track_ends[k]))
    return gated


@jit
def clusters(gated, alone):
    """
    Compiled twin of ``tracking._clusters`` on the pairs not alone in their row and column.

    :param gated: shape (N, K): which pairs pass the individual gate
    :param alone: shape (N, K): the gated pairs alone in their row and column (left out)
    :return: each detection's cluster (-1: none), numbered from 0 in the order of their first
        detections, and the number of clusters
    """
    count, tracks = gated.shape
    parent = np.arange(count + tracks)
    for n in range(count):
        for k in range(tracks):
            if gated[n, k] and not alone[n, k]:
                parent[_root(parent, n)] = _root(parent, count + k)
    label_of_root = np.full(count + tracks, -1, np.intp)
    cluster = np.full(count, -1, np.intp)
    found = 0
    for n in range(count):
        for k in range(tracks):
            if gated[n, k] and not alone[n, k]:
                root = _root(parent, n)
                if label_of_root[root] < 0:
                    label_of_root[root] = found
                    found += 1
                cluster[n] = label_of_root[root]
                break
    return cluster, found


@jit
def _root(parent, node):
    """Return a node's root in the union-find forest, halving the path on the way."""
    while parent[node] != node:
        parent[node] = parent[parent[node]]
        node = parent[node]
    return node


@jit
def resolve(gated, squared, error, innovation, by_step, step_cov, gates, max_hypotheses):
    """
    Compiled twin of ``Tracker._resolve``: each detection's track, JCBB in ambiguous clusters.

    :param gated: shape (N, K)
    :param squared: shape (N, K)
    :param error: shape (N, K, 2)
    :param innovation: shape (N, K, 2, 2)
    :param by_step: d track / d step, shape (K, d, 3)
    :param step_cov: shape (3, 3)
    :param gates: the joint gate of m pairings at m (chi2(2 m, p)), shape (M + 1,)
    :param max_hypotheses: nodes of the search per cluster
    :return: each detection's track, -1 for none, shape (N,)
    """
    count, tracks = gated.shape
    matched = np.full(count, -1, np.intp)
    per_row = np.zeros(count, np.intp)
    per_column = np.zeros(tracks, np.intp)
    for n in range(count):
        for k in range(tracks):
            if gated[n, k]:
                per_row[n] += 1
                per_column[k] += 1
    alone = np.zeros((count, tracks), np.bool_)
    for n in range(count):
        for k in range(tracks):
            if gated[n, k] and per_row[n] == 1 and per_column[k] == 1:
                alone[n, k] = True
                matched[n] = k
    cluster, found = clusters(gated, alone)
    for label in range(found):
        in_cluster = np.zeros(tracks, np.bool_)
        size, track_count = 0, 0
        for n in range(count):
            if cluster[n] == label:
                size += 1
                for k in range(tracks):
                    if gated[n, k] and not in_cluster[k]:
                        in_cluster[k] = True
                        track_count += 1
        members = np.empty(size, np.intp)
        at = 0
        for n in range(count):
            if cluster[n] == label:
                members[at] = n
                at += 1
        cluster_tracks = np.empty(track_count, np.intp)
        at = 0
        for k in range(tracks):
            if in_cluster[k]:
                cluster_tracks[at] = k
                at += 1
        best = joint_search(members, cluster_tracks, gated, squared, error, innovation,
                            by_step, step_cov, gates, max_hypotheses)
        for d in range(size):
            if best[d] >= 0:
                matched[members[d]] = best[d]
    return matched


@jit
def joint_search(detections, tracks, gated, squared, error, innovation, by_step, step_cov,
                 gates, max_hypotheses):
    """
    Compiled twin of ``tracking._JointSearch.best``: the best jointly compatible pairing.

    The same search in the same order (the detections with fewest candidates first, each one's
    candidates nearest first, then leaving it unpaired while that can still win; the
    nearest-first pairing as the first best when jointly compatible, and as the answer when the
    nodes run out before any leaf), as a loop over an explicit stack, the joint distance kept
    by the incremental Cholesky factor (see the module's docstring).

    :param detections: the cluster's detections, ascending, shape (D,)
    :param tracks: the cluster's tracks, ascending, shape (T,)
    :return: the track of each of ``detections`` (-1: unpaired), shape (D,)
    """
    size, total_tracks = detections.size, gated.shape[1]
    place = np.full(total_tracks, -1, np.intp)
    for t in range(tracks.size):
        place[tracks[t]] = t
    shared = _shared_step(tracks, by_step, step_cov)
    most = min(size, tracks.size)
    lower = np.zeros((2 * most, 2 * most))
    whitened = np.zeros(2 * most)
    pair_place = np.zeros(most, np.intp)           # each pair's track, by its place

    # The nearest-first pairing (ties: by detection, then track).
    candidates = 0
    for d in range(size):
        for k in range(total_tracks):
            if gated[detections[d], k]:
                candidates += 1
    pair_squared = np.empty(candidates)
    pair_detection = np.empty(candidates, np.intp)
    pair_track = np.empty(candidates, np.intp)
    at = 0
    for d in range(size):
        for k in range(total_tracks):
            if gated[detections[d], k]:
                pair_squared[at], pair_detection[at], pair_track[at] = (
                    squared[detections[d], k], d, k)
                at += 1
    fallback = np.full(size, -1, np.intp)
    taken = np.zeros(total_tracks, np.bool_)
    paired = 0
    joint = 0.0
    for c in stable_order(pair_squared):
        d, k = pair_detection[c], pair_track[c]
        if fallback[d] < 0 and not taken[k]:
            joint = _extend(paired, detections[d], k, joint, lower, whitened, pair_place,
                            place, shared, error, innovation)
            pair_place[paired] = place[k]
            fallback[d], taken[k] = k, True
            paired += 1
    best = np.full(size, -1, np.intp)
    best_size, best_joint = 0, math.inf
    if joint <= gates[paired]:
        for d in range(size):
            best[d] = fallback[d]
        best_size, best_joint = paired, joint

    # The detections with fewest candidates first, each one's candidates nearest first.
    row_counts = np.zeros(size)
    for d in range(size):
        for k in range(total_tracks):
            if gated[detections[d], k]:
                row_counts[d] += 1.0
    order = stable_order(row_counts)
    options = np.zeros((size, tracks.size), np.intp)
    option_count = np.zeros(size, np.intp)
    own = np.empty(tracks.size, np.intp)
    own_squared = np.empty(tracks.size)
    for depth in range(size):
        n = detections[order[depth]]
        found = 0
        for k in range(total_tracks):
            if gated[n, k]:
                own[found], own_squared[found] = k, squared[n, k]
                found += 1
        ranked = stable_order(own_squared[:found])
        option_count[depth] = found
        for i in range(found):
            options[depth, i] = own[ranked[i]]

    # The search: choice[depth] the track of order[depth] (-1 unpaired), next_option[depth]
    # the next candidate to try, pairs_at / joint_at the hypothesis when entering a depth.
    choice = np.full(size, -1, np.intp)
    next_option = np.zeros(size, np.intp)
    left_unpaired = np.zeros(size, np.bool_)
    pairs_at = np.zeros(size + 1, np.intp)
    joint_at = np.zeros(size + 1)
    taken = np.zeros(total_tracks, np.bool_)
    nodes_left = max_hypotheses - 1                # the root
    depth = 0
    while depth >= 0 and nodes_left >= 0:
        descend = False
        if next_option[depth] < option_count[depth]:
            k = options[depth, next_option[depth]]
            next_option[depth] += 1
            if taken[k]:
                continue
            if nodes_left <= 0:                    # nothing below can change the best
                break
            pairs = pairs_at[depth]
            candidate = _extend(pairs, detections[order[depth]], k, joint_at[depth], lower,
                                whitened, pair_place, place, shared, error, innovation)
            if candidate <= gates[pairs + 1]:
                choice[depth], taken[k] = k, True
                pair_place[pairs] = place[k]
                pairs_at[depth + 1], joint_at[depth + 1] = pairs + 1, candidate
                descend = True
        elif not left_unpaired[depth]:
            left_unpaired[depth] = True
            # Leaving this detection unpaired can still win only with enough detections left.
            if pairs_at[depth] + size - depth - 1 > best_size:
                if nodes_left <= 0:
                    break
                choice[depth] = -1
                pairs_at[depth + 1], joint_at[depth + 1] = pairs_at[depth], joint_at[depth]
                descend = True
        else:                                      # this depth is done: back to the one above
            depth -= 1
            if depth >= 0 and choice[depth] >= 0:
                taken[choice[depth]] = False
                choice[depth] = -1
            continue
        if not descend:
            continue
        nodes_left -= 1
        if depth + 1 == size:                      # a leaf
            if (pairs_at[size] > best_size
                    or (pairs_at[size] == best_size and joint_at[size] < best_joint)):
                best_size, best_joint = pairs_at[size], joint_at[size]
                for d in range(size):
                    best[order[d]] = choice[d]
            if choice[depth] >= 0:
                taken[choice[depth]] = False
                choice[depth] = -1
            continue
        depth += 1
        next_option[depth] = 0
        left_unpaired[depth] = False
    # A search cut short before any leaf keeps the nearest-first pairing.
    if best_size > 0:
        return best
    if nodes_left <= 0:
        return fallback
    return np.full(size, -1, np.intp)


@jit
def _shared_step(tracks, by_step, step_cov):
    """Return G_j Q G_k^T of every two of the tracks on the gated rows, shape (T, T, 2, 2)."""
    count = tracks.size
    by_q = np.zeros((count, 2, 3))
    for t in range(count):
        for i in range(2):
            for m in range(3):
                total = 0.0
                for n in range(3):
                    total += by_step[tracks[t], i, n] * step_cov[n, m]
                by_q[t, i, m] = total
    shared = np.zeros((count, count, 2, 2))
    for a in range(count):
        for b in range(count):
            for i in range(2):
                for j in range(2):
                    total = 0.0
                    for m in range(3):
                        total += by_q[a, i, m] * by_step[tracks[b], j, m]
                    shared[a, b, i, j] = total
    return shared


@jit
def _extend(pairs, n, k, joint, lower, whitened, pair_place, place, shared, error, innovation):
    """
    Return the joint distance of the hypothesis's first ``pairs`` pairs and (n, k).

    Writes the factor's rows 2 pairs and 2 pairs + 1 and the whitened innovation there: the
    first ``pairs`` pairs' rows are kept (see the module's docstring).

    :return: the joint squared distance (inf when the Schur complement is not positive
        definite)
    """
    top = 2 * pairs
    own = place[k]
    # B = L^-1 C, C the shared step's blocks of the earlier pairs' tracks against track k.
    for column in range(2):
        for row in range(top):
            total = shared[pair_place[row // 2], own, row % 2, column]
            for m in range(row):
                total -= lower[row, m] * lower[top + column, m]
            lower[top + column, row] = total / lower[row, row]
    schur = np.empty((2, 2))
    for i in range(2):
        for j in range(2):
            total = innovation[n, k, i, j]
            for m in range(top):
                total -= lower[top + i, m] * lower[top + j, m]
            schur[i, j] = total
    if not schur[0, 0] > 0.0:
        return math.inf
    first = math.sqrt(schur[0, 0])
    cross = schur[1, 0] / first
    rest = schur[1, 1] - cross * cross
    if not rest > 0.0:
        return math.inf
    lower[top, top], lower[top + 1, top] = first, cross
    lower[top, top + 1], lower[top + 1, top + 1] = 0.0, math.sqrt(rest)
    # y of the new rows: L y = e.
    for i in range(2):
        total = error[n, k, i]
        for m in range(top + i):
            total -= lower[top + i, m] * whitened[m]
        whitened[top + i] = total / lower[top + i, top + i]
    return joint + whitened[top] ** 2 + whitened[top + 1] ** 2


@jit
def correct(is_line, value, cov, ends, matched, mean, track_cov, persistent, track_ends, state,
            hits, misses, last_scan, rules, scan):
    """
    Compiled twin of ``Tracker._correct``: the Kalman update of each matched track.

    In place, on the track arrays; a line's stretch as ``frames.spanned`` gives it.

    :param matched: each detection's track (-1: none), shape (N,)
    :param rules: the tracker's :class:`~wctls_ros.core.records.TrackRules`
    :param scan: this scan's number
    """
    dims = mean.shape[1]
    angle = 0 if is_line else 2
    error = np.empty(dims)
    total_cov = np.empty((dims, dims))
    prior = np.empty((dims, dims))
    updated = np.empty((dims, dims))
    for n in range(matched.size):
        k = matched[n]
        if k < 0:
            continue
        for i in range(dims):
            error[i] = value[n, i] - mean[k, i]
        error[angle] = wrap_angle(error[angle])
        for i in range(dims):
            for j in range(dims):
                prior[i, j] = track_cov[k, i, j]
                total_cov[i, j] = prior[i, j] + rules.white_share * cov[n, i, j]
        # The gain P (P + R)^-1 is the transpose of (P + R)^-1 P: gain[i, j] = solved[j, i].
        solved = _solve(total_cov, prior)
        for i in range(dims):
            total = 0.0
            for j in range(dims):
                total += solved[j, i] * error[j]
            mean[k, i] += total
        mean[k, angle] = wrap_angle(mean[k, angle])
        for i in range(dims):                      # P (P + R)^-1 R
            for j in range(dims):
                total = 0.0
                for m in range(dims):
                    total += solved[m, i] * (rules.white_share * cov[n, m, j])
                updated[i, j] = total
        for i in range(dims):
            for j in range(dims):
                track_cov[k, i, j] = 0.5 * (updated[i, j] + updated[j, i])
                persistent[k, i, j] = cov[n, i, j] - rules.white_share * cov[n, i, j]
        if is_line:
            _span(ends[n], track_ends[k])
        hits[k] += 1
        misses[k] = 0
        last_scan[k] = scan
        if state[k] == LOST or hits[k] >= rules.confirm_hits:
            state[k] = CONFIRMED


@jit
def _solve(a, b):
    """Return A^-1 B by Gaussian elimination with partial pivoting (A small and square)."""
    size = a.shape[0]
    lu = a.copy()
    x = b.copy()
    for column in range(size):
        pivot = column
        for row in range(column + 1, size):
            if abs(lu[row, column]) > abs(lu[pivot, column]):
                pivot = row
        if pivot != column:
            for m in range(size):
                lu[column, m], lu[pivot, m] = lu[pivot, m], lu[column, m]
            for m in range(x.shape[1]):
                x[column, m], x[pivot, m] = x[pivot, m], x[column, m]
        for row in range(column + 1, size):
            factor = lu[row, column] / lu[column, column]
            for m in range(column, size):
                lu[row, m] -= factor * lu[column, m]
            for m in range(x.shape[1]):
                x[row, m] -= factor * x[column, m]
    for column in range(size - 1, -1, -1):
        for m in range(x.shape[1]):
            total = x[column, m]
            for j in range(column + 1, size):
                total -= lu[column, j] * x[j, m]
            x[column, m] = total / lu[column, column]
    return x


@jit
def _span(ends, track_ends):
    """Compiled twin of :func:`wctls_ros.frontend.frames.spanned`, into ``track_ends``."""
    direction_x, direction_y = ends[1, 0] - ends[0, 0], ends[1, 1] - ends[0, 1]
    norm = max(math.sqrt(direction_x * direction_x + direction_y * direction_y), 1e-12)
    direction_x, direction_y = direction_x / norm, direction_y / norm
    first = ends[0, 0] * direction_x + ends[0, 1] * direction_y
    low, high = first, first
    for along in (ends[1, 0] * direction_x + ends[1, 1] * direction_y,
                  track_ends[0, 0] * direction_x + track_ends[0, 1] * direction_y,
                  track_ends[1, 0] * direction_x + track_ends[1, 1] * direction_y):
        low, high = min(low, along), max(high, along)
    foot_x, foot_y = ends[0, 0] - first * direction_x, ends[0, 1] - first * direction_y
    track_ends[0, 0], track_ends[0, 1] = foot_x + low * direction_x, foot_y + low * direction_y
    track_ends[1, 0], track_ends[1, 1] = foot_x + high * direction_x, foot_y + high * direction_y


@jit
def sees(x, y, ranges_m, angle_min_rad, angle_increment_rad, range_max_m, margin_m):
    """
    Compiled twin of :meth:`wctls_ros.frontend.tracking.View.sees` for one point.

    :return: the point is inside the bearings and the reach, and not hidden
    """
    count = ranges_m.size
    step = abs(angle_increment_rad)
    turned = math.atan2(y, x) - angle_min_rad
    if angle_increment_rad < 0.0:
        turned = -turned
    index = int(np.rint((turned % (2.0 * math.pi)) / step))
    if count * step >= 2.0 * math.pi - 1.5 * step:             # a full turn
        index %= count
    distance = math.hypot(x, y)
    measured = ranges_m[min(index, count - 1)]
    hidden = math.isfinite(measured) and measured < distance - margin_m
    return index < count and distance <= range_max_m and not hidden


@jit
def age(is_line, matched, mean, track_ends, state, misses, last_scan, rules, scan, seen,
        ranges_m, angle_min_rad, angle_increment_rad, range_max_m):
    """
    Compiled twin of ``Tracker._age``: count the misses in view, lose and drop tracks.

    :param seen: a view was given (else every track counts as in view)
    :return: the tracks to keep, shape (K,)
    """
    count = mean.shape[0]
    missed = np.ones(count, np.bool_)
    for n in range(matched.size):
        if matched[n] >= 0:
            missed[matched[n]] = False
    keep = np.ones(count, np.bool_)
    for k in range(count):
        if missed[k] and seen:
            if is_line:
                x = 0.5 * (track_ends[k, 0, 0] + track_ends[k, 1, 0])
                y = 0.5 * (track_ends[k, 0, 1] + track_ends[k, 1, 1])
            else:
                x, y = mean[k, 0], mean[k, 1]
            missed[k] = sees(x, y, ranges_m, angle_min_rad, angle_increment_rad, range_max_m,
                             rules.occlusion_margin_m)
        if missed[k]:
            misses[k] += 1
        if state[k] == CONFIRMED and misses[k] >= rules.lose_misses:
            state[k] = LOST
        keep[k] = not ((state[k] == TENTATIVE and misses[k] >= rules.drop_tentative_misses)
                       or scan - last_scan[k] > rules.memory_scans)
    return keep


@jit
def update_tracks(is_line, value, cov, ends, mean, track_cov, persistent, track_ends, state,
                  hits, misses, last_scan, step, step_cov, gates, rules, scan, seen, ranges_m,
                  angle_min_rad, angle_increment_rad, range_max_m):
    """
    Predict, associate, correct and age one kind's tracks, in place: one scan of the tracker.

    Compiled twin of the steps of ``Tracker.update`` for one kind before it starts the new
    tracks: ``_predict``, then ``_associate`` up to ``_identify``.

    :param is_line: line landmarks (alpha rad, r m), else corners (x m, y m, yaw rad)
    :param value: the detections, shape (N, d)
    :param cov: their covariances, shape (N, d, d)
    :param ends: their ends, shape (N, 2, 2), m
    :param mean: the tracks' estimates, shape (K, d)
    :param track_cov: their covariances, shape (K, d, d)
    :param persistent: the persistent part of their last observation, shape (K, d, d)
    :param track_ends: the stretches they have seen, shape (K, 2, 2), m
    :param state: their state codes (int8), shape (K,)
    :param hits: their observations, shape (K,)
    :param misses: their misses in a row, shape (K,)
    :param last_scan: the scan each was last seen in, shape (K,)
    :param step: the sensor's step since the previous scan (dx m, dy m, dyaw rad)
    :param step_cov: its covariance, shape (3, 3)
    :param gates: chi2(2 m, p) at m, for m up to min(N, K) at least, shape (M + 1,)
    :param rules: the tracker's :class:`~wctls_ros.core.records.TrackRules`
    :param scan: this scan's number
    :param seen: a view was given: ``ranges_m``, ``angle_min_rad``, ``angle_increment_rad``,
        ``range_max_m`` as in :class:`wctls_ros.frontend.tracking.View`
    :return: (each detection's track (-1: none) (N,), its squared distance (NaN: none) (N,),
        the tracks to keep (K,))
    """
    by_step = predict(is_line, mean, track_cov, persistent, track_ends, step, step_cov)
    count, tracks = value.shape[0], mean.shape[0]
    matched = np.full(count, -1, np.intp)
    squared_distance = np.full(count, np.nan)
    if count and tracks:
        error, innovation, squared = innovations(is_line, value, cov, rules.white_share, mean,
                                                 track_cov)
        gated = gate(is_line, squared, gates[1], ends, track_ends)
        matched = resolve(gated, squared, error, innovation, by_step, step_cov, gates,
                          rules.max_hypotheses)
        for n in range(count):
            if matched[n] >= 0:
                squared_distance[n] = squared[n, matched[n]]
    correct(is_line, value, cov, ends, matched, mean, track_cov, persistent, track_ends, state,
            hits, misses, last_scan, rules, scan)
    keep = age(is_line, matched, mean, track_ends, state, misses, last_scan, rules, scan, seen,
               ranges_m, angle_min_rad, angle_increment_rad, range_max_m)
    return matched, squared_distance, keep
