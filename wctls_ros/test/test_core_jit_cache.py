# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Where the compiled core keeps its JIT cache.

Next to a writable install, else in $XDG_CACHE_HOME/wctls_ros, and wherever NUMBA_CACHE_DIR
says when the user sets it.

Each case runs a fresh interpreter on a copy of the package with a one-line compiled probe in
its core/, so that numba's real cache locator decides, as it will for the pipeline. The cache is
set up by an explicit call before the first compile, as the pipeline's entry points make it:
importing the core changes nothing outside it.
"""

import json
import os
import pathlib
import shutil
import stat
import subprocess
import sys

import pytest
import wctls_ros

PROBE = """from ._jit import jit
from .probe_factor import factor


@jit
def twice(value):
    return factor(value)
"""
FACTOR = """from ._jit import jit


@jit
def factor(value):
    return {} * value
"""


@pytest.fixture()
def package(tmp_path):
    """Return a copy of wctls_ros with a compiled probe in core/numba_core/, and that folder."""
    copy = tmp_path / 'site'
    shutil.copytree(pathlib.Path(wctls_ros.__file__).parent, copy / 'wctls_ros',
                    ignore=shutil.ignore_patterns('__pycache__'))
    core = copy / 'wctls_ros' / 'core' / 'numba_core'
    (core / 'probe.py').write_text(PROBE)
    (core / 'probe_factor.py').write_text(FACTOR.format(2.0))
    yield copy, core
    if os.geteuid() == 0:
        subprocess.run(['chattr', '-i', str(core)], check=False)
    core.chmod(stat.S_IRWXU)                  # so that pytest can remove it


def make_read_only(folder: pathlib.Path) -> None:
    """Make a folder unwritable, also for root (immutable, where the file system allows)."""
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    if os.geteuid() == 0 and subprocess.run(['chattr', '+i', str(folder)],
                                            capture_output=True).returncode:
        pytest.skip('root writes to read-only folders, and chattr +i is not available here')


def run_probe(site: pathlib.Path, expected=4.0, **environment) -> None:
    """Compile and run the probe in a fresh interpreter with the given environment."""
    env = {key: value for key, value in os.environ.items() if key != 'NUMBA_CACHE_DIR'}
    env.update(environment, PYTHONPATH=str(site))
    subprocess.run([sys.executable, '-c', 'from wctls_ros.core.numba_core.probe import twice; '
                    'from wctls_ros.core.numba_core._jit import use_disk_cache; '
                    f'use_disk_cache(); assert twice(2.0) == {expected}, twice(2.0)'], env=env,
                   check=True, timeout=120)


def cache_files(folder: pathlib.Path):
    """Return numba's cache files (index and data) under a folder."""
    return sorted(path.name for path in folder.rglob('probe.twice-*.nb[ic]'))


def test_a_writable_install_keeps_the_cache_next_to_its_source(package, tmp_path):
    site, core = package
    run_probe(site, XDG_CACHE_HOME=str(tmp_path / 'xdg'))
    assert cache_files(core / '__pycache__')
    assert not cache_files(tmp_path / 'xdg')


def test_a_read_only_install_keeps_the_cache_in_the_users_cache_folder(package, tmp_path):
    site, core = package
    make_read_only(core)
    run_probe(site, XDG_CACHE_HOME=str(tmp_path / 'xdg'))
    assert cache_files(tmp_path / 'xdg' / 'wctls_ros')
    assert not (core / '__pycache__').exists()


def test_numba_cache_dir_wins(package, tmp_path):
    site, core = package
    run_probe(site, XDG_CACHE_HOME=str(tmp_path / 'xdg'), NUMBA_CACHE_DIR=str(tmp_path / 'own'))
    assert cache_files(tmp_path / 'own')
    assert not cache_files(core / '__pycache__') and not cache_files(tmp_path / 'xdg')


def test_a_changed_callee_in_another_file_is_not_served_from_the_cache(package, tmp_path):
    # numba alone checks only the caller's own file: probe.py is unchanged (same time stamp and
    # size), so without the core's fingerprint the cached twice() would still multiply by 2.
    site, core = package
    run_probe(site, XDG_CACHE_HOME=str(tmp_path / 'xdg'))
    caller = core / 'probe.py'
    stamp = caller.stat()
    (core / 'probe_factor.py').write_text(FACTOR.format(3.0))
    os.utime(caller, ns=(stamp.st_atime_ns, stamp.st_mtime_ns))
    run_probe(site, expected=6.0, XDG_CACHE_HOME=str(tmp_path / 'xdg'))


def cache_stamps(folder: pathlib.Path):
    """Return the modification time of each of numba's cache files under a folder, ns."""
    return {path.name: path.stat().st_mtime_ns for path in folder.rglob('probe.twice-*.nb[ic]')}


@pytest.mark.parametrize('edited, recompiled', [(('numpy_core', 'noise.py'), False),
                                                (('rules.py',), True)])
def test_only_sources_the_kernels_read_invalidate_the_cache(package, tmp_path, edited,
                                                            recompiled):
    # The numpy twin is no kernel's source: a docstring edit there keeps every machine's
    # compiled kernels; the shared rule constants are, so an edit there recompiles.
    site, core = package
    run_probe(site, XDG_CACHE_HOME=str(tmp_path / 'xdg'))
    before = cache_stamps(core / '__pycache__')
    source = core.parent.joinpath(*edited)
    source.write_text(source.read_text() + '# an edited comment\n')
    run_probe(site, XDG_CACHE_HOME=str(tmp_path / 'xdg'))
    after = cache_stamps(core / '__pycache__')
    assert before and after.keys() == before.keys()
    assert (after != before) == recompiled


IMPORT_EVERYTHING = """
import json, os, sys
import numba
environment, cache_dir = dict(os.environ), numba.config.CACHE_DIR
from wctls_ros.core.numba_core import (_jit, corners, lines, model_error, noise, pipeline,
                                       precompile, scan, segmentation)
print(json.dumps({'environment_kept': dict(os.environ) == environment,
                  'numba_config_kept': numba.config.CACHE_DIR == cache_dir,
                  'folder': _jit.cache_folder()}))
if sys.argv[1:] == ['set up']:
    _jit.use_disk_cache()
"""


def test_importing_the_core_changes_neither_the_environment_nor_the_cache(package, tmp_path):
    # A read-only install, whose cache goes to the user's folder: the choice that used to be
    # written into os.environ at import. A cached kernel there from before a core change (its
    # fingerprint differs) is deleted only when the cache is set up, before the first compile.
    site, core = package
    make_read_only(core)
    env = {key: value for key, value in os.environ.items() if key != 'NUMBA_CACHE_DIR'}
    env.update(PYTHONPATH=str(site), XDG_CACHE_HOME=str(tmp_path / 'xdg'))

    def run(*arguments):
        return json.loads(subprocess.run(
            [sys.executable, '-c', IMPORT_EVERYTHING, *arguments], env=env, check=True,
            capture_output=True, text=True, timeout=120).stdout)

    folder = pathlib.Path(run()['folder'])
    assert folder.is_relative_to(tmp_path / 'xdg' / 'wctls_ros')
    folder.mkdir(parents=True, exist_ok=True)
    stale = folder / 'pipeline._features_of_scan-1.py311.nbi'
    stale.write_text('compiled from an older core')
    (folder / 'wctls_ros_core.fingerprint').write_text('an older core')
    imported = run()
    assert imported['environment_kept'] and imported['numba_config_kept']
    assert stale.exists()
    assert run('set up')['environment_kept']
    assert not stale.exists()
