# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
``calibrate``: fit a sensor's noise model on a static recording, check it, print node params.

Examples::

    calibrate data/sick_lms111_static > lms111.yaml          # fit, check, print the YAML
    calibrate data/sick_lms111_static --holdout              # + fit on each half, check on other
    calibrate data/sick_lms111_static --validate other_bag   # + check the fit on another bag
    calibrate data/sick_lms111_static --write-preset my_lms.yaml      # a sensor preset file
    calibrate --params lms111.yaml --validate other_bag      # check a parameter file only
    calibrate --sensor sick_lms1xx --validate other_bag      # check a shipped preset

The method and its thresholds are in :mod:`.calibration` and :mod:`.corner_check`; how to add
a sensor with it, in docs/sensors.md. Offline: reads bags with rosbags and never starts ROS.
Exit status: 0 the model is printed (warnings on stderr); 2 a user error (bad option, path,
bag, parameter file, a sensor or scene that moved: the measured drift against its bound), one
line on stderr; 3 the model is implausible or cannot be validated (on the recording, the
held-out scans or a --validate bag: no stable corner, the extractor loses the corners with it,
NEES or beam scatter out of bounds): the reasons on stderr, and no YAML (nor preset file)
unless --accept-implausible.
"""

import argparse
import math
import os
import pathlib
import secrets
import sys
from typing import List, Optional, Sequence

from wctls_ros.cli import bounded, Parser, start_core, USER_ERROR, UserError
from wctls_ros.core import FeatureConfig, METHODS
from wctls_ros.extras import explains_missing_extras, require
from wctls_ros.process import check_stop, ending_at_once, stop_signals, Stopped
from wctls_ros.sensors import DEFAULT_SENSOR, sensor_presets

from .calibration import (calibrate, Calibration, Finding, node_yaml, noise_of, preset_yaml,
                          validate, Validation)
from .corner_check import CornerNees, TrackedCorner
from .rules import require_still
from .scans import load_scans, StaticScans
from .score_cli import node_config
from ..simulation import NoiseModel

# Beyond the shared convention (0, 2 a user error, :mod:`wctls_ros.cli`): a model refused.
IMPLAUSIBLE_EXIT = 3
# The first line of every preset file calibrate writes: --write-preset replaces only such a file.
PRESET_MARK = '# written by calibrate of wctls_ros: a later calibrate --write-preset replaces it'


def parser() -> argparse.ArgumentParser:
    """
    Return the parser of ``calibrate``.

    :return: the parser
    """
    p = Parser(
        prog='calibrate', description='Fit the range / bearing / common-mode noise of a sensor '
        'from a static recording (robust to people walking through it), check it on the '
        "stable corners' NEES, and print the feature_node parameters. With --validate, check "
        'the model (or a --params file) on other recordings.',
        epilog='Exit status: 0 the model is printed; 2 a user error or a moving sensor (one '
        'line on stderr); 3 the model is implausible or cannot be validated: no stable '
        'corner, or fewer corners per scan than before (reasons on stderr, no YAML unless '
        '--accept-implausible).')
    p.add_argument('bag', nargs='?', default=None,
                   help='ROS 2 (mcap/sqlite3) or ROS 1 bag of scans from a still sensor to fit '
                   'the model on; without it, --validate checks the --params model only')
    p.add_argument('--topic', default=None,
                   help="LaserScan topic of every bag (default: each bag's only one)")
    p.add_argument('--limit', type=bounded(int, 6), default=None,
                   help='use at most this many scans of each bag, at least 6 (default: all)')
    p.add_argument('--params', default=None, metavar='FILE',
                   help='feature_node parameter file (as for --params-file): the pipeline '
                   'settings to fit under and the model "before" (default: the node\'s '
                   'defaults); without a bag, the model --validate checks')
    p.add_argument('--sensor', default=None, choices=tuple(sensor_presets()),
                   help='sensor preset over the --params file\'s, as the model "before" and, '
                   "without a bag, the model --validate checks (default: the file's, else "
                   f'{DEFAULT_SENSOR})')
    p.add_argument('--method', default=None, choices=METHODS,
                   help='line fit whose corners check the model (default: that of --params, '
                   f"else the node's, {FeatureConfig().method})")
    p.add_argument('--validate', action='append', default=[], metavar='BAG',
                   help='check the model on this recording too (repeatable): per-corner NEES '
                   'and per-beam scatter (default: none)')
    p.add_argument('--holdout', action='store_true',
                   help='also fit on the first half of the scans and check on the second, and '
                   'the other way round (default: off)')
    p.add_argument('--write-preset', default=None, metavar='FILE',
                   help='also write the fitted model as a sensor preset file (as '
                   'config/sensors/NAME.yaml; feature_node reads it from there as sensor NAME): '
                   'a new file, or one an earlier --write-preset wrote (default: none)')
    p.add_argument('--accept-implausible', action='store_true',
                   help='print the YAML of an implausible model anyway, with the reasons as '
                   'comments, and exit 0 (default: off: refuse it, exit 3)')
    return p


@explains_missing_extras('calibrate')
def main(argv=None) -> int:
    """
    Run ``calibrate``.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status: 0, 2 on a user error, 3 on an implausible model
    """
    args = parser().parse_args(argv)
    from wctls_ros.bags import BagError
    try:
        with stop_signals():
            with ending_at_once('calibrate'):
                require('rosbags')     # reads bags: missing, the tool ends before it starts
                start_core('calibrate')
            return run(args)
    except Stopped as stopped:
        print(f'calibrate: stopped by {stopped}', file=sys.stderr)
        return 128 + stopped.signal_number
    except (BagError, OSError, ValueError) as error:
        message = str(error).splitlines()[0] if str(error) else type(error).__name__
        print(f'calibrate: error: {message}', file=sys.stderr)
        return USER_ERROR


def run(args) -> int:
    """Load, fit, check and print; raise on what the user gave wrong."""
    if args.bag is None and not args.validate:
        raise UserError('give a bag to calibrate on, or --validate BAG to check a model')
    if args.bag is None and args.holdout:
        raise UserError('--holdout needs a bag to calibrate on')
    if args.bag is None and args.write_preset:
        raise UserError('--write-preset needs a bag to calibrate on')
    if args.write_preset:                   # refused now rather than after the fit
        _claim_preset(pathlib.Path(args.write_preset))
    config = node_config(args.params, args.sensor)
    if args.method is not None:
        config = config.replace(method=args.method)
    origin = ' with sensor '.join(filter(None, [args.params or "the node's defaults",
                                                args.sensor]))
    findings: List[Finding] = []
    model = config
    calibration = None
    if args.bag is not None:
        scans = _load(args.bag, args)
        count = len(scans)
        calibration = calibrate(scans, config)
        _print_calibration(args.bag, scans, calibration, config, origin)
        findings += _tagged(calibration.findings, str(args.bag))
        model = calibration.final_config
        if args.holdout:
            findings += _holdout(scans, config)
    for bag in args.validate:
        scans = _load(bag, args)
        validation = validate(scans, model)
        _print_validation(bag, scans, validation,
                          'the fitted model' if calibration else f'the model of {origin}')
        findings += _tagged(validation.findings, f'validated on {bag}')
    check_stop()
    implausible = any(f.implausible for f in findings)
    for finding in findings:
        print(f'calibrate: {"IMPLAUSIBLE" if finding.implausible else "warning"}: '
              f'{finding.text}', file=sys.stderr)
    if calibration is not None and (not implausible or args.accept_implausible):
        notes = [f'{"IMPLAUSIBLE" if f.implausible else "warning"}: {f.text}' for f in findings]
        print(node_yaml(calibration.noise, calibration.published_config, notes))
        if args.write_preset:
            preset = pathlib.Path(args.write_preset)
            refused = [f.text for f in findings if f.implausible]
            _write_preset(preset, preset_yaml(calibration, str(args.bag), count, refused))
            print(f'calibrate: wrote the sensor preset {preset}', file=sys.stderr)
    if implausible and not args.accept_implausible:
        print('calibrate: refused: the model is implausible (reasons above); '
              '--accept-implausible prints it anyway', file=sys.stderr)
        return IMPLAUSIBLE_EXIT
    return 0


def _claim_preset(path: pathlib.Path) -> None:
    """Refuse a preset path that holds anything but a preset file calibrate wrote."""
    if not path.exists() and not path.is_symlink():
        return
    try:
        first = path.read_text().splitlines()[:1]
    except (OSError, UnicodeDecodeError):
        first = []
    if first != [PRESET_MARK]:
        raise UserError(f'--write-preset: {path} exists and is not a preset file calibrate '
                        'wrote: refusing to overwrite it; remove it or choose another name')


def _write_preset(path: pathlib.Path, text: str) -> None:
    """
    Write a preset file whole or not at all (a temporary file beside it, then a rename).

    The temporary file is created exclusively (O_EXCL), under a name of its own: never through
    a file or link someone left there. Its mode is the umask's, as for any file written.
    """
    _claim_preset(path)
    partial = path.with_name(f'.partial-{path.name}-{secrets.token_hex(8)}')
    descriptor = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(descriptor, 'w') as file:
            file.write(f'{PRESET_MARK}\n{text}')
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)


def _load(path, args) -> StaticScans:
    """Read a bag's scans and refuse a sensor or scene that moved."""
    if not pathlib.Path(path).exists():
        raise UserError(f'{path}: no such bag')
    with ending_at_once('calibrate'):      # steps of seconds that write nothing
        scans = load_scans(path, args.topic, args.limit)
        require_still(scans)
    check_stop()
    return scans


