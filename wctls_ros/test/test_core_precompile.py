# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The first start on a machine compiles the pipeline's, tracker's and dock's kernels; the next loads.

Each case runs a fresh interpreter with its own empty cache, as a first start does; numba's own
compile events say which kernels that process compiled rather than loaded.
"""

import json
import os
import subprocess
import sys

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
from wctls_ros.core.numba_core import precompile
before = precompile.pipeline_is_cached()
precompile.warm_up()
print(json.dumps({'cached_before': before, 'cached_after': precompile.pipeline_is_cached(),
                  'compiled': compiled}))
"""


def run(code: str, cache, timeout: float = 300.0) -> subprocess.CompletedProcess:
    """Run code in a fresh interpreter with its own numba cache; return the finished process."""
    environment = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=os.pathsep.join(
        [os.path.dirname(os.path.dirname(wctls_ros.__file__)), os.environ.get('PYTHONPATH', '')]))
    return subprocess.run([sys.executable, '-c', code], env=environment, capture_output=True,
                          text=True, check=True, timeout=timeout)


def test_a_first_start_compiles_the_pipeline_and_the_next_loads_it(tmp_path):
    first = json.loads(run(FIRST_START, tmp_path).stdout)
    assert not first['cached_before'] and first['cached_after']
    assert {'_features_of_scan', 'update_tracks', 'fit_returns'} <= set(first['compiled'])
    again = json.loads(run(FIRST_START, tmp_path).stdout)
    assert again['cached_before'] and again['compiled'] == []
