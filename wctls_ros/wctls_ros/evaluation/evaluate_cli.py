# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``evaluate`` and ``calibrate``: the paper's analysis and the noise calibration on a bag.

Examples::

    evaluate out/env_a --out docs/results/env_a --range-sigma 0.05 --bearing-sigma-deg 0.391
    evaluate ../shared/data/sick_lms111_static --out out/lms111            # noise fitted
    evaluate out/env_a --out out/env_a_diag --propagation diagonal        # the paper's gap?
    calibrate ../shared/data/sick_lms111_static                          # YAML for the node
"""

import argparse
import math
import pathlib
import shlex
import sys

from .analysis import evaluate_scans, PROPAGATIONS
from .calibration import fit_noise, node_yaml
from .samples import NoiseParameters
from .scans import load_scans, MovingSensorError, require_still
from ..cli import staged_folder
from ..core import METHODS


def _common_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('bag', help='ROS 2 (mcap/sqlite3) or ROS 1 bag of scans from a still sensor')
    p.add_argument('--topic', default=None, help="LaserScan topic (default: the bag's only one)")
    p.add_argument('--limit', type=int, default=None, help='use at most this many scans')


def evaluate_parser() -> argparse.ArgumentParser:
    """
    Return the parser of ``evaluate``.

    :return: the parser
    """
    p = argparse.ArgumentParser(
        prog='evaluate', description='Per-corner sigma tables, ellipse figure, per-scan '
        'median area box plots and the propagated-versus-empirical check (NEES) of UTLS, WTLS, '
        'WCTLS (and ML) on repeated scans from a still sensor.')
    _common_arguments(p)
    p.add_argument('--out', required=True, help='output folder (report.md, PNG, CSV)')
    p.add_argument('--title', default=None, help='report title (default: the bag name)')
    p.add_argument('--methods', default='utls,wtls,wctls,ml',
                   help='comma-separated methods among ' + ', '.join(METHODS))
    p.add_argument('--propagation', choices=PROPAGATIONS, default='full',
                   help="'full': the correct propagation feature_node uses; 'diagonal': drop "
                   "the off-diagonal terms of each line's 3x3 covariance before the corner "
                   "(an analysis of the paper's results, never the node's behaviour)")
    p.add_argument('--range-sigma', type=float, default=None,
                   help='range noise std, m (default: fitted from the data)')
    p.add_argument('--bearing-sigma-deg', type=float, default=None,
                   help='bearing noise std, deg (default: fitted with the range sigma)')
    p.add_argument('--common-range-sigma', type=float, default=None,
                   help='per-scan common range offset std, m (default: fitted when the noise '
                   'is fitted, else 0)')
    p.add_argument('--min-presence', type=float, default=0.8,
                   help='keep corners found in at least this fraction of the scans')
    return p


def _noise(args, scans):
    """Return the noise model (given or fitted) and a note on where it came from."""
    if args.range_sigma is None:
        fit = fit_noise(scans)
        noise = fit.noise
        if args.bearing_sigma_deg is not None:
            noise = NoiseParameters(noise.range_sigma_m, math.radians(args.bearing_sigma_deg),
                                    noise.common_range_sigma_m)
        if args.common_range_sigma is not None:
            noise = NoiseParameters(noise.range_sigma_m, noise.bearing_sigma_rad,
                                    args.common_range_sigma)
        return noise, (f'noise fitted from the ranges of {fit.wall_beams} wall beams '
                       f'(common-mode offset lag-1 correlation {fit.offset_lag1:.2f})')
    bearing = math.radians(args.bearing_sigma_deg or 0.0)
    return (NoiseParameters(args.range_sigma, bearing, args.common_range_sigma or 0.0),
            'noise model given on the command line')


def main(argv=None) -> int:
    """
    Run ``evaluate``.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status (2 for a moving sensor)
    """
    args = evaluate_parser().parse_args(argv)
    methods = [m.strip() for m in args.methods.split(',') if m.strip()]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown or not methods:
        print(f'evaluate: unknown methods {unknown}; choose among {METHODS}', file=sys.stderr)
        return 1
    return _guarded('evaluate', lambda: _evaluate(args, methods, argv))


def _guarded(prog: str, work) -> int:
    """Run a command's work; a moving sensor exits 2, an unreadable input 1, with the reason."""
    from ..bags import BagError
    try:
        return work()
    except MovingSensorError as error:
        print(f'{prog}: refused: {error}', file=sys.stderr)
        return 2
    except (BagError, ValueError) as error:
        print(f'{prog}: {error}', file=sys.stderr)
        return 1


