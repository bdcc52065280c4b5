# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""An earlier commit's wctls_ros package, imported beside today's for a benchmark to compare."""

import importlib.util
import io
import os
import pathlib
import subprocess
import sys
import tarfile

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]


def earlier_package(commit: str, benchmark: str) -> str:
    """
    Import the wctls_ros package of an earlier commit as a package of its own.

    Its files come out of git into a folder under the user's cache, one per benchmark and
    commit, kept between runs so that numba's cache beside them is too: the whole package,
    since its modules import each other, imported under a name of its own so that its modules
    are not today's.

    :param commit: the commit (anything ``git rev-parse`` takes)
    :param benchmark: the benchmark's name, the cache folder's
    :return: the package's module name (``wctls_ros_<short hash>``)
    """
    full = subprocess.run(['git', '-C', str(REPOSITORY), 'rev-parse', commit], check=True,
                          capture_output=True, text=True).stdout.strip()
    base = pathlib.Path(os.environ.get('XDG_CACHE_HOME') or pathlib.Path.home() / '.cache')
    folder = base / 'wctls_ros' / benchmark / full
    package = folder / 'wctls_ros' / 'wctls_ros'
    if not (package / '__init__.py').is_file():
        archive = subprocess.run(['git', '-C', str(REPOSITORY), 'archive', full,
                                  'wctls_ros/wctls_ros'], check=True,
                                 capture_output=True).stdout
        with tarfile.open(fileobj=io.BytesIO(archive)) as files:
            files.extractall(folder, filter='data')
    name = f'wctls_ros_{full[:7]}'
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, package / '__init__.py',
                                                      submodule_search_locations=[str(package)])
        sys.modules[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[name])
    return name
