# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The offline tools' installed executables: each imports its tool when it runs.

So that a tool whose optional package is missing (rosbags, matplotlib, tqdm: :mod:`.extras`)
ends with one line naming the install command and status 1, whether the package is needed at
the tool's import or later. The nodes (feature_node, rplidar_node) need no optional package and
start directly.
"""

import importlib
import sys

from .extras import missing_extra


def _run(prog: str, module: str) -> int:
    """Import a tool's module and run its main(); a missing optional package is one line."""
    try:
        return importlib.import_module(f'wctls_ros.{module}').main()
    except ImportError as error:
        reason = missing_extra(error)
        if reason is None:
            raise
        print(f'{prog}: error: {reason}', file=sys.stderr)
        return 1


def bag_replay() -> int:
    """Run the bag_replay tool (:mod:`wctls_ros.bags.replay_node`)."""
    return _run('bag_replay', 'bags.replay_node')


def calibrate() -> int:
    """Run the calibrate tool (:mod:`wctls_ros.evaluation.calibrate_cli`)."""
    return _run('calibrate', 'evaluation.calibrate_cli')


def demo() -> int:
    """Run the demo tool (:mod:`wctls_ros.demo`)."""
    return _run('demo', 'demo')


def evaluate() -> int:
    """Run the evaluate tool (:mod:`wctls_ros.evaluation.evaluate_cli`)."""
    return _run('evaluate', 'evaluation.evaluate_cli')


def process_bag() -> int:
    """Run the process_bag tool (:mod:`wctls_ros.bags.process_bag`)."""
    return _run('process_bag', 'bags.process_bag')


def score() -> int:
    """Run the score tool (:mod:`wctls_ros.evaluation.score_cli`)."""
    return _run('score', 'evaluation.score_cli')


def simulate() -> int:
    """Run the simulate tool (:mod:`wctls_ros.evaluation.simulate_cli`)."""
    return _run('simulate', 'evaluation.simulate_cli')
