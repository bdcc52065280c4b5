# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The first start on a machine: helper processes compile kernels into numba's cache.

Each case runs a fresh interpreter with its own empty cache, as a first start does; numba's own
compile events say which kernels that process compiled rather than loaded.
"""

import json
import os
import subprocess
import sys
import time

import pytest
import wctls_ros

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

FIRST_START = """
import json, os
from numba.core import event
compiled = []


class Compiles(event.Listener):
    def on_start(self, data):
        pass

    def on_end(self, data):
        compiled.append(data.data['dispatcher'].py_func.__qualname__)


event.register('numba:compile', Compiles())
from wctls_ros.core.numba_core import pipeline, precompile
before = precompile.pipeline_is_cached()
precompile.warm_up(helpers=1)
try:
    os.waitpid(-1, os.WNOHANG)
    children_left = True
except ChildProcessError:
    children_left = False
print(json.dumps({
    'cached_before': before, 'cached_after': precompile.pipeline_is_cached(),
    'compiled': compiled, 'children_left': children_left,
    'plan': [kernel.__name__ for kernel, _ in pipeline.kernels_last_first()],
    'not_the_pipelines': [kernel.__name__ for kernel, types in pipeline.kernels_last_first()
                          if tuple(types) not in [tuple(s) for s in kernel.signatures]]}))
"""


def run(code: str, cache, timeout: float = 300.0) -> subprocess.CompletedProcess:
    """Run code in a fresh interpreter with its own numba cache; return the finished process."""
    environment = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=os.pathsep.join(
        [os.path.dirname(os.path.dirname(wctls_ros.__file__)), os.environ.get('PYTHONPATH', '')]))
    return subprocess.run([sys.executable, '-c', code], env=environment, capture_output=True,
                          text=True, check=True, timeout=timeout)


def test_a_first_start_leaves_kernels_to_a_helper_and_ends_it(tmp_path):
    first = json.loads(run(FIRST_START, tmp_path).stdout)
    assert not first['cached_before'] and first['cached_after']
    # The helper compiled the exact versions the pipeline needs: the pipeline found them in
    # the cache (a planned argument type that differs from the pipeline's would be missing).
    assert first['not_the_pipelines'] == []
    # The helper starts with the last step's kernel, which this process reaches last.
    assert first['plan'][0] not in first['compiled']
    assert len(set(first['plan']) & set(first['compiled'])) < len(first['plan']) - 1
    assert '_features_of_scan' in first['compiled']
    assert not first['children_left']
    again = json.loads(run(FIRST_START, tmp_path).stdout)
    assert again['cached_before'] and again['compiled'] == []


def test_a_helper_whose_parent_died_compiles_nothing(tmp_path):
    parent = subprocess.Popen(['true'])
    parent.wait()
    started = time.perf_counter()
    run('from wctls_ros.core.numba_core.precompile import compile_share; '
        f'compile_share(0, 1, parent_pid={parent.pid})', tmp_path)
    assert time.perf_counter() - started < 60.0       # one kernel alone takes seconds here
    assert not list(tmp_path.rglob('*.nbi'))
