# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``evaluate``: the paper's analysis on a bag of repeated scans from a still sensor.

Examples::

    evaluate out/env_a --out docs/results/env_a --range-sigma 0.05 --bearing-sigma-deg 0.391
    evaluate data/sick_lms111_static --out out/lms111                      # noise fitted
    evaluate out/env_a --out out/env_a_diag --propagation diagonal        # the paper's gap?

The noise calibration that prints the node's parameters is ``calibrate`` (calibrate_cli).
Exit status: 0 done; 2 a user error or a moving sensor (the measured drift against its bound),
one line on stderr; 3 no corner was associated across the scans, so no NEES could be measured
(one line on stderr, nothing written).
"""

import argparse
from dataclasses import replace
import math
import pathlib
import shlex
import sys

from wctls_ros.cli import bounded, Parser, start_core, USER_ERROR, UserError
from wctls_ros.core import METHODS
from wctls_ros.extras import explains_missing_extras, require
from wctls_ros.output_folders import claim, owned_folder
from wctls_ros.process import check_stop, ending_at_once, stop_signals, Stopped
from wctls_ros.sensors import sensor_presets

from .analysis import evaluate_scans, PROPAGATIONS
from .calibration import fit_noise, noise_of
from .rules import corners_per_scan_figure, MovingSensorError, require_still
from .scans import load_scans
from .score_cli import node_config
from ..simulation import NoiseModel

# Beyond the shared convention (0, 2 a user error): nothing to measure a NEES on.
NO_CORNER_EXIT = 3


def _methods(text: str) -> list:
    """Parse a comma-separated list of methods (an argparse type)."""
    methods = [m.strip() for m in text.split(',') if m.strip()]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown or not methods:
        raise argparse.ArgumentTypeError(f'unknown methods {unknown}; choose among {METHODS}')
    return methods


def evaluate_parser() -> argparse.ArgumentParser:
    """
    Return the parser of ``evaluate``.

    :return: the parser
    """
    p = Parser(
        prog='evaluate', description='Per-corner sigma tables, ellipse figure, per-scan '
        'median area box plots and the propagated-versus-empirical check (NEES) of UTLS, WTLS, '
        'WCTLS (and ML) on repeated scans from a still sensor.',
        epilog='Exit status: 0 done; 2 a user error or a moving sensor (one line on stderr); '
        '3 no corner associated across the scans (no NEES).')
    p.add_argument('bag', help='ROS 2 (mcap/sqlite3) or ROS 1 bag of scans from a still sensor')
    p.add_argument('--topic', default=None, help="LaserScan topic (default: the bag's only one)")
    p.add_argument('--limit', type=bounded(int, 1), default=None,
                   help='use at most this many scans (default: all)')
    p.add_argument('--out', required=True,
                   help='output folder (report.md, PNG, CSV): a new or empty folder, or an '
                   'earlier output of evaluate, which is replaced; required, no default')
    p.add_argument('--title', default=None, help='report title (default: the bag name)')
    p.add_argument('--methods', type=_methods, default='utls,wtls,wctls,ml',
                   help='comma-separated methods among ' + ', '.join(METHODS)
                   + ' (default: %(default)s)')
    p.add_argument('--propagation', choices=PROPAGATIONS, default='full',
                   help="'full': the correct propagation feature_node uses; 'diagonal': drop "
                   "the off-diagonal terms of each line's 3x3 covariance before the corner "
                   "(an analysis of the paper's results, never the node's behaviour) "
                   '(default: %(default)s)')
    p.add_argument('--params', default=None, metavar='FILE',
                   help='feature_node parameter file (as for --params-file): run the pipeline '
                   "with the node's settings and noise model instead of the paper's settings "
                   'and a fitted noise (default: none)')
    p.add_argument('--sensor', default=None, choices=tuple(sensor_presets()),
                   help="like --params, with this sensor preset over the file's (default: "
                   'none)')
    p.add_argument('--range-sigma', type=bounded(float, 0.0), default=None,
                   help='range noise std, m (default: that of --params or --sensor, else '
                   'fitted from the data)')
    p.add_argument('--bearing-sigma-deg', type=bounded(float, 0.0), default=None,
                   help='bearing noise std, deg (default: fitted with the range sigma)')
    p.add_argument('--common-range-sigma', type=bounded(float, 0.0), default=None,
                   help='per-scan common range offset std, m (default: fitted when the noise '
                   'is fitted, else 0)')
    p.add_argument('--min-presence', type=bounded(float, 0.0, 1.0), default=0.8,
                   help='keep corners found in at least this fraction of the scans '
                   '(default: %(default)s)')
    return p


def _noise(args, scans, base):
    """Return the noise model (given, the node's or fitted) and a note on where it came from."""
    if args.range_sigma is None and base is not None:
        noise = noise_of(base)
        return noise, (f'noise model of {args.params or "the node"}'
                       + (f' with sensor {args.sensor}' if args.sensor else ''))
    if args.range_sigma is None:
        fit = fit_noise(scans)
        noise = fit.noise
        if args.bearing_sigma_deg is not None:
            noise = replace(noise, bearing_sigma_rad=math.radians(args.bearing_sigma_deg))
        if args.common_range_sigma is not None:
            noise = replace(noise, common_range_sigma_m=args.common_range_sigma)
        return noise, (f'noise fitted from the ranges of {fit.wall_beams} wall beams '
                       f'(common-mode offset lag-1 correlation {fit.offset_lag1:.2f})')
    bearing = math.radians(args.bearing_sigma_deg or 0.0)
    return (NoiseModel(range_sigma_m=args.range_sigma, bearing_sigma_rad=bearing,
                       common_range_sigma_m=args.common_range_sigma or 0.0),
            'noise model given on the command line')


@explains_missing_extras('evaluate')
def main(argv=None) -> int:
    """
    Run ``evaluate``.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status: 0 done; 2 a user error, an unreadable bag or a moving sensor; 3 no
        NEES measured
    """
    from wctls_ros.bags import BagError
    args = evaluate_parser().parse_args(argv)
    try:
        with stop_signals():
            with ending_at_once('evaluate'):
                require('rosbags')     # reads bags: missing, the tool ends before it starts
                start_core('evaluate')
            return _evaluate(args, args.methods, argv)
    except Stopped as stopped:
        print(f'evaluate: stopped by {stopped}', file=sys.stderr)
        return 128 + stopped.signal_number
    except MovingSensorError as error:
        print(f'evaluate: error: refused: {error}', file=sys.stderr)
    except (BagError, UserError, ValueError) as error:
        print(f'evaluate: error: {error}', file=sys.stderr)
    return USER_ERROR


def _evaluate(args, methods, argv) -> int:
    """Load, check, analyse and write the report of ``evaluate``."""
    claim(args.out, 'evaluate')            # refused now rather than after the analysis
    with ending_at_once('evaluate'):       # steps of seconds that write nothing
        scans = load_scans(args.bag, args.topic, args.limit)
        still = require_still(scans)
    check_stop()
    base = (node_config(args.params, args.sensor) if args.params or args.sensor else None)
    noise, origin = _noise(args, scans, base)
    evaluation = evaluate_scans(scans, noise, methods, args.propagation, args.min_presence,
                                base)
    check_stop()
    unmeasured = [m for m in methods if not math.isfinite(evaluation.pooled_nees(m))]
    if unmeasured:
        print(f'evaluate: error: no NEES for {", ".join(unmeasured)}: no corner was found in '
              f'{100 * args.min_presence:.0f} % of the {len(scans)} scans (--min-presence; '
              'corners per scan: ' + ', '.join(
                  f'{m} {corners_per_scan_figure(evaluation.per_scan[m]):.3f}'
                  for m in methods) + '), so none could be compared with its scatter; '
              'nothing written', file=sys.stderr)
        return NO_CORNER_EXIT
    command = 'evaluate ' + ' '.join(shlex.quote(a) for a in
                                     (sys.argv[1:] if argv is None else argv))
    notes = [origin, f'stillness check: {still.describe()}']
    try:
        with owned_folder(args.out, 'evaluate') as staging:
            # Importing matplotlib and drawing: steps of a second or two beside a busy machine.
            with ending_at_once('evaluate', removing=staging):
                from .report import summary_rows, write_report
                written = write_report(evaluation, staging, args.title or str(args.bag),
                                       command, notes)
            check_stop()                # before the files move in: a stop leaves nothing
    except OSError as error:                # a full disk, a file-size limit, no permission
        raise ValueError(f'cannot write {args.out}: {error.strerror or error}') from error
    path = pathlib.Path(args.out) / written.name
    print(f'evaluate: {len(scans)} scans, {len(evaluation.centers)} corners, noise '
          f'{noise.describe()}, propagation {args.propagation}')
    for row in summary_rows(evaluation):
        print(f'  {row[0]:6s} pooled NEES {row[2]:7.2f}  median corner NEES {row[3]:7.2f}  '
              f'median area ratio {row[4]:6.2f}  per-scan median area {row[5]:9.1f} mm^2')
    for method in methods:
        print(f'  {method:6s} corners per scan '
              f'{corners_per_scan_figure(evaluation.per_scan[method]):.3f}')
    print(f'evaluate: wrote {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
