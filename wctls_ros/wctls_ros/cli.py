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
# Compiling the feature pipeline takes seconds on a machine that has never run it, a fraction
# of one from numba's cache: only the first is worth a line on standard error.
SLOW_START_S = 1.0


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


def warm_up_core(prog: str) -> float:
    """
    Compile the feature pipeline (or load it from the cache) before a tool's first scan.

    Done once in the tool's own process, before any worker process is forked, so that the
    workers inherit the compiled code. A slow compile is reported on standard error.

    :param prog: the tool's name, for the message
    :return: how long it took, s
    """
    from .core import warm_up
    seconds = warm_up()
    if seconds >= SLOW_START_S:
        print(f'{prog}: compiled the feature pipeline for this machine in {seconds:.1f} s '
              '(cached for later runs)', file=sys.stderr)
    return seconds
