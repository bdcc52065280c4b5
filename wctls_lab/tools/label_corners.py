#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
r"""
Hand-label the true corners of a recording (data/labels/README.md describes the procedure).

Run inside the built workspace (``source tools/env.sh``)::

    # 1. look: the median scan of the still scans, every beam's index, a 1 cm grid
    tools/label_corners.py plot data/urg04lx_office --scans 0-24 --out office.png \\
        --window 0.1,1.05,1.3,2.3 --every 1
    # 2. write data/labels/<recording>.yaml with, per corner, the beams of its two walls
    # 3. compute the positions: lines fitted to those beams, intersected (--write saves them)
    tools/label_corners.py fit data/labels/urg04lx_office.yaml --write

A label file names its recording (``recording:``, relative to the label file) and the scans it
covers (``scans: [first, last]``); a file with ``per_scan`` entries labels separate scans (a
folder of JSON scans, or a bag of single scans such as data/rplidar_c1_single_scans), each from
its own ranges: plot them one at a time (``--scans 7-7``).
"""

import argparse
import pathlib
import re
import sys

import numpy as np
from wctls_lab.evaluation.score_cli import load_recording
from wctls_lab.evaluation.truth import corner_from_beams, median_scan
from wctls_lab.plotting import pyplot
import yaml


def _scans(recording, first, last):
    """Return the median scan of scans first..last (or the single scan) and the bearings."""
    last = len(recording) - 1 if last is None else last
    ranges = recording.ranges[first:last + 1]
    return median_scan(ranges, recording.valid()[first:last + 1]), recording.bearings


def _labelled(document, first, last):
    """Return the corner entries of a label file that belong to scans first..last."""
    if 'per_scan' not in document:
        return document.get('corners', [])
    last = len(document['per_scan']) - 1 if last is None else last
    return [corner for entry in document['per_scan'][first:last + 1]
            for corner in entry['corners']]


def plot(args) -> int:
    """Draw the median scan with beam indices (and any labels) for labelling by eye."""
    recording = load_recording(args.recording, None)
    first, _, last = (args.scans or '0-').partition('-')
    ranges, bearings = _scans(recording, int(first), int(last) if last else None)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(14, 14))
    ok = np.isfinite(ranges)
    x, y = ranges * np.cos(bearings), ranges * np.sin(bearings)
    ax.scatter(x[ok], y[ok], s=5, c=np.arange(len(ranges))[ok], cmap='tab20')
    for i in np.flatnonzero(ok & (np.arange(len(ranges)) % args.every == 0)):
        ax.annotate(str(i), (x[i], y[i]), fontsize=6)
    if args.labels:
        document = yaml.safe_load(pathlib.Path(args.labels).read_text())
        for corner in _labelled(document, int(first), int(last) if last else None):
            ax.plot(corner['x_m'], corner['y_m'], 'o', mfc='none', mec='red', ms=12)
            ax.annotate(f"{corner['id']} {corner['kind']}", (corner['x_m'], corner['y_m']),
                        color='red', fontsize=8, xytext=(6, -10), textcoords='offset points')
    ax.plot(0.0, 0.0, 'k*')
    ax.set_aspect('equal')
    ax.minorticks_on()
    ax.grid(which='major', lw=0.6)
    ax.grid(which='minor', lw=0.2)
    if args.window:
        x0, x1, y0, y1 = (float(v) for v in args.window.split(','))
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
    ax.set_title(f'{args.recording}, median of scans {args.scans or "all"}')
    fig.savefig(args.out, dpi=90)
    print(f'wrote {args.out}')
    return 0


def _fitted(entries, ranges, bearings):
    """Return {id: (x, y)} of corner entries with walls, fitted to one scan's ranges."""
    return {c['id']: corner_from_beams(ranges, bearings, c['walls'])
            for c in entries if 'walls' in c}


def fit(args) -> int:
    """Compute every labelled corner's position from its walls' beams; print or write them."""
    path = pathlib.Path(args.labels)
    document = yaml.safe_load(path.read_text())
    recording = load_recording(path.parent / document['recording'], None)
    positions = {}
    if 'per_scan' in document:
        for n, entry in enumerate(document['per_scan']):
            positions[n] = _fitted(entry['corners'], recording.ranges[n], recording.bearings)
    else:
        first, last = document.get('scans', [0, None])
        ranges, bearings = _scans(recording, first, last)
        positions[None] = _fitted(document['corners'], ranges, bearings)
    text, scan = path.read_text().splitlines(keepends=True), None
    for k, line in enumerate(text):
        if re.match(r'\s*- corners:', line) or re.match(r'\s*- \{?scan:', line):
            scan = 0 if scan is None else scan + 1
        match = re.search(r'id: (\d+), x_m: [-0-9.e]+, y_m: [-0-9.e]+', line)
        key = scan if 'per_scan' in document else None
        if match and int(match.group(1)) in positions.get(key, {}):
            x, y = positions[key][int(match.group(1))]
            text[k] = line.replace(match.group(0),
                                   f'id: {match.group(1)}, x_m: {x:.4f}, y_m: {y:.4f}')
            print(f'scan {key}, corner {match.group(1)}: x {x:.4f} m, y {y:.4f} m')
    if args.write:
        path.write_text(''.join(text))
        print(f'wrote {path}')
    return 0


def main(argv=None) -> int:
    """Run the chosen step."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    steps = p.add_subparsers(dest='step', required=True)
    look = steps.add_parser('plot', help='draw the median scan with beam indices')
    look.add_argument('recording', help='bag, JSON scan or folder of JSON scans')
    look.add_argument('--out', required=True, help='PNG to write')
    look.add_argument('--scans', default=None, help='FIRST-LAST still scans (default: all)')
    look.add_argument('--window', default=None, help='x0,x1,y0,y1 in m (default: all)')
    look.add_argument('--every', type=int, default=5, help='annotate every n-th beam')
    look.add_argument('--labels', default=None, help='label file to draw on top')
    place = steps.add_parser('fit', help="compute the labels' positions from their walls")
    place.add_argument('labels', help='label YAML (data/labels/<recording>.yaml)')
    place.add_argument('--write', action='store_true', help='save the positions in the file')
    args = p.parse_args(argv)
    return plot(args) if args.step == 'plot' else fit(args)


if __name__ == '__main__':
    sys.exit(main())
