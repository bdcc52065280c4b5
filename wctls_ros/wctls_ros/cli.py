# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
What the command-line tools share: one exit-status convention and one-line errors.

Every offline tool (``simulate``, ``score``, ``s1_emulator``, ...) exits with

- 0 when it did what was asked;
- 2 on a user error: a bad option, path, bag, file or value. One line on standard error,
  ``PROG: error: REASON``, no traceback, and nothing written;
- 128 + N when stopped by signal N (130 for Ctrl-C, 143 for SIGTERM), with nothing half
  written.

docs/user_guide.md lists every tool's statuses. Pure Python: no rclpy import.
"""

import argparse
import contextlib
import math
import os
import pathlib
import shutil
import sys
import tempfile

USER_ERROR = 2


class UserError(ValueError):
    """Something the user gave that the tool cannot use; the message says what to change."""


class Parser(argparse.ArgumentParser):
    """An argparse parser whose usage errors follow the convention: one line, status 2."""

    def error(self, message):
        """
        Report a command-line error in one line and exit with status 2.

        :param message: what is wrong
        """
        self.exit(USER_ERROR, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def bounded(kind, low, high=math.inf):
    """
    Return an argparse type: ``kind`` values within [low, high].

    :param kind: int or float
    :param low: the smallest value allowed
    :param high: the largest value allowed
    :return: the parsing function (raises argparse.ArgumentTypeError with the reason)
    """
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            what = 'an integer' if kind is int else 'a number'
            raise argparse.ArgumentTypeError(f'not {what}: {text!r}') from None
        if not low <= value <= high:
            span = f'at least {low}' if high == math.inf else f'from {low} to {high}'
            raise argparse.ArgumentTypeError(f'must be {span}, got {text}')
        return value
    return parse


@contextlib.contextmanager
def staged_folder(out_dir):
    """
    Yield a staging folder whose files move into ``out_dir`` once the block ends without error.

    A tool writes its outputs into the staging folder (beside ``out_dir``, on the same file
    system); only when all are written does each replace its namesake in ``out_dir`` (a rename,
    which needs no space). A full disk or a file-size limit midway leaves ``out_dir`` as it was.
    The staging folder is removed in every case.

    :param out_dir: the output folder (created with its parents when missing)
    :return: the staging folder (a context manager's value)
    :raises OSError: when a folder cannot be created or a file cannot be moved into place
    """
    out = pathlib.Path(out_dir)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = pathlib.Path(tempfile.mkdtemp(prefix=f'.partial-{out.name}-', dir=out.parent))
    try:
        yield staging
        out.mkdir(exist_ok=True)
        for item in sorted(staging.iterdir()):
            os.replace(item, out / item.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def start_core(prog: str, wait: bool = False, give_up=None):
    """
    Choose the feature pipeline's implementation before a tool's first scan, and say so.

    Loads the compiled pipeline from numba's cache first, silently; otherwise a line on standard
    error says what happens: numba missing (the numpy pipeline serves), a compile starting (the
    first run on a machine: the numpy pipeline serves meanwhile), its end. Nothing is said when
    ``WCTLS_ROS_CORE=numpy`` asked for the numpy pipeline. Done in the tool's own process, before
    any worker process is forked, so that the workers inherit what serves then.

    :param prog: the tool's name, for the messages
    :param wait: have the compiled pipeline now, compiling it if need be (a tool about to fork
        workers), instead of starting with the numpy one while it loads
    :param give_up: with ``wait``, a callable saying whether to stop waiting for a compile (a
        signal asked the tool to stop)
    :return: the :class:`wctls_ros.core.CoreStatus`
    """
    from .core import start

    def changed(status) -> None:
        stopping = give_up is not None and give_up()
        # A cached compiled pipeline, or the numpy one the user asked for: nothing to learn, and a
        # user error stays the one line on standard error.
        quiet = not status.compiled_here if status.name == 'numba' else status.forced
        if not quiet and not stopping:
            print(f'{prog}: {status.describe()}', file=sys.stderr)

    # A tool's results do not depend on when a load ended: it loads a cached pipeline first.
    status = start(wait=wait, on_change=changed, give_up=give_up, load_now=True)
    if not status.pending:
        changed(status)
    return status
