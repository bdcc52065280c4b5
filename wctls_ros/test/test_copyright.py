# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Every source file carries a copyright line and its SPDX license, as ament_copyright checks."""

import pathlib
import re

import pytest

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
# Where our own source lives (data/ holds other people's recordings under their licenses).
SOURCE_ROOTS = ('wctls_ros', 'wctls_rplidar', 'wctls_lab', 'wctls_msgs', 'tools', '.ci')
SOURCE_SUFFIXES = ('.py', '.sh', '.msg', '.yaml', '.cfg', '.ini')
SOURCE_NAMES = ('Makefile', 'CMakeLists.txt', 'run')
# Build products and caches that may sit inside the source roots.
SKIPPED_PARTS = {'__pycache__', '.pytest_cache', '.hypothesis', 'build', 'install', 'log'}
COPYRIGHT = re.compile(r'^(#!.*\n)?# Copyright \d{4}(-\d{4})? \S.*\n'
                       r'# SPDX-License-Identifier: Apache-2\.0\n')


def _source_files():
    files = [REPOSITORY / 'Makefile', REPOSITORY / 'pytest.ini', REPOSITORY / 'conftest.py']
    for root in SOURCE_ROOTS:
        for path in sorted((REPOSITORY / root).rglob('*')):
            if (path.is_file() and not SKIPPED_PARTS & set(path.relative_to(REPOSITORY).parts)
                    and (path.suffix in SOURCE_SUFFIXES or path.name in SOURCE_NAMES)):
                files.append(path)
    return files


@pytest.mark.linter
def test_the_source_tree_has_files_to_check():
    names = {path.name for path in _source_files()}
    assert {'Makefile', 'CMakeLists.txt', 'pipeline.py', 'Corner.msg', 'env.sh'} <= names


@pytest.mark.linter
@pytest.mark.parametrize('path', _source_files(),
                         ids=lambda path: str(path.relative_to(REPOSITORY)))
def test_source_file_starts_with_copyright_and_spdx_license(path):
    head = ''.join(path.read_text().splitlines(keepends=True)[:3])
    assert COPYRIGHT.match(head), (
        f'{path.relative_to(REPOSITORY)} must start with "# Copyright <year> <holder>" and '
        '"# SPDX-License-Identifier: Apache-2.0" (after a #! line if it has one)')


@pytest.mark.linter
def test_the_repository_carries_the_license_text():
    text = (REPOSITORY / 'LICENSE').read_text()
    assert 'Apache License' in text and 'Version 2.0, January 2004' in text
    for package in ('wctls_ros', 'wctls_msgs'):
        manifest = (REPOSITORY / package / 'package.xml').read_text()
        assert '<license>Apache-2.0</license>' in manifest