def _tagged(findings: Sequence[Finding], where: str) -> List[Finding]:
    """Return findings with where they were found in front."""
    return [Finding(f.implausible, f'{where}: {f.text}') for f in findings]


def _halves(scans: StaticScans):
    """Return the first and the second half of the scans."""
    middle = len(scans) // 2
    return scans.part(0, middle), scans.part(middle, len(scans))


def _holdout(scans: StaticScans, config: FeatureConfig) -> List[Finding]:
    """Fit on each half of the scans, check on the other; print and return the findings."""
    findings = []
    first, second = _halves(scans)
    names = (f'scans 0-{len(first) - 1}', f'scans {len(first)}-{len(scans) - 1}')
    for (fit_on, fit_name), (check_on, check_name) in (
            ((first, names[0]), (second, names[1])), ((second, names[1]), (first, names[0]))):
        calibration = calibrate(fit_on, config)
        validation = validate(check_on, calibration.final_config)
        print(f'# holdout: fitted on {fit_name}: {calibration.noise.describe()}, wall flatness '
              f'{1e3 * calibration.flatness_m:.2f} mm; checked on {check_name}: it predicts '
              f"{validation.beam_ratio:.2f} times the beams' scatter")
        _print_corners(validation.corners, validation.stable, validation.nees,
                       {'NEES': validation.nees})
        findings += _tagged(calibration.findings, f'holdout, fitted on {fit_name}')
        findings += _tagged(validation.findings, f'holdout, checked on {check_name}')
    return findings


