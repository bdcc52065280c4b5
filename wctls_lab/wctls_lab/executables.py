# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The lab's installed executables, run as wctls_ros runs its own (:func:`wctls_ros.executables.run`).

A stop signal during the imports ends a tool quietly with 128 + N, and a missing optional
package (rosbags, matplotlib, tqdm) is one line naming the install command.
"""

from wctls_ros.executables import run


def calibrate() -> int:
    """Run the calibrate tool (:mod:`wctls_lab.evaluation.calibrate_cli`)."""
    return run('calibrate', 'wctls_lab.evaluation.calibrate_cli', False)


def demo() -> int:
    """Run the demo tool (:mod:`wctls_lab.demo`)."""
    return run('demo', 'wctls_lab.demo', False)


def evaluate() -> int:
    """Run the evaluate tool (:mod:`wctls_lab.evaluation.evaluate_cli`)."""
    return run('evaluate', 'wctls_lab.evaluation.evaluate_cli', False)


def score() -> int:
    """Run the score tool (:mod:`wctls_lab.evaluation.score_cli`)."""
    return run('score', 'wctls_lab.evaluation.score_cli', False)


def simulate() -> int:
    """Run the simulate tool (:mod:`wctls_lab.evaluation.simulate_cli`)."""
    return run('simulate', 'wctls_lab.evaluation.simulate_cli', False)


def simulated_rplidar() -> int:
    """Run the simulated_rplidar tool (:mod:`wctls_lab.simulated_rplidar`)."""
    return run('simulated_rplidar', 'wctls_lab.simulated_rplidar', False)
