# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The paper's evaluation on repeated scans from a still sensor, and what the paper lacks.

Pure analysis (numpy, matplotlib with the Agg backend; no rclpy): :func:`evaluate_scans` runs
every method over the scans, associates corners across scans and compares the propagated
covariances with the real scatter (area ratio, NEES); :func:`write_report` writes the paper's
tables and figures as Markdown, PNG and CSV; :func:`fit_noise` calibrates the noise model from
the ranges of a static recording; :func:`score_scans` measures precision, recall and NEES
against true corners (:class:`Truth`: a simulation's or hand labels) and the recurrence of
corners on static recordings. The command-line tools are ``simulate``, ``evaluate``,
``calibrate`` and ``score``.
"""

from .analysis import (corner_stats, corners_per_scan, CornerStats, evaluate_scans,
                       Evaluation, PROPAGATIONS, run_methods)
from .calibration import fit_noise, node_yaml, NoiseFit
from .report import write_report
from .rules import (assign, associate, check_still, corners_per_scan_figure,
                    MovingSensorError, require_still, StillnessCheck)
from .samples import PAPER_METHODS, scan_corners, ScanCorners
from .scans import load_json_scans, load_scans, StaticScans
from .score import (match_detections, MethodScore, RecurringCorner, score_detections,
                    score_scans, ScoreTable, TrueCornerRate, write_score)
from .truth import (corner_from_beams, load_truth, median_scan, Truth, TRUTH_FILE,
                    truth_from_dict, truth_from_recording, truth_to_yaml, TruthError)

__all__ = [
    'CornerStats', 'Evaluation', 'MethodScore', 'MovingSensorError', 'NoiseFit',
    'PAPER_METHODS', 'PROPAGATIONS', 'RecurringCorner', 'ScanCorners', 'ScoreTable', 'StaticScans',
    'StillnessCheck', 'TRUTH_FILE', 'TrueCornerRate', 'Truth', 'TruthError', 'assign', 'associate',
    'check_still', 'corner_from_beams', 'corner_stats', 'corners_per_scan',
    'corners_per_scan_figure', 'evaluate_scans', 'fit_noise', 'load_json_scans', 'load_scans',
    'load_truth', 'match_detections', 'median_scan', 'node_yaml', 'require_still', 'run_methods',
    'scan_corners', 'score_detections', 'score_scans', 'truth_from_dict', 'truth_from_recording',
    'truth_to_yaml', 'write_report', 'write_score',
]
