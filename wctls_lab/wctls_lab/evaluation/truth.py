# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
True corners of a recording: what ``simulate`` writes beside its bag and what hand labels hold.

One small YAML format serves both, in the sensor frame (m)::

    frame_id: laser
    description: free text
    recording: urg04lx_office      # optional: what the labels belong to (a note)
    scans: [0, 24]                 # optional: the scans (first, last; inclusive) it covers
    corners:                       # the same corners in every scan (a still sensor)
      - {id: 0, x_m: 1.2345, y_m: -0.5, kind: inside}     # more keys are notes, kept in the file
    visible:                       # optional: the ids each scan can see, one list per scan (or
      - [0, 1]                     # a single list for every scan); absent: all, in every scan

or, when the corners move from scan to scan (a moving sensor, separate single scans)::

    frame_id: laser
    per_scan:                      # one entry per scan
      - corners: [{id: 0, x_m: 1.2, y_m: 0.4, kind: inside}]
        visible: [0]               # optional: absent: all of this scan's corners

``kind`` is 'inside' (concave seen from the free space, like a room's corner) or 'outside'
(convex, like a box's). An id names the same physical corner in every scan.

Hand labels are made from the median scan of a still interval: the labeller picks the beams of
each of a corner's two walls (``walls: [[[first, last], ...], [[first, last], ...]]`` beside the
corner, beam ranges inclusive) and :func:`corner_from_beams` intersects straight lines fitted to
them (data/labels/README.md describes the procedure; wctls_lab/tools/label_corners.py draws
and fits).
"""

from dataclasses import dataclass
import math
import pathlib
from typing import Optional, Tuple

import numpy as np
from wctls_ros.plain_yaml import load_without_aliases
import yaml

from ..simulation import CORNER_KINDS

# The truth simulate writes into a bag folder, and where score looks for it.
TRUTH_FILE = 'truth.yaml'
# Bounds on a truth file: labels are small; a simulation's is a few hundred kB.
_MAX_BYTES = 50_000_000
_MAX_CORNERS = 10_000
_MAX_SCANS = 1_000_000
_CORNER_KEYS = ('id', 'x_m', 'y_m', 'kind')


class TruthError(ValueError):
    """A truth or label file that cannot be used, with the reason."""


@dataclass(frozen=True)
class Truth:
    """
    The true corners of a recording, in the sensor frame.

    :ivar ids: corner ids, shape (M,)
    :ivar kinds: 'inside' or 'outside' per corner, length M
    :ivar xy_m: positions, shape (S, M, 2), m: S = 1 (the same in every scan) or one row per
        scan; NaN where a corner does not exist in a scan
    :ivar visible: which corners each scan can see, shape (S, M) or (1, M) for every scan
    :ivar frame_id: the sensor frame the positions are in
    :ivar first_scan: first scan covered (0 unless the file says)
    :ivar last_scan: last scan covered (inclusive), None: up to the recording's end
    :ivar description: free text
    """

    ids: np.ndarray
    kinds: Tuple[str, ...]
    xy_m: np.ndarray
    visible: np.ndarray
    frame_id: str = 'laser'
    first_scan: int = 0
    last_scan: Optional[int] = None
    description: str = ''

    @property
    def per_scan(self) -> bool:
        """
        Tell whether positions change from scan to scan.

        :return: True when the file gives every scan its own positions
        """
        return self.xy_m.shape[0] > 1

    def covered(self, scan_count: int) -> Tuple[int, int]:
        """
        Return the scans of a recording this truth covers.

        :param scan_count: scans in the recording
        :return: (first, last) inclusive
        :raises TruthError: when the truth and the recording do not fit together
        """
        last = scan_count - 1 if self.last_scan is None else self.last_scan
        if self.per_scan and self.xy_m.shape[0] != scan_count:
            raise TruthError(f'the truth gives {self.xy_m.shape[0]} scans their own corners, '
                             f'the recording has {scan_count} scans')
        if self.visible.shape[0] > 1 and self.visible.shape[0] != scan_count:
            raise TruthError(f'the truth lists visible corners for {self.visible.shape[0]} '
                             f'scans, the recording has {scan_count} scans')
        if not 0 <= self.first_scan <= last < scan_count:
            raise TruthError(f'the truth covers scans {self.first_scan}-{last}, the recording '
                             f'has scans 0-{scan_count - 1}')
        return self.first_scan, last

    def select(self, first: int, count: int) -> 'Truth':
        """
        Return the truth of some consecutive scans, numbered from 0.

        :param first: the first scan's index in the recording
        :param count: how many scans
        :return: the truth of scans first .. first + count - 1, covering exactly those
        """
        xy = self.xy_m[first:first + count] if self.per_scan else self.xy_m
        visible = (self.visible[first:first + count] if self.visible.shape[0] > 1
                   else self.visible)
        return Truth(self.ids, self.kinds, xy, visible, self.frame_id, 0, count - 1,
                     self.description)

    def at(self, scan: int):
        """
        Return the true corners of one scan.

        :param scan: the scan's index in the recording
        :return: (positions (M, 2) m, NaN where absent; visible (M,) boolean)
        """
        xy = self.xy_m[scan if self.per_scan else 0]
        visible = self.visible[scan if self.visible.shape[0] > 1 else 0]
        return xy, visible & np.isfinite(xy[:, 0])


def _fail(source: str, message: str):
    raise TruthError(f'{source}: {message}')


def _corner(item, source: str, where: str):
    """Return (id, x, y, kind) of one corner entry, or fail with the reason."""
    if not isinstance(item, dict) or any(k not in item for k in _CORNER_KEYS):
        _fail(source, f'{where}: expected a mapping with {list(_CORNER_KEYS)}, got {item!r}')
    identifier, x, y, kind = (item[k] for k in _CORNER_KEYS)
    if isinstance(identifier, bool) or not isinstance(identifier, int) or identifier < 0:
        _fail(source, f'{where}.id: expected an integer >= 0, got {identifier!r}')
    for name, value in (('x_m', x), ('y_m', y)):
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or not math.isfinite(value) or abs(value) > 1e4):
            _fail(source, f'{where}.{name}: expected a finite number of m, got {value!r}')
    if kind not in CORNER_KINDS:
        _fail(source, f'{where}.kind: expected one of {CORNER_KINDS}, got {kind!r}')
    return identifier, float(x), float(y), kind


def _list(value, source: str, where: str, limit: int) -> list:
    if not isinstance(value, list) or len(value) > limit:
        _fail(source, f'{where}: expected a list of at most {limit} items')
    return value


def _corners(items, source: str, where: str):
    """Return the corners of a list as {id: (x, y, kind)}."""
    corners = {}
    for n, item in enumerate(_list(items, source, where, _MAX_CORNERS)):
        identifier, x, y, kind = _corner(item, source, f'{where}[{n}]')
        if identifier in corners:
            _fail(source, f'{where}[{n}]: id {identifier} given twice')
        corners[identifier] = (x, y, kind)
    return corners


def _visible(lists, ids: np.ndarray, source: str, where: str) -> np.ndarray:
    """Return a (rows, M) boolean array from lists of visible ids."""
    rows = []
    for n, seen in enumerate(_list(lists, source, where, _MAX_SCANS)):
        seen = _list(seen, source, f'{where}[{n}]', _MAX_CORNERS)
        unknown = sorted(set(seen) - set(ids.tolist()))
        if unknown:
            _fail(source, f'{where}[{n}]: ids {unknown[:5]} are not among the corners')
        rows.append(np.isin(ids, seen))
    if not rows:
        _fail(source, f'{where}: expected at least one list of ids')
    return np.array(rows, dtype=bool).reshape(len(rows), len(ids))


def truth_from_dict(document, source: str = 'truth') -> Truth:
    """
    Build the truth from its YAML structure (see the module's documentation).

    :param document: the parsed YAML
    :param source: the file's name, for the messages
    :return: the truth
    :raises TruthError: on a malformed file, with where and why
    """
    known = ('frame_id', 'description', 'recording', 'scans', 'corners', 'visible',
             'per_scan')
    if not isinstance(document, dict):
        _fail(source, 'expected a mapping with frame_id and corners (or per_scan)')
    unknown = sorted(str(k) for k in document if k not in known)
    if unknown:
        _fail(source, f'unknown keys {unknown}; known: {list(known)}')
    if ('corners' in document) == ('per_scan' in document):
        _fail(source, "give either 'corners' (the same in every scan) or 'per_scan'")
    first, last = 0, None
    if 'scans' in document:
        scans = document['scans']
        if (not isinstance(scans, list) or len(scans) != 2
                or not all(isinstance(v, int) and not isinstance(v, bool) for v in scans)
                or not 0 <= scans[0] <= scans[1]):
            _fail(source, f'scans: expected [first, last] with 0 <= first <= last, got {scans!r}')
        first, last = scans
    if 'corners' in document:
        corners = _corners(document['corners'], source, 'corners')
        ids = np.array(sorted(corners), dtype=np.int64)
        xy = np.array([corners[i][:2] for i in ids], dtype=float).reshape(1, -1, 2)
        visible = (_visible(document['visible'], ids, source, 'visible')
                   if 'visible' in document else np.ones((1, len(ids)), dtype=bool))
        kinds = tuple(corners[i][2] for i in ids)
    else:
        if 'visible' in document:
            _fail(source, "with 'per_scan', give 'visible' inside each scan's entry")
        scans = []
        for n, entry in enumerate(_list(document['per_scan'], source, 'per_scan', _MAX_SCANS)):
            if not isinstance(entry, dict) or 'corners' not in entry:
                _fail(source, f'per_scan[{n}]: expected a mapping with corners')
            corners = _corners(entry['corners'], source, f'per_scan[{n}].corners')
            seen = _list(entry.get('visible', sorted(corners)), source,
                         f'per_scan[{n}].visible', _MAX_CORNERS)
            scans.append((corners, set(seen)))
        kind_of = {}
        for n, (corners, seen) in enumerate(scans):
            if seen - set(corners):
                _fail(source, f'per_scan[{n}].visible: ids {sorted(seen - set(corners))[:5]} '
                      'are not among its corners')
            for i, (_, _, kind) in corners.items():
                if kind_of.setdefault(i, kind) != kind:
                    _fail(source, f'per_scan[{n}]: corner {i} changes its kind')
        ids = np.array(sorted(kind_of), dtype=np.int64)
        xy = np.full((len(scans), len(ids), 2), np.nan)
        visible = np.zeros((len(scans), len(ids)), dtype=bool)
        for n, (corners, seen) in enumerate(scans):
            for m, i in enumerate(ids):
                if i in corners:
                    xy[n, m] = corners[i][:2]
                    visible[n, m] = i in seen
        kinds = tuple(kind_of[i] for i in ids)
    return Truth(ids, kinds, xy, visible, str(document.get('frame_id', 'laser')), first, last,
                 str(document.get('description', '')).strip())


def load_truth(path) -> Truth:
    """
    Read a truth or label file.

    :param path: the YAML file
    :return: the truth
    :raises TruthError: when it is missing, unreadable or malformed (one line: where and why)
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise TruthError(f'{path}: no such label or truth file')
    if path.stat().st_size > _MAX_BYTES:
        raise TruthError(f'{path}: larger than {_MAX_BYTES} bytes')
    try:
        document = load_without_aliases(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
        raise TruthError(f'{path}: not a readable YAML file: '
                         f'{str(error).splitlines()[0]}') from error
    return truth_from_dict(document, str(path))


def _corner_rows(ids, kinds, xy) -> list:
    return [{'id': int(i), 'x_m': float(x), 'y_m': float(y), 'kind': kind}
            for i, kind, (x, y) in zip(ids, kinds, xy) if math.isfinite(x)]


def truth_to_yaml(truth: Truth, header: str = '') -> str:
    """
    Return the YAML text of a truth.

    :param truth: the truth
    :param header: comment lines to put first (without the '#')
    :return: the text
    """
    document = {'frame_id': truth.frame_id, 'description': truth.description}
    if truth.first_scan or truth.last_scan is not None:
        document['scans'] = [truth.first_scan, truth.last_scan]
    if truth.per_scan:
        document['per_scan'] = [
            {'corners': _corner_rows(truth.ids, truth.kinds, truth.xy_m[n]),
             'visible': truth.ids[truth.at(n)[1]].tolist()} for n in range(len(truth.xy_m))]
    else:
        document['corners'] = _corner_rows(truth.ids, truth.kinds, truth.xy_m[0])
        document['visible'] = [truth.ids[row].tolist() for row in truth.visible]
    comments = ''.join(f'# {line}\n' for line in header.splitlines())
    return comments + yaml.safe_dump(document, default_flow_style=None, sort_keys=False,
                                     width=100)


def truth_from_recording(recording, frame_id: str = 'laser', description: str = '') -> Truth:
    """
    Return the truth of a simulated recording.

    :param recording: a :class:`~wctls_lab.simulation.Recording`
    :param frame_id: the scans' frame
    :param description: free text (e.g. how it was simulated)
    :return: the truth: one set of positions for a still sensor, per-scan positions for a
        moving one; visibility per scan (one row when it never changes)
    """
    ids = np.arange(recording.corners_m.shape[1])
    still = bool(np.all(recording.poses == recording.poses[0]))
    xy = recording.corners_m[:1] if still else recording.corners_m
    visible = recording.visible
    if still and np.all(visible == visible[:1]):
        visible = visible[:1]
    return Truth(ids, tuple(recording.corner_kinds), xy, visible, frame_id,
                 description=description)


def median_scan(ranges: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """
    Return the median of each beam's valid ranges over repeated scans.

    :param ranges: shape (T, N), m
    :param valid: which ranges are returns, shape (T, N)
    :return: shape (N,), m; NaN for a beam that never returned
    """
    present = valid.any(axis=0)
    median = np.full(ranges.shape[1], np.nan)
    median[present] = np.nanmedian(np.where(valid, ranges, np.nan)[:, present], axis=0)
    return median


def corner_from_beams(ranges: np.ndarray, bearings: np.ndarray, walls) -> np.ndarray:
    """
    Return where two walls meet, from straight lines fitted to hand-chosen beams of a scan.

    Each wall's line is the total least squares line through its returns (the principal axis
    of their scatter); the corner is the two lines' intersection.

    :param ranges: one scan's ranges, shape (N,), m (NaN or inf beams are skipped)
    :param bearings: the beams' bearings, shape (N,), rad
    :param walls: two walls, each a list of [first, last] beam ranges (inclusive)
    :return: the corner, shape (2,), m, in the scan's frame
    :raises ValueError: for walls with fewer than 2 returns, or parallel walls
    """
    if len(walls) != 2:
        raise ValueError(f'a corner needs 2 walls, got {len(walls)}')
    normals, offsets = [], []
    for wall in walls:
        beams = np.concatenate([np.arange(first, last + 1) for first, last in wall])
        beams = beams[np.isfinite(ranges[beams])]
        if len(beams) < 2:
            raise ValueError(f'wall {wall} has fewer than 2 returns')
        points = ranges[beams, None] * np.column_stack([np.cos(bearings[beams]),
                                                        np.sin(bearings[beams])])
        centre = points.mean(axis=0)
        normal = np.linalg.svd(points - centre)[2][1]          # the least-spread direction
        normals.append(normal)
        offsets.append(normal @ centre)
    if abs(np.linalg.det(np.array(normals))) < 1e-6:
        raise ValueError(f'walls {walls} are parallel: they meet nowhere')
    return np.linalg.solve(np.array(normals), np.array(offsets))
