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
import re
import signal
import subprocess
import sys
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


@pytest.mark.parametrize('program, arguments, status', [
    ('feature_node', [], 0),
    ('process_bag', [str(REAL_DATA / 'urg04lx_office'), '-d', '{out}'], 128 + signal.SIGINT)])
def test_ctrl_c_while_a_program_imports_ends_it_quietly(program, arguments, status, tmp_path):
    # The imports take a second or more; a Ctrl-C then gave a KeyboardInterrupt traceback.
    # Python reports each import statement's module as it completes (PYTHONPROFILEIMPORTTIME):
    # the signal is sent once the first module of the package has been imported by the
    # program's module (not by the executables' module, whose handlers are not yet in place),
    # and at delays into its imports after that.
    environment = dict(os.environ, PYTHONPROFILEIMPORTTIME='1')
    for delay_s in (0.0, 0.1, 0.3):
        command = [str(installed_executable(program))] + [
            argument.format(out=tmp_path / f'out{delay_s}') for argument in arguments]
        process = subprocess.Popen(command, env=environment, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True)
        for line in process.stderr:
            if re.search(r'\|\s+wctls_ros\.(?!(executables|process)\s*$)', line):
                break
        time.sleep(delay_s)
        process.send_signal(signal.SIGINT)
        try:
            output, errors = process.communicate(timeout=30)
        finally:
            if process.poll() is None:
                process.kill()
                process.communicate()
        assert 'Traceback' not in output + errors, (delay_s, errors[-2000:])
        assert process.returncode == status, (delay_s, process.returncode, errors[-2000:])


# The Ctrl-C of the test above once came while the imports ran a garbage-collector callback:
# the handler's exit, raised inside it, was printed with its traceback and dropped, and the node
# ran on. Here the first collection after the import has started sends it, every time.
_CTRL_C_INSIDE_A_COLLECTION_DURING_THE_IMPORTS = """
import gc
import importlib
import os
import signal
import sys

from wctls_ros import executables

sent = []


def sigint_inside_a_collection(phase, info):
    if phase == 'start' and not sent:
        sent.append(True)
        print('signalled inside a collection', file=sys.stderr, flush=True)
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):   # the handler runs at one of these bytecodes, in this callback
            pass


real_import_module = importlib.import_module


def import_module_with_a_sigint_in_a_collection(name, package=None):
    gc.callbacks.append(sigint_inside_a_collection)
    return real_import_module(name, package)


importlib.import_module = import_module_with_a_sigint_in_a_collection
program = sys.argv[1]
sys.argv = sys.argv[1:]
sys.exit(getattr(executables, program)())
"""


@pytest.mark.parametrize('program, arguments, status', [
    ('feature_node', [], 0),
    ('process_bag', [str(REAL_DATA / 'urg04lx_office'), '-d', '{out}'], 128 + signal.SIGINT)])
def test_ctrl_c_inside_a_collection_during_the_imports_ends_it(program, arguments, status,
                                                               tmp_path):
    command = [sys.executable, '-c', _CTRL_C_INSIDE_A_COLLECTION_DURING_THE_IMPORTS, program,
               *(argument.format(out=tmp_path / 'out') for argument in arguments)]
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired as error:
        pytest.fail(f'{program} ran on after the Ctrl-C: {error.stderr}')
    assert result.stderr.splitlines() == ['signalled inside a collection']
    assert result.returncode == status
