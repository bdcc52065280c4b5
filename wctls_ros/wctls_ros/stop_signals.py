# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The signals that stop a tool: Ctrl-C (SIGINT), SIGTERM and a closed terminal (SIGHUP).

While :func:`raising` is active, each raises :class:`Stopped` where the tool is, as Ctrl-C
raises KeyboardInterrupt, so that every ``finally`` runs (a staging folder is removed) and the
tool exits 128 + N with one line instead of dying with its files half written (SIGTERM, SIGHUP)
or with a traceback (Ctrl-C). Pure Python: no rclpy import.
"""

import contextlib
import signal

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
# Within :func:`held` a stop signal waits (its number here) and is raised when the block ends.
_holding = 0
_waiting: list = []


class Stopped(Exception):
    """A stop signal arrived; its number is ``signal_number``."""

    def __init__(self, signal_number: int):
        super().__init__(signal.Signals(signal_number).name)
        self.signal_number = signal_number


def raise_stopped(number: int, _frame) -> None:
    """
    Raise :class:`Stopped` (a signal handler).

    :param number: the signal
    :raises Stopped: at once, or when the :func:`held` block around it ends
    """
    if _holding:
        _waiting.append(number)
        return
    raise Stopped(number)


@contextlib.contextmanager
def held():
    """
    Let a stop signal wait until the block has run, then raise :class:`Stopped`.

    For a few steps that must happen together, e.g. creating a staging folder and remembering
    it for its removal: a signal between the two would leave the folder behind.

    :return: nothing (a context manager)
    :raises Stopped: when a stop signal arrived during the block
    """
    global _holding
    _holding += 1
    try:
        yield
    finally:
        _holding -= 1
    if not _holding and _waiting:
        number = _waiting[0]
        _waiting.clear()
        raise Stopped(number)


@contextlib.contextmanager
def raising():
    """
    Make the stop signals raise :class:`Stopped` within the block; restore their handlers after.

    :return: nothing (a context manager)
    """
    previous = {number: signal.signal(number, raise_stopped) for number in SIGNALS}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
