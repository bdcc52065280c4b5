# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The installed executables: each imports its node or tool when it runs, and runs it.

The imports take a second or more (rclpy, numpy, the message packages); this module imports
nothing heavy, so that what happens meanwhile is handled: Ctrl-C ends the program quietly with
the status it has later (0 for a node, 130 for a tool) instead of a traceback, and a tool whose
optional package is missing (rosbags, matplotlib, tqdm: :mod:`.extras`) ends with one line
naming the install command and status 1, whether the package is needed at the tool's import or
later.

A Ctrl-C during the imports ends the process at once (``os._exit``) rather than raising: the
handler runs in whatever Python code the main thread is in, and the imports run weakref and
garbage-collector callbacks, in which Python prints an exception with its traceback and drops
it. A raised exit was lost there once in a loaded test run, and the node went on to run. The
imports have opened nothing a clean-up would close.
"""

import importlib
import os
import signal
import sys

# The status Ctrl-C gives: a node ends cleanly (the ROS convention), a tool reports the signal.
NODE_INTERRUPTED = 0
TOOL_INTERRUPTED = 128 + signal.SIGINT


def _run(prog: str, module: str, interrupted: int, function: str = 'main') -> int:
    """
    Import a program's module and run its main(), handling Ctrl-C and missing packages.

    :param prog: the program's name, for messages
    :param module: its module, relative to wctls_ros
    :param interrupted: the exit status of a Ctrl-C the program does not handle itself
    :param function: the module's function that runs the program
    :return: the program's exit status
    """
    def at_once(signal_number, frame):
        os._exit(interrupted)

    previous = signal.signal(signal.SIGINT, at_once)
    try:
        program = importlib.import_module(f'wctls_ros.{module}')
        signal.signal(signal.SIGINT, previous)
        return getattr(program, function)()
    except KeyboardInterrupt:
        # A Ctrl-C the program did not handle (one before a node's run_node or a tool's stop
        # signals take over, or in a tool without them): the finally blocks have run.
        return interrupted
    except ImportError as error:
        from .extras import missing_extra
        reason = missing_extra(error)
        if reason is None:
            raise
        print(f'{prog}: error: {reason}', file=sys.stderr)
        return 1


def feature_node() -> int:
    """Run the feature_node node (:mod:`wctls_ros.feature_node`)."""
    return _run('feature_node', 'feature_node', NODE_INTERRUPTED)


def odometry_node() -> int:
    """Run the odometry_node node (:mod:`wctls_ros.odometry_node`)."""
    return _run('odometry_node', 'odometry_node', NODE_INTERRUPTED)


def bag_replay() -> int:
    """Run the bag_replay node (:mod:`wctls_ros.bags.replay_node`)."""
    return _run('bag_replay', 'bags.replay_node', NODE_INTERRUPTED)


def process_bag() -> int:
    """Run the process_bag tool (:mod:`wctls_ros.bags.process_bag`)."""
    return _run('process_bag', 'bags.process_bag', TOOL_INTERRUPTED)