def _evaluate(args, methods, argv) -> int:
    """Load, check, analyse and write the report of ``evaluate``."""
    scans = load_scans(args.bag, args.topic, args.limit)
    still = require_still(scans)
    noise, origin = _noise(args, scans)
    evaluation = evaluate_scans(scans, noise, methods, args.propagation, args.min_presence)
    from .report import summary_rows, write_report
    command = 'evaluate ' + ' '.join(shlex.quote(a) for a in
                                     (sys.argv[1:] if argv is None else argv))
    notes = [origin, f'stillness check: {still.steady_beams} steady beams, '
             f'{100 * still.drifted_fraction:.1f} % drifted (refused above 10 %)']
    try:
        with staged_folder(args.out) as staging:
            written = write_report(evaluation, staging, args.title or str(args.bag), command,
                                   notes)
    except OSError as error:                # a full disk, a file-size limit, no permission
        raise ValueError(f'cannot write {args.out}: {error.strerror or error}') from error
    path = pathlib.Path(args.out) / written.name
    print(f'evaluate: {len(scans)} scans, {len(evaluation.centers)} corners, noise '
          f'{noise.describe()}, propagation {args.propagation}')
    for row in summary_rows(evaluation):
        print(f'  {row[0]:6s} pooled NEES {row[2]:7.2f}  median corner NEES {row[3]:7.2f}  '
              f'median area ratio {row[4]:6.2f}  per-scan median area {row[5]:9.1f} mm^2')
    print(f'evaluate: wrote {path}')
    return 0


def calibrate_parser() -> argparse.ArgumentParser:
    """
    Return the parser of ``calibrate``.

    :return: the parser
    """
    p = argparse.ArgumentParser(
        prog='calibrate', description='Fit the range / bearing / common-mode noise of a sensor '
        'from a static recording, check it on the corners (NEES) and print the feature_node '
        'parameters.')
    _common_arguments(p)
    p.add_argument('--method', default='wtls', choices=METHODS,
                   help='method whose corner NEES checks the fit')
    return p


def calibrate(scans, method: str = 'wtls'):
    """
    Fit the noise model and measure the corner NEES with and without its common-mode term.

    :param scans: static scans
    :param method: the line fit used for the check
    :return: (NoiseFit, NEES with the independent terms only, NEES with the full model,
        scale of the fitted sigmas that brings the NEES of the full model to 2)
    """
    fit = fit_noise(scans)
    independent = NoiseParameters(fit.noise.range_sigma_m, fit.noise.bearing_sigma_rad)
    nees_independent = evaluate_scans(scans, independent, [method]).pooled_nees(method)
    nees_full = evaluate_scans(scans, fit.noise, [method]).pooled_nees(method)
    scale = math.sqrt(nees_full / 2.0) if math.isfinite(nees_full) else 1.0
    return fit, nees_independent, nees_full, scale


def calibrate_main(argv=None) -> int:
    """
    Run ``calibrate``.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status (2 for a moving sensor)
    """
    args = calibrate_parser().parse_args(argv)
    return _guarded('calibrate', lambda: _calibrate(args))


def _calibrate(args) -> int:
    """Load, check and fit the recording of ``calibrate`` and print the results."""
    scans = load_scans(args.bag, args.topic, args.limit)
    require_still(scans)
    fit, nees_independent, nees_full, scale = calibrate(scans, args.method)
    print(f'# calibrate {args.bag}: {len(scans)} scans, {fit.wall_beams} wall beams')
    print(f'# fitted: {fit.noise.describe()} (offset lag-1 correlation '
          f'{fit.offset_lag1:.2f})')
    print(f'# corner NEES ({args.method}, 2 = calibrated): independent terms only '
          f'{nees_independent:.2f}, with the common-mode term {nees_full:.2f}')
    print(node_yaml(fit.noise, scale))
    return 0


if __name__ == '__main__':
    sys.exit(main())
