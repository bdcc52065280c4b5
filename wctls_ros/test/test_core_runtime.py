# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Which implementation serves: numba when it can, numpy otherwise and while numba compiles.

Each case runs a fresh interpreter, since the choice is made once per process; an empty numba
cache stands for the first start on a machine. numba's absence is made by a ``numba`` entry of
None in ``sys.modules`` (the stock-install run has none at all), a too-old numba by a module of
that name with an old version on the import path.
"""

import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest
import wctls_ros
from wctls_ros.core import runtime

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

PACKAGE_PARENT = str(pathlib.Path(wctls_ros.__file__).resolve().parents[1])
# A square room's full turn, and what the process reports: the core after its first scan.
FIRST_SCAN = """
import json, math, sys, time
import numpy as np
{before}
started = time.perf_counter()
from wctls_ros.core import extract_features, start, status
changes = []
chosen = start({start_arguments}on_change=lambda new: changes.append(new.describe()))
beams = 720
bearing = -math.pi + 2 * math.pi / beams * np.arange(beams)
ranges = 2.0 / np.maximum(np.abs(np.cos(bearing)), np.abs(np.sin(bearing)))
corners = len(extract_features(ranges, -math.pi, 2 * math.pi / beams).corners)
print(json.dumps({{'first_scan_s': time.perf_counter() - started, 'corners': corners,
                  'core': status().name, 'reason': status().reason,
                  'pending': chosen.pending, 'line': chosen.describe(),
                  'numba_imported': 'numba' in sys.modules}}), flush=True)
{after}
"""


def run_first_scan(tmp_path, before='', after='', start_arguments='', timeout=600.0,
                   **environment):
    """Run FIRST_SCAN in a fresh interpreter with an empty numba cache; return its report."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / 'cache'), **environment)
    env['PYTHONPATH'] = os.pathsep.join([str(tmp_path), PACKAGE_PARENT,
                                         os.environ.get('PYTHONPATH', '')])
    code = FIRST_SCAN.format(before=before, after=after, start_arguments=start_arguments)
    result = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                            text=True, timeout=timeout)
    assert result.returncode == 0, result.stderr
    return [json.loads(line) for line in result.stdout.splitlines()]


def test_without_numba_the_numpy_core_serves_and_says_how_to_get_the_compiled_one(tmp_path):
    report, = run_first_scan(tmp_path, before="sys.modules['numba'] = None")
    assert report['core'] == 'numpy' and report['corners'] == 4
    assert report['reason'] == 'numba is not installed'
    assert runtime.INSTALL_NUMBA in report['line'] and f'{runtime.SPEEDUP}x' in report['line']


def test_a_numba_older_than_the_oldest_supported_falls_back_to_numpy(tmp_path):
    (tmp_path / 'numba').mkdir()
    (tmp_path / 'numba' / '__init__.py').write_text("__version__ = '0.59.1'\n")
    (tmp_path / 'numba-0.59.1.dist-info').mkdir()
    (tmp_path / 'numba-0.59.1.dist-info' / 'METADATA').write_text(
        'Metadata-Version: 2.1\nName: numba\nVersion: 0.59.1\n')
    report, = run_first_scan(tmp_path)
    assert report['core'] == 'numpy' and report['corners'] == 4
    assert 'numba 0.59.1 is older than 0.60.0' in report['reason']


def test_forcing_numpy_never_imports_numba(tmp_path):
    report, = run_first_scan(tmp_path, WCTLS_ROS_CORE='numpy')
    assert report['core'] == 'numpy' and not report['numba_imported']


def test_forcing_numba_without_it_is_an_error_naming_the_install_command(tmp_path):
    code = ("import sys; sys.modules['numba'] = None\n"
            'from wctls_ros.core import start\nstart()')
    environment = dict(os.environ, WCTLS_ROS_CORE='numba', PYTHONPATH=os.pathsep.join(
        [PACKAGE_PARENT, os.environ.get('PYTHONPATH', '')]))
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            env=environment)
    assert result.returncode != 0
    assert 'CoreUnavailable' in result.stderr and runtime.INSTALL_NUMBA in result.stderr


def test_an_unknown_choice_is_refused(monkeypatch):
    monkeypatch.setenv(runtime.CORE_VARIABLE, 'fortran')
    with pytest.raises(runtime.CoreUnavailable, match='auto, numba, numpy'):
        runtime.choice()


def test_a_compile_that_fails_falls_back_to_numpy(monkeypatch):
    from wctls_ros.core.numba_core import precompile

    def failing():
        raise RuntimeError('Failed in nopython mode pipeline\nthe details')
    monkeypatch.setattr(precompile, 'pipeline_is_cached', lambda: True)
    monkeypatch.setattr(precompile, 'warm_up', failing)
    status = runtime._bring_in_compiled('auto', on_compile=None)
    assert status.name == 'numpy' and not status.pending
    assert 'failed to compile the core (RuntimeError: Failed in nopython' in status.reason
    with pytest.raises(runtime.CoreUnavailable, match='failed to compile'):
        runtime._bring_in_compiled('numba', on_compile=None)


