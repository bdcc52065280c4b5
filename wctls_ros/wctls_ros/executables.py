# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The installed executables: each imports its node or tool when it runs, and runs it.

The imports take a second or more (rclpy, numpy, the message packages); this module imports
nothing heavy, so that what happens meanwhile is handled: a stop signal (Ctrl-C, SIGTERM,
SIGHUP) ends the program quietly with the status it has later (0 for a node, 128 + N for a
tool) instead of a traceback or the signal's default end, and a tool whose
optional package is missing (rosbags, matplotlib, tqdm: :mod:`.extras`) ends with one line
naming the install command and status 1, whether the package is needed at the tool's import or
later.

A stop signal during the imports ends the process at once (``os._exit``) rather than raising: the
handler runs in whatever Python code the main thread is in, and the imports run weakref and
garbage-collector callbacks, in which Python prints an exception with its traceback and drops
it. A raised exit was lost there once in a loaded test run, and the node went on to run. The
imports have opened nothing a clean-up would close.
"""

import gc
import importlib
import os
import signal
import sys
import threading

from .process import STOP_SIGNALS


def run(prog: str, module: str, node: bool, function: str = 'main') -> int:
    """
    Import a program's module and run its main(), handling stop signals and missing packages.

    The lab's executables (:mod:`wctls_lab.executables`) are run by it too.

    :param prog: the program's name, for messages
    :param module: its module, e.g. ``wctls_ros.feature_node``
    :param node: the program is a node: a stop signal ends it with 0 (the ROS convention), not
        with 128 + N as a tool
    :param function: the module's function that runs the program
    :return: the program's exit status
    """
    def stopped(signal_number: int) -> int:
        return 0 if node else 128 + signal_number

    def at_once(signal_number, frame):
        os._exit(stopped(signal_number))

    previous = {number: signal.signal(number, at_once) for number in STOP_SIGNALS}
    try:
        program = importlib.import_module(module)
        for number, handler in previous.items():
            signal.signal(number, handler)
        status = getattr(program, function)()
        # The process ends: its objects need not be collected one by one at exit (0.8 s with
        # numba loaded, 0.1 s frozen), so a signal ends it within a second. Not while another
        # thread still runs (the compiled pipeline loading): LLVM then aborted at exit.
        if threading.active_count() == 1:
            gc.freeze()
        return status
    except KeyboardInterrupt:
        # A Ctrl-C the program did not handle (one before a node's run_node or a tool's stop
        # signals take over, or in a tool without them): the finally blocks have run.
        return stopped(signal.SIGINT)
    except ImportError as error:
        from .extras import missing_extra
        reason = missing_extra(error)
        if reason is None:
            raise
        print(f'{prog}: error: {reason}', file=sys.stderr)
        return 1


def feature_node() -> int:
    """Run the feature_node node (:mod:`wctls_ros.feature_node`)."""
    return run('feature_node', 'wctls_ros.feature_node', True)


def odometry_node() -> int:
    """Run the odometry_node node (:mod:`wctls_ros.odometry_node`)."""
    return run('odometry_node', 'wctls_ros.odometry_node', True)


def bag_replay() -> int:
    """Run the bag_replay node (:mod:`wctls_ros.bags.replay_node`)."""
    return run('bag_replay', 'wctls_ros.bags.replay_node', True)


def process_bag() -> int:
    """Run the process_bag tool (:mod:`wctls_ros.bags.process_bag`)."""
    return run('process_bag', 'wctls_ros.bags.process_bag', False)
