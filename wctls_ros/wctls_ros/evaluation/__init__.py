# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The paper's evaluation on repeated scans from a still sensor, and what the paper lacks.

Pure analysis (numpy, matplotlib with the Agg backend; no rclpy): :func:`evaluate_scans` runs
every method over the scans, associates corners across scans and compares the propagated
covariances with the real scatter (area ratio, NEES); :func:`write_report` writes the paper's
tables and figures as Markdown, PNG and CSV; :func:`fit_noise` calibrates the noise model from
the ranges of a static recording. The command-line tools are ``simulate``, ``evaluate`` and
``calibrate``.
"""

from .analysis import (assign, associate, corner_stats, CornerStats, evaluate_scans,
                       Evaluation, PROPAGATIONS, run_methods)
from .calibration import fit_noise, node_yaml, NoiseFit
from .report import write_report
from .samples import NoiseParameters, PAPER_METHODS, scan_corners, ScanCorners
from .scans import (check_still, load_scans, MovingSensorError, require_still,
                    StaticScans, StillnessCheck)

__all__ = [
    'CornerStats', 'Evaluation', 'MovingSensorError', 'NoiseFit', 'NoiseParameters',
    'PAPER_METHODS', 'PROPAGATIONS', 'ScanCorners', 'StaticScans', 'StillnessCheck', 'assign',
    'associate', 'check_still', 'corner_stats', 'evaluate_scans', 'fit_noise', 'load_scans',
    'node_yaml', 'require_still', 'run_methods', 'scan_corners', 'write_report',
]
