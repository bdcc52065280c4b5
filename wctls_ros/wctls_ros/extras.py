# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The optional Python packages: what each adds, and how to install it.

A stock ROS 2 Jazzy install (Ubuntu 24.04, apt) has rclpy, numpy, PyYAML and pyserial, which is
all the nodes need. The packages below add speed or offline tools; a tool that needs a missing
one says so in one line with the command that installs it (:func:`missing_extra`), never with a
traceback. The README's install section lists the same, with figures.
"""

from dataclasses import dataclass
import functools
import importlib
import sys
from typing import Callable, Optional

from .core.runtime import INSTALL_NUMBA, SPEEDUP


@dataclass(frozen=True)
class Extra:
    """
    An optional Python package.

    :ivar purpose: what needs it, in a few words
    :ivar install: the command that installs it on Ubuntu 24.04
    """

    purpose: str
    install: str


EXTRAS = {
    'numba': Extra(f'the compiled feature pipeline, about {SPEEDUP}x faster per scan than numpy',
                   INSTALL_NUMBA),
    'rosbags': Extra('reading and writing bags (process_bag, bag_replay, simulate, score, '
                     "evaluate, calibrate, demo) and feature_node's faster message path",
                     'pip install rosbags'),
    'matplotlib': Extra('plots (demo, score --plot, evaluate)',
                        'sudo apt install python3-matplotlib'),
    'tqdm': Extra('progress bars (process_bag --progress)', 'sudo apt install python3-tqdm'),
}


def missing_extra(error: ImportError) -> Optional[str]:
    """
    Return the one-line explanation of an ImportError caused by a missing optional package.

    :param error: the error an import raised
    :return: 'X is not installed: it gives PURPOSE (COMMAND)', or None when the missing module
        is not one of :data:`EXTRAS` (a real bug, to be raised as it is)
    """
    name = (getattr(error, 'name', None) or '').split('.')[0]
    extra = EXTRAS.get(name)
    if extra is None:
        return None
    return f'{name} is not installed: it gives {extra.purpose} ({extra.install})'


def require(name: str) -> None:
    """
    Import an optional package now: a tool that cannot work without it fails before it starts.

    :param name: one of :data:`EXTRAS`
    :raises ImportError: when it is missing (:func:`explains_missing_extras` turns it into
        one line)
    """
    importlib.import_module(name)


def explains_missing_extras(prog: str) -> Callable[[Callable[..., int]], Callable[..., int]]:
    """
    Decorate a tool's ``main``: a missing optional package ends it with one line and status 1.

    The line is ``PROG: error: `` and :func:`missing_extra`'s explanation, on standard error;
    an ImportError of any other module is a bug and is raised as it is. The tools import their
    optional packages when they first need them, so that ``--help`` and the argument checks
    work without them.

    :param prog: the tool's name, for the line
    :return: the decorator
    """
    def decorate(main: Callable[..., int]) -> Callable[..., int]:
        @functools.wraps(main)
        def main_explaining_missing_extras(*args, **kwargs) -> int:
            try:
                return main(*args, **kwargs)
            except ImportError as error:
                reason = missing_extra(error)
                if reason is None:
                    raise
                print(f'{prog}: error: {reason}', file=sys.stderr)
                return 1
        return main_explaining_missing_extras
    return decorate