def _print_calibration(bag, scans: StaticScans, calibration: Calibration,
                       before: FeatureConfig, origin: str) -> None:
    """Print what the fit found and the corner table, as YAML comments."""
    fit, config = calibration.fit, calibration.config
    from_scan = (", or each scan's own range noise when larger" if before.range_sigma_from_scan
                 else '')
    crossed = (f'{int(fit.crossed.sum())} returns crossed by something in {fit.crossed_scans} '
               'scans (left out)' if fit.crossed.any() else 'nothing crossed the walls')
    print(f'# calibrate {bag}: {len(scans)} scans, {fit.wall_beams} wall beams, {crossed}')
    print(f'# fitted from the beams: {fit.noise.describe()} (offset lag-1 correlation '
          f'{fit.offset_lag1:.2f}); it predicts {fit.beam_ratio(fit.noise):.2f} times the '
          "beams' scatter")
    print(f'# corner NEES ({config.method}, residual scaling '
          f'{"on" if config.residual_scaling else "off"}, wall flatness '
          f'{1e3 * config.wall_flatness_sigma_m:g} mm; 2 = calibrated); before: {origin} '
          f'({_describe(noise_of(before))}{from_scan})')
    print(f'# corners per scan {calibration.corners_per_scan_final:.3f} with the final model, '
          f'{calibration.corners_per_scan_before:.3f} before ({origin})')
    _print_corners(calibration.corners, calibration.stable, calibration.fitted,
                   {'before': calibration.before, 'fitted': calibration.fitted,
                    'final': calibration.final})
    stable = sum(calibration.stable)
    if stable:
        print(f'# final: wall flatness {1e3 * calibration.flatness_m:.2f} mm (the scatter of the '
              f'stable corners beyond the noise: x{calibration.excess:.2f} in std), which brings '
              f'the pooled NEES of the {stable} stable corner{"s" if stable > 1 else ""} to '
              f'{calibration.pooled(calibration.final):.2f} (fitted: '
              f'{calibration.pooled(calibration.fitted):.2f}, before: '
              f'{calibration.pooled(calibration.before):.2f})')


