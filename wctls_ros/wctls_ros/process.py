# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
How a wctls_ros process ends: stop signals honoured at safe points, children that die with it.

A stop signal (Ctrl-C is SIGINT, then SIGTERM, and SIGHUP from a closed terminal) is only
noted by its handler, within :func:`stop_signals`. A handler that raised would raise wherever
the main thread stands, and inside numba's boxing of a compiled function's results that is a
segmentation fault (numba/numba#2324: feature_node died so on 9 of 9 Ctrl-C with large scans in
flight). The process looks at the note at its safe points instead, between two scans or two
spins (:func:`check_stop`, :func:`stop_requested`), and ends there with its documented status:
0 for a node, 128 + N for a tool. Pure Python: no rclpy import.
"""

import atexit
import contextlib
import ctypes
import gc
import os
import pathlib
import shutil
import signal
import threading
from typing import Iterator, List, Optional

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
# The stop signals noted within :func:`stop_signals`, first first.
_noted: List[int] = []
# prctl option: the signal a process gets when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1
# Looked up now: between fork and exec a child must not load a library.
try:
    _PRCTL = ctypes.CDLL(None, use_errno=True).prctl
except (OSError, AttributeError):       # no prctl: not Linux
    _PRCTL = None


def _freeze_at_exit() -> None:
    """
    At exit, leave the objects uncollected: a signal then ends a process within a second.

    Python collects every object one by one as it exits: 0.8 s with numba loaded, 0.1 s
    frozen (a stopped tool's 1 s deadline was missed by that). Not while another thread still
    runs (the compiled pipeline loading): LLVM then aborted at exit.
    """
    if threading.active_count() == 1:
        gc.freeze()


# Every node and tool of ours imports this module; the handler runs before Python's last
# collection.
atexit.register(_freeze_at_exit)


class Stopped(Exception):
    """A stop signal asked the process to end; its number is ``signal_number``."""

    def __init__(self, signal_number: int):
        super().__init__(signal.Signals(signal_number).name)
        self.signal_number = signal_number


def _note(number: int, _frame) -> None:
    """Note a stop signal (the handler: it never raises)."""
    _noted.append(number)


@contextlib.contextmanager
def stop_signals(ending: bool = False) -> Iterator[None]:
    """
    Within the block, a stop signal is only noted, for :func:`check_stop` to act on.

    Main thread only (Python's rule for signal handlers). A node enters it before rclpy.init,
    which chains its own handlers (they shut the context down) to these.

    :param ending: the process ends after the block: the signals are then ignored instead of
        given back their handlers (Python gives its own handlers back to the system's defaults
        as it exits, and a Ctrl-C then would kill the process with status -2)
    :return: nothing (a context manager)
    """
    _noted.clear()
    previous = {number: signal.signal(number, _note) for number in STOP_SIGNALS}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, signal.SIG_IGN if ending else handler)


def stop_requested() -> Optional[int]:
    """
    Return the first stop signal noted within :func:`stop_signals`, or None.

    :return: the signal number, or None
    """
    return _noted[0] if _noted else None


def check_stop() -> None:
    """
    End here if a stop signal was noted: a safe point (between two scans, say).

    :raises Stopped: when a stop signal was noted
    """
    if _noted:
        raise Stopped(_noted[0])


@contextlib.contextmanager
def ending_at_once(prog: str, removing: Optional[pathlib.Path] = None) -> Iterator[None]:
    """
    Within the block, a stop signal ends the tool at once: 128 + N, one line on standard error.

    For a step of a tool that offers no safe point, such as loading the compiled pipeline,
    reading a bag, the stillness test or drawing the figures (seconds each on a busy machine).
    Ending the process never lands in numba as an exception would; the line is written without
    taking a lock. A signal noted before the block is left to the next :func:`check_stop`.

    :param prog: the tool's name, for the line
    :param removing: a folder the step writes into (a staging folder), removed before the end so
        that a stopped tool leaves nothing behind; None when the step writes nothing
    :return: nothing (a context manager)
    """
    def end(number: int, _frame) -> None:
        if removing is not None:
            shutil.rmtree(removing, ignore_errors=True)
        os.write(2, f'{prog}: stopped by {signal.Signals(number).name}\n'.encode())
        os._exit(128 + number)

    previous = {number: signal.signal(number, end) for number in STOP_SIGNALS}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def die_with_parent(parent_pid: int, number: int = signal.SIGKILL) -> None:
    """
    In a child process: be sent a signal when the parent ends, however it ends (even SIGKILL).

    Linux's PR_SET_PDEATHSIG; it acts when the thread that forked the child ends. Safe between
    fork and exec (a ``preexec_fn``). A parent that ended before the call sends nothing: the
    child then ends at once. Does nothing where there is no prctl.

    :param parent_pid: the process that forked this one
    :param number: the signal to be sent
    """
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, number)
    if os.getppid() != parent_pid:
        os._exit(1)
