# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The evaluation's outputs: the paper's tables and figures, the consistency tables, CSV files.

Figures are drawn with matplotlib's Agg backend (no display needed) into small PNGs.
"""

import csv
import math
import pathlib
import textwrap
from typing import List, Sequence

import numpy as np

from .analysis import Evaluation
from ..plotting import add_covariance_ellipses, PAPER_ELLIPSE_SCALE as ELLIPSE_SCALE, pyplot

COLOURS = {'utls': 'tab:blue', 'wtls': 'tab:green', 'wctls': 'tab:red', 'ml': 'tab:gray'}
LABELS = {'utls': 'UTLS', 'wtls': 'WTLS', 'wctls': 'WCTLS', 'ml': 'ML'}


def sigma_table(evaluation: Evaluation) -> List[list]:
    """
    Return the per-corner sigma_x, sigma_y of the representative scan (Tables 1-2), in mm.

    :param evaluation: the evaluation
    :return: rows [corner number, sigma_x, sigma_y per method...] (NaN where not found)
    """
    t = evaluation.representative
    rows = []
    for k in range(len(evaluation.centers)):
        row = [k + 1]
        for method in evaluation.methods:
            i = evaluation.assignment[method][t, k]
            if i < 0:
                row += [math.nan, math.nan]
                continue
            cov = evaluation.per_scan[method][t].covariances(evaluation.propagation)[i]
            row += [1e3 * math.sqrt(cov[0, 0]), 1e3 * math.sqrt(cov[1, 1])]
        rows.append(row)
    return rows


def consistency_rows(evaluation: Evaluation) -> List[list]:
    """
    Return per corner and method: scans found, empirical and propagated sigmas, ratio, NEES.

    :param evaluation: the evaluation
    :return: rows [corner, x m, y m, method, scans, emp sx mm, emp sy mm, prop sx mm,
        prop sy mm, area ratio, NEES]
    """
    rows = []
    for k, center in enumerate(evaluation.centers):
        for method in evaluation.methods:
            s = evaluation.stats[method][k]
            emp = 1e3 * np.sqrt(np.diag(s.empirical_cov))
            prop = 1e3 * np.sqrt(np.diag(s.propagated_cov))
            rows.append([k + 1, center[0], center[1], method, s.count, emp[0], emp[1], prop[0],
                         prop[1], s.area_ratio, s.nees])
    return rows


def summary_rows(evaluation: Evaluation) -> List[list]:
    """
    Return per method: corners, pooled and median NEES, median area ratio, per-scan areas.

    :param evaluation: the evaluation
    :return: rows [method, corners, pooled NEES, median corner NEES, median area ratio,
        median of per-scan median areas mm^2, their std mm^2]
    """
    rows = []
    for method in evaluation.methods:
        stats = evaluation.stats[method]
        areas = evaluation.scan_median_areas(method)
        rows.append([method, len(stats), evaluation.pooled_nees(method),
                     float(np.nanmedian([s.nees for s in stats])) if stats else math.nan,
                     float(np.nanmedian([s.area_ratio for s in stats])) if stats else math.nan,
                     float(np.nanmedian(areas)), float(np.nanstd(areas))])
    return rows


def _write_csv(path: pathlib.Path, header: Sequence[str], rows: List[list]) -> None:
    with path.open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for row in rows:
            writer.writerow([f'{v:.6g}' if isinstance(v, float) else v for v in row])


def _markdown_table(header: Sequence[str], rows: List[list], digits: int = 2) -> str:
    def cell(value):
        if isinstance(value, float):
            return '-' if math.isnan(value) else f'{value:.{digits}f}'
        return str(value)
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(cell(v) for v in row) + ' |' for row in rows]
    return '\n'.join(lines)


def plot_scan(evaluation: Evaluation, path: pathlib.Path, title: str) -> None:
    """
    Draw the representative scan with segments, numbered corners and ellipses x10 (Fig. 3).

    :param evaluation: the evaluation
    :param path: PNG to write
    :param title: figure title
    """
    from .samples import feature_config, scan_corners
    plt = pyplot()
    scans, t = evaluation.scans, evaluation.representative
    ranges = scans.ranges[t]
    valid = scans.valid()[t]
    bearings = scans.bearings
    fig, ax = plt.subplots(figsize=(7.0, 5.0), dpi=90)
    ax.plot(ranges[valid] * np.cos(bearings[valid]), ranges[valid] * np.sin(bearings[valid]),
            '.', color='0.55', ms=1.5, label='returns')
    method = 'wtls' if 'wtls' in evaluation.methods else evaluation.methods[0]
    features, _ = scan_corners(ranges, scans.angle_min, scans.angle_increment,
                               scans.range_min, scans.range_max,
                               feature_config(evaluation.noise, method))
    for k, segment in enumerate(features.segments):
        ax.plot([segment.start_xy_m[0], segment.end_xy_m[0]],
                [segment.start_xy_m[1], segment.end_xy_m[1]], '-', color='black', lw=1.0,
                label='segments' if k == 0 else None)
    for method in evaluation.methods:
        if method == 'ml':
            continue
        corners = evaluation.per_scan[method][t]
        found = evaluation.assignment[method][t]
        found = found[found >= 0]
        add_covariance_ellipses(ax, corners.xy[found],
                                corners.covariances(evaluation.propagation)[found],
                                ELLIPSE_SCALE, COLOURS[method],
                                f'{LABELS[method]} x{ELLIPSE_SCALE:g}')
    for k, center in enumerate(evaluation.centers):
        ax.plot(*center, 'k^', ms=4)
        ax.annotate(str(k + 1), center, textcoords='offset points', xytext=(4, 4), fontsize=7)
    ax.plot(0.0, 0.0, 'r*', ms=8, label='sensor')
    ax.set_aspect('equal')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.set_title(textwrap.fill(title, 60), fontsize=8)
    ax.legend(fontsize=7, loc='best')
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_areas(evaluation: Evaluation, path: pathlib.Path, title: str) -> None:
    """
    Draw box plots of the per-scan median ellipse area per method on a log axis (Fig. 4).

    :param evaluation: the evaluation
    :param path: PNG to write
    :param title: figure title
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.0, 4.0), dpi=90)
    data = [evaluation.scan_median_areas(m) for m in evaluation.methods]
    data = [d[np.isfinite(d)] for d in data]
    box = ax.boxplot(data, whis=1.5, patch_artist=True)
    ax.set_xticks(range(1, len(data) + 1), [LABELS[m] for m in evaluation.methods])
    for patch, method in zip(box['boxes'], evaluation.methods):
        patch.set_facecolor(COLOURS[method])
        patch.set_alpha(0.5)
    ax.set_yscale('log')
    ax.set_ylabel('per-scan median 1-sigma ellipse area (mm$^2$)')
    ax.set_title(textwrap.fill(title, 60), fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_consistency(evaluation: Evaluation, path: pathlib.Path, title: str) -> None:
    """
    Draw per corner the propagated / empirical ellipse area and the NEES of each method.

    :param evaluation: the evaluation
    :param path: PNG to write
    :param title: figure title
    """
    plt = pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 5.0), dpi=90, sharex=True)
    count = len(evaluation.centers)
    width = 0.8 / max(len(evaluation.methods), 1)
    for j, method in enumerate(evaluation.methods):
        x = np.arange(1, count + 1) + (j - (len(evaluation.methods) - 1) / 2) * width
        stats = evaluation.stats[method]
        top.bar(x, [s.area_ratio for s in stats], width, color=COLOURS[method],
                label=LABELS[method])
        bottom.bar(x, [s.nees for s in stats], width, color=COLOURS[method])
    top.axhline(1.0, color='k', lw=0.8)
    top.set_yscale('log')
    top.set_ylabel('propagated / empirical\nellipse area')
    top.legend(fontsize=7, ncol=len(evaluation.methods))
    bottom.axhline(2.0, color='k', lw=0.8)
    bottom.set_yscale('log')
    bottom.set_ylabel('mean NEES (2 = calibrated)')
    bottom.set_xlabel('corner')
    if count:
        bottom.set_xticks(range(1, count + 1))
    top.set_title(textwrap.fill(title, 80), fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_report(evaluation: Evaluation, out_dir, title: str, command: str = '',
                 notes: Sequence[str] = ()) -> pathlib.Path:
    """
    Write report.md, the figures (PNG) and the tables (CSV) of an evaluation.

    :param evaluation: the evaluation
    :param out_dir: output folder (created)
    :param title: heading of the report
    :param command: the command that regenerates it (shown in the report)
    :param notes: extra lines (e.g. the stillness check, the calibration)
    :return: the path of report.md
    """
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    methods = [LABELS[m] for m in evaluation.methods]
    diagonal = evaluation.propagation == 'diagonal'
    label = ' [diagonal line covariances: analysis only]' if diagonal else ''
    sigma_rows = sigma_table(evaluation)
    sigma_header = ['corner'] + [f'{m} {axis}' for m in methods for axis in ('sx', 'sy')]
    _write_csv(out / 'corner_sigmas.csv', [h.replace(' ', '_') for h in sigma_header],
               sigma_rows)
    rows = consistency_rows(evaluation)
    _write_csv(out / 'corner_consistency.csv',
               ['corner', 'x_m', 'y_m', 'method', 'scans', 'empirical_sx_mm',
                'empirical_sy_mm', 'propagated_sx_mm', 'propagated_sy_mm', 'area_ratio',
                'nees'], rows)
    areas = np.column_stack([evaluation.scan_median_areas(m) for m in evaluation.methods])
    _write_csv(out / 'scan_median_areas.csv', ['scan'] + [f'{m}_mm2' for m in
                                                          evaluation.methods],
               [[t] + [float(v) for v in row] for t, row in enumerate(areas)])
    summary = summary_rows(evaluation)
    _write_csv(out / 'summary.csv', ['method', 'corners', 'pooled_nees', 'median_corner_nees',
                                     'median_area_ratio', 'median_scan_area_mm2',
                                     'std_scan_area_mm2'], summary)
    plot_scan(evaluation, out / 'fig3_scan.png', f'{title}: scan {evaluation.representative}, '
              f'ellipses x{ELLIPSE_SCALE:g}{label}')
    plot_areas(evaluation, out / 'fig4_areas.png', f'{title}{label}')
    plot_consistency(evaluation, out / 'fig5_consistency.png', f'{title}{label}')

    scans = evaluation.scans
    lines = [f'# {title}{label}', '']
    if command:
        lines += ['Regenerate with:', '', f'    {command}', '']
    lines += [f'- scans: {len(scans)} of {scans.ranges.shape[1]} beams from '
              f'`{scans.source}`',
              f'- noise model: {evaluation.noise.describe()}',
              f'- propagation: {evaluation.propagation}'
              + (' (each line covariance reduced to its diagonal before the corner: a test '
                 "of the paper's gap, not what feature_node does)" if diagonal else
                 ' (full 3x3 line covariances, as feature_node)'),
              f'- corners associated across scans: {len(evaluation.centers)}; representative '
              f'scan {evaluation.representative}']
    lines += [f'- {note}' for note in notes]
    lines += ['', '## Summary', '',
              _markdown_table(['method', 'corners', 'pooled NEES', 'median corner NEES',
                               'median area ratio (prop/emp)', 'per-scan median area mm^2',
                               'std mm^2'],
                              [[LABELS[r[0]]] + r[1:] for r in summary]),
              '', 'NEES: mean of e^T C^-1 e over the scans, e = position minus its mean over '
              'the scans; 2 when the propagated covariance matches the real scatter. Area: '
              '1-sigma ellipse pi sqrt(det C).', '',
              f"## Corner sigmas of scan {evaluation.representative} (mm, as the paper's "
              'Tables 1-2)', '',
              _markdown_table(sigma_header, sigma_rows), '',
              '## Propagated versus empirical scatter per corner', '',
              _markdown_table(['corner', 'x m', 'y m', 'method', 'scans', 'emp sx', 'emp sy',
                               'prop sx', 'prop sy', 'area ratio', 'NEES'],
                              [r[:3] + [LABELS[r[3]]] + r[4:] for r in rows]), '',
              '## Figures', '',
              '![scan with ellipses](fig3_scan.png)', '',
              '![per-scan median ellipse area](fig4_areas.png)', '',
              '![propagated vs empirical](fig5_consistency.png)', '']
    path = out / 'report.md'
    path.write_text('\n'.join(lines))
    return path