@pytest.mark.parametrize('version, expected', [
    ('0.60.0', (0, 60, 0)), ('0.61.0rc1', (0, 61, 0)), ('0.68.1', (0, 68, 1)), ('1.0', (1, 0, 0)),
    ('0.59.1+1.g5ab', (0, 59, 1))])
def test_numba_versions_compare_by_their_numbers(version, expected):
    assert runtime._version_tuple(version) == expected


# After the first scan, wait for the switch and report again, with every change announced.
AFTER_SWITCH = """
deadline = time.monotonic() + 500
while status().pending and time.monotonic() < deadline:
    time.sleep(0.1)
corners = len(extract_features(ranges, -math.pi, 2 * math.pi / beams).corners)
print(json.dumps({'core': status().name, 'corners': corners, 'changes': changes,
                  'compiled_here': status().compiled_here}), flush=True)
"""


AFTER_WARM_UP = """
from wctls_ros.core import warm_up
warm_up()
print(json.dumps({'core': status().name, 'pending': status().pending}), flush=True)
"""


def test_a_cold_start_answers_with_numpy_at_once_then_switches_to_the_compiled_core(tmp_path):
    first, switched = run_first_scan(tmp_path, after=AFTER_SWITCH)
    # Answered by numpy while numba compiled in another process (which takes 10-200 s here).
    assert first['core'] == 'numpy' and first['pending'] and first['corners'] == 4
    assert switched['core'] == 'numba' and switched['compiled_here'] and switched['corners'] == 4
    compiling, compiled = switched['changes']
    assert compiling.startswith('compiling the feature pipeline for this machine')
    assert 'the numpy one serves meanwhile' in compiling
    assert 'compiled for this machine in' in compiled
    # The next process finds the cache: loaded, not compiled, and nothing said of a compile.
    again, after = run_first_scan(tmp_path, after=AFTER_SWITCH)
    assert again['pending'] and after['core'] == 'numba' and not after['compiled_here']
    assert len(after['changes']) == 1 and 'loaded in' in after['changes'][0]
    # warm_up() after a start in the background waits for it.
    _, waited = run_first_scan(tmp_path, after=AFTER_WARM_UP)
    assert waited == {'core': 'numba', 'pending': False}
    # A batch tool loads a cached pipeline before its first scan (load_now).
    loaded, = run_first_scan(tmp_path, start_arguments='load_now=True, ')
    assert loaded['core'] == 'numba' and not loaded['pending']


KEEP_RUNNING = """
from wctls_ros.core import runtime
while runtime._compiler is None:
    time.sleep(0.01)
print(json.dumps({'compiler': runtime._compiler.pid}), flush=True)
time.sleep(600)
"""


def test_the_background_compile_ends_when_its_process_is_killed(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / 'cache'), PYTHONPATH=os.pathsep.join(
        [PACKAGE_PARENT, os.environ.get('PYTHONPATH', '')]))
    code = FIRST_SCAN.format(before='', after=KEEP_RUNNING, start_arguments='')
    parent = subprocess.Popen([sys.executable, '-c', code], env=env, stdout=subprocess.PIPE,
                              text=True)
    try:
        first = json.loads(parent.stdout.readline())
        compiler = json.loads(parent.stdout.readline())['compiler']
        assert first['pending']
        os.kill(compiler, 0)                     # running
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and _alive(compiler):
            time.sleep(0.05)
        assert not _alive(compiler)
    finally:
        parent.kill()
        parent.wait()


def _alive(pid: int) -> bool:
    """Return whether a process exists and is not a zombie."""
    try:
        with open(f'/proc/{pid}/stat') as stat:
            return stat.read().split(')')[-1].split()[0] != 'Z'
    except FileNotFoundError:
        return False


# Each front end's compiled choice without the compiled core: the caller, its refusal.
REFUSALS = {
    'tracking': ('from wctls_ros.frontend.tracking import Tracker\n'
                 'assert Tracker()._kernels() is None\n'
                 'Tracker(compiled=True)\n', 'the compiled tracker needs the compiled core'),
    'dock': ('from wctls_ros.frontend.dock import DockReturns, DockShape, fit_returns\n'
             'import numpy as np\n'
             'returns = DockReturns(np.ones(360), -3.14, 0.0174, 0.01, 0.001)\n'
             'fit_returns(returns, (1.0, 0.0, 0.0), DockShape(), compiled=True)\n',
             'the compiled dock fit needs the compiled core'),
    'odometry': ('from wctls_ros.frontend.odometry import Odometry\n'
                 'Odometry(compiled=True)\n', 'the compiled odometry needs the compiled core'),
}


@pytest.mark.parametrize('name', sorted(runtime.COMPILED_KERNELS))
def test_a_front_end_forced_compiled_without_the_compiled_core_is_refused_with_the_reason(name):
    caller, refusal = REFUSALS[name]
    code = ('from wctls_ros.core import CoreUnavailable, runtime\n'
            f'assert runtime.compiled_kernels({name!r}) is None\n'
            'try:\n'
            + ''.join(f'    {line}\n' for line in caller.splitlines())
            + 'except CoreUnavailable as error:\n'
            '    print(error)\n')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          env=dict(os.environ, WCTLS_ROS_CORE='numpy'), timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f'{refusal}: WCTLS_ROS_CORE=numpy'
