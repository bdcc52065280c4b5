# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The report of a failing test shows where the process's other threads stood."""

import os
import pathlib
import subprocess
import sys

from failure_report import SECTION

TEST_DIR = pathlib.Path(__file__).resolve().parent

INNER_TESTS = """
import threading

import pytest


@pytest.fixture
def stalled_thread():
    release = threading.Event()

    def wait_for_the_release():
        release.wait()

    thread = threading.Thread(target=wait_for_the_release, name='stalled reader')
    thread.start()
    yield
    release.set()
    thread.join()


def test_fails_while_a_thread_waits(stalled_thread):
    assert False, 'the deadline passed'


def test_passes_while_a_thread_waits(stalled_thread):
    pass
"""


def test_a_failure_shows_the_stack_of_a_stalled_thread_and_a_pass_shows_none(tmp_path):
    (tmp_path / 'conftest.py').write_text(
        'from failure_report import pytest_runtest_makereport  # noqa: F401\n')
    (tmp_path / 'test_inner.py').write_text(INNER_TESTS)
    run = subprocess.run(
        [sys.executable, '-m', 'pytest', '-p', 'no:cacheprovider', '-o', 'addopts=',
         '-rA', str(tmp_path)],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
        env={**os.environ, 'PYTHONPATH': os.pathsep.join(
            [str(TEST_DIR), os.environ.get('PYTHONPATH', '')])})
    assert '1 failed, 1 passed' in run.stdout, run.stdout + run.stderr
    # Once (the passing test has none): the thread's name and the call it stands in.
    assert run.stdout.count(SECTION) == 1, run.stdout
    section = run.stdout[run.stdout.index(SECTION):]
    assert 'stalled reader (daemon: False):' in section
    assert 'in wait_for_the_release' in section and 'release.wait()' in section
