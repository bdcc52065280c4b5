# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Ctrl-C and SIGTERM end a node or a tool within 2 s while numba compiles (a first start).

Each case starts an installed executable with an empty numba cache, waits until its compile
process is running (a child compiling for tens of seconds here), signals the executable, and
times its end; the compile process must be gone too.
"""

import os
import pathlib
import signal
import subprocess
import time

import pytest
from test_feature_node import installed_executable

pytest.importorskip('numba')

# One of the suite's slowest modules (make test-fast leaves it out), and one that runs
# nodes, emulators or signals against deadlines (make test runs it in its realtime group).
pytestmark = [pytest.mark.slow, pytest.mark.realtime]

REAL_DATA = pathlib.Path(__file__).resolve().parents[2] / 'data'
DEADLINE_S = 2.0


def compile_processes(parent: int) -> list:
    """Return the pids of the compile processes (and their helpers) under a process."""
    found, pending = [], [parent]
    while pending:
        pid = pending.pop()
        children = []
        # Each thread's children: the compile is started from a thread of the node.
        for task in pathlib.Path(f'/proc/{pid}/task').glob('*'):
            try:
                children += (task / 'children').read_text().split()
            except OSError:
                continue
        for child in map(int, children):
            try:
                command = pathlib.Path(f'/proc/{child}/cmdline').read_bytes()
            except OSError:
                continue
            if b'precompile' in command:
                found.append(child)
            pending.append(child)
    return found


def alive(pid: int) -> bool:
    try:
        state = pathlib.Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state != 'Z'


@pytest.mark.parametrize('command, signal_number, status', [
    (['feature_node'], signal.SIGINT, 0),
    (['feature_node'], signal.SIGTERM, 0),
    (['process_bag', str(REAL_DATA / 'urg04lx_office'), '-j', '2', '-d', '{out}'],
     signal.SIGTERM, 128 + signal.SIGTERM),
    (['process_bag', str(REAL_DATA / 'urg04lx_office'), '-j', '2', '-d', '{out}'],
     signal.SIGINT, 128 + signal.SIGINT),
])
def test_a_signal_during_the_compile_ends_it_within_two_seconds(command, signal_number, status,
                                                                tmp_path):
    executable = installed_executable(command[0])
    arguments = [argument.format(out=tmp_path / 'out') for argument in command[1:]]
    environment = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / 'cache'), WCTLS_ROS_CORE='auto')
    process = subprocess.Popen([str(executable), *arguments], env=environment,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60.0
        compiling = []
        while not compiling and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.05)
            compiling = compile_processes(process.pid)
        assert compiling, 'no compile process started'
        time.sleep(0.5)                         # well inside the compile
        signalled = time.monotonic()
        process.send_signal(signal_number)
        output, _ = process.communicate(timeout=30)
        took = time.monotonic() - signalled
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert took < DEADLINE_S, (took, output)
    assert process.returncode == status, output
    assert 'Traceback' not in output
    gone = time.monotonic() + 5.0
    while any(alive(pid) for pid in compiling) and time.monotonic() < gone:
        time.sleep(0.05)
    assert not any(alive(pid) for pid in compiling)