def _print_validation(bag, scans: StaticScans, validation: Validation, what: str) -> None:
    """Print the check of a model on another recording, as YAML comments."""
    print(f'# validate {what} on {bag}: {len(scans)} scans; it predicts '
          f"{validation.beam_ratio:.2f} times the beams' scatter, which the recording's own fit "
          f'puts at {_describe(validation.fit.noise)}')
    print(f'# corners per scan {validation.corners_per_scan:.3f} with {what}')
    _print_corners(validation.corners, validation.stable, validation.nees,
                   {'NEES': validation.nees})
    if any(validation.stable):
        print(f'# pooled NEES of the stable corners: {validation.pooled:.2f}')


def _describe(noise: NoiseModel) -> str:
    """Return a model's sigmas in short."""
    return (f'range {1e3 * noise.range_sigma_m:.2f} mm, bearing '
            f'{math.degrees(noise.bearing_sigma_rad):.3f} deg, common '
            f'{1e3 * noise.common_range_sigma_m:.2f} mm')


def _print_corners(corners: Sequence[TrackedCorner], stable: Sequence[bool],
                   counts: Sequence[CornerNees], columns: dict) -> None:
    """
    Print one row per tracked corner: position, scans, stability, NEES per model.

    :param corners: the tracked corners
    :param stable: which are stable
    :param counts: the results whose scans found and jumps are shown (the tracking model's)
    :param columns: column title -> one result per corner
    """
    if not corners:
        print('#   no corner found in half of the scans')
        return
    print('#   corner     x m     y m  clear  found  jumps  stable '
          + ' '.join(f'{name:>7s}' for name in columns))
    for k, corner in enumerate(corners):
        values = ' '.join(_number(results[k].nees) for results in columns.values())
        print(f'#   {k + 1:6d} {corner.center_xy_m[0]:7.3f} {corner.center_xy_m[1]:7.3f} '
              f'{int(corner.clear.sum()):6d} {counts[k].found:6d} {counts[k].jumps:6d}  '
              f'{"yes" if stable[k] else "no":6s} {values}')


def _number(value: Optional[float]) -> str:
    """Return a NEES in a column of 7."""
    return f'{value:7.2f}' if value is not None and math.isfinite(value) else '      -'


if __name__ == '__main__':
    sys.exit(main())
