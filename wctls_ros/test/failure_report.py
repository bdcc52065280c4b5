# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""A failing test's report shows where every other thread of the process stood (conftest)."""

import sys
import threading
import traceback

import pytest

SECTION = 'threads at the failure'


def other_thread_stacks() -> str:
    """
    Return the Python stack of every live thread but the calling one.

    :return: one block per thread, its name first, innermost call last
    """
    frames = sys._current_frames()
    blocks = [f'{thread.name} (daemon: {thread.daemon}):\n'
              + ''.join(traceback.format_stack(frames[thread.ident]))
              for thread in threading.enumerate()
              if thread is not threading.current_thread() and thread.ident in frames]
    return '\n'.join(blocks) or 'no other thread'


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    """
    Add the other threads' stacks to the report of a test that failed.

    Taken before the test's fixtures are torn down: a node's reader thread that stalled is
    still where it stalled. A test whose deadline passed on a loaded machine then tells a
    thread stuck in a call from one merely late.
    """
    report = yield
    if report.failed and call.when == 'call':
        report.sections.append((SECTION, other_thread_stacks()))
    return report
