# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
What a stock ROS 2 Jazzy install needs of the package: rosdep keys that apt resolves on noble.

The environment itself (noble's library versions, no optional package) is checked by
stock_install_checks.py, which only `make test`'s stock-install run collects.
"""

import ast
import pathlib
import re
import xml.etree.ElementTree as ET

import pytest
from wctls_ros.core import runtime
from wctls_ros.extras import EXTRAS

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
PACKAGES = ('wctls_ros', 'wctls_rplidar', 'wctls_lab', 'wctls_msgs')
DEPENDENCY_TAGS = ('depend', 'build_depend', 'buildtool_depend', 'exec_depend', 'test_depend',
                   'build_export_depend')
TABLE_MARKER = '<!-- rosdep-keys: the test reads the rows of this table -->'


def package_keys() -> dict:
    """Return every rosdep key of both package.xml files -> the packages naming it."""
    keys = {}
    for package in PACKAGES:
        root = ET.parse(REPOSITORY / package / 'package.xml').getroot()
        for tag in DEPENDENCY_TAGS:
            for element in root.iter(tag):
                keys.setdefault(element.text.strip(), []).append(package)
    return keys


def noble_table() -> dict:
    """Return docs/install.md's table: key -> (apt package, version, source)."""
    text = (REPOSITORY / 'docs' / 'install.md').read_text()
    assert TABLE_MARKER in text, 'docs/install.md lost its rosdep-keys table'
    rows = {}
    for line in text.split(TABLE_MARKER, 1)[1].splitlines()[3:]:
        if not line.startswith('|'):
            break
        key, package, version, source = (cell.strip() for cell in line.strip('|').split('|'))
        rows[key] = (package, version, source)
    return rows


def test_every_rosdep_key_resolves_to_a_noble_apt_package_in_the_table():
    table = noble_table()
    missing = sorted(set(package_keys()) - set(table) - set(PACKAGES))
    assert not missing, f'keys with no row in docs/install.md: {missing}'
    for key, (package, version, source) in table.items():
        assert re.fullmatch(r'[a-z0-9][a-z0-9.+-]+', package), (key, package)
        assert re.match(r'(\d+:)?\d+\.\d+', version), (key, version)
        assert source, key


def test_no_key_is_a_pip_key_or_lacks_a_noble_package():
    keys = package_keys()
    # The build farm refuses pip keys; numba has no noble package (its rule fails in apt).
    assert not [key for key in keys if key.endswith('-pip')]
    assert 'python3-numba' not in keys


def test_the_table_lists_no_key_the_packages_dropped():
    extra_rows = sorted(set(noble_table()) - set(package_keys()))
    assert not extra_rows, f'rows for keys no package.xml names: {extra_rows}'


def test_the_oldest_numba_is_the_one_the_oldest_versions_run_installs():
    pins = dict(line.split('==') for line in
                (REPOSITORY / 'requirements' / 'oldest.txt').read_text().splitlines()
                if '==' in line and not line.startswith('#'))
    assert tuple(int(part) for part in pins['numba'].split('.')) == runtime.OLDEST_NUMBA
    assert EXTRAS['numba'].install == runtime.INSTALL_NUMBA
    assert '.'.join(map(str, runtime.OLDEST_NUMBA[:2])) in runtime.INSTALL_NUMBA


@pytest.mark.parametrize('requirement', ['numpy', 'PyYAML', 'pyserial'])
def test_the_stock_run_installs_nobles_version_of_what_a_node_needs(requirement):
    pins = dict(line.split('==') for line in
                (REPOSITORY / 'requirements' / 'stock.txt').read_text().splitlines()
                if '==' in line and not line.startswith('#'))
    apt_name = {'numpy': 'python3-numpy', 'PyYAML': 'python3-yaml',
                'pyserial': 'python3-serial'}[requirement]
    _, noble_version, _ = noble_table()[apt_name]
    # 1:1.26.4+ds-6ubuntu1 is upstream 1.26.4.
    upstream = re.sub(r'^\d+:', '', noble_version).split('-')[0].split('+')[0]
    assert pins[requirement] == upstream


# Standard-library modules Python 3.12 (Ubuntu 24.04's) removed: PEP 594's first ones, PEP 632.
REMOVED_IN_PYTHON_3_12 = {'distutils', 'imp', 'asynchat', 'asyncore', 'smtpd'}


def test_nothing_imports_a_module_python_3_12_removed():
    offenders = []
    for path in sorted((REPOSITORY / 'wctls_ros').rglob('*.py')):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                     else [node.module or ''] if isinstance(node, ast.ImportFrom) else [])
            offenders += [f'{path.relative_to(REPOSITORY)}: {name}' for name in names
                          if name.split('.')[0] in REMOVED_IN_PYTHON_3_12]
    assert not offenders
