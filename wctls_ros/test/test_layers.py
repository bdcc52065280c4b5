# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
docs/architecture.md's package maps are the code's: no import runs upward.

Every module is on its package's map, and no import runs upward, within a package or between
packages.

Each Python package's table gives each of its modules or subpackages a layer; a module may
import its own layer and the layers below, never one above (imports inside functions count
too). Between packages, the driver imports neither the features nor the lab, and the features
do not import the lab or the driver.
"""

import ast
import pathlib
import re

import pytest

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
ARCHITECTURE = REPOSITORY / 'docs' / 'architecture.md'
# Each package and the packages of ours it may import.
PACKAGES = {'wctls_rplidar': set(), 'wctls_ros': set(),
            'wctls_lab': {'wctls_ros', 'wctls_rplidar'}}


def map_layers(package: str) -> dict:
    """Return a package map's unit (a top-level module or subpackage name) -> its layer."""
    maps = ARCHITECTURE.read_text().split('## The package maps', 1)[1].split('\n## ', 1)[0]
    text = maps.split(f'### {package}\n', 1)[1].split('\n### ', 1)[0]
    layers = {}
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.strip().strip('|').split('|')]
        if len(cells) != 3 or not cells[0].isdigit():
            continue
        # The units are the backticked names before any colon: `core/`: `config`, ...
        for token in re.findall(r'`([^`]+)`', cells[1].split(':')[0]):
            layers[token.rstrip('/').removesuffix('.py')] = int(cells[0])
    return layers


def unit_of(package: str, path: pathlib.Path) -> str:
    """Return the unit of a package file: its top-level module or subpackage."""
    return path.relative_to(REPOSITORY / package / package).parts[0].removesuffix('.py')


def imports_of(package: str, path: pathlib.Path):
    """
    Yield (package, unit) of every module of ours a file imports, anywhere in it.

    :param package: the file's package
    :param path: the file
    """
    parts = path.relative_to(REPOSITORY / package).with_suffix('').parts
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            module = list(parts[:len(parts) - node.level]) + (
                node.module.split('.') if node.module else [])
            names = [module + [alias.name] for alias in node.names] if len(module) == 1 else [
                module]
        elif isinstance(node, ast.ImportFrom):
            names = [(node.module or '').split('.')]
        elif isinstance(node, ast.Import):
            names = [alias.name.split('.') for alias in node.names]
        else:
            continue
        for name in names:
            if name[0] in PACKAGES and len(name) > 1 and name[1] != '__init__':
                yield name[0], name[1]


def package_files(package: str):
    """Return a package's Python files (its own __init__.py aside)."""
    root = REPOSITORY / package / package
    return [path for path in sorted(root.rglob('*.py')) if path.parent != root
            or path.name != '__init__.py']


@pytest.mark.parametrize('package', PACKAGES)
def test_every_module_of_the_package_is_on_its_map(package):
    layers = map_layers(package)
    assert layers
    missing = sorted({unit_of(package, path) for path in package_files(package)} - set(layers))
    assert not missing, f"not in docs/architecture.md's map of {package}: {missing}"


@pytest.mark.parametrize('package', PACKAGES)
def test_no_import_runs_upward(package):
    layers = map_layers(package)
    upward = []
    for path in package_files(package):
        source = unit_of(package, path)
        for other, target in imports_of(package, path):
            if other != package and other not in PACKAGES[package]:
                upward.append(f'{path.relative_to(REPOSITORY)} imports {other}.{target}')
            elif other == package and layers.get(target, 0) > layers.get(source, 0):
                upward.append(f'{path.relative_to(REPOSITORY)} (layer {layers[source]}) '
                              f'imports {target} (layer {layers[target]})')
    assert not upward, '\n'.join(upward)


def test_an_upward_import_is_found(tmp_path, monkeypatch):
    # The check itself: a driver module importing the features is reported.
    package = tmp_path / 'wctls_rplidar' / 'wctls_rplidar'
    package.mkdir(parents=True)
    (package / 'protocol.py').write_text('from wctls_ros.core import FeatureConfig\n')
    monkeypatch.setattr(__import__(__name__), 'REPOSITORY', tmp_path, raising=False)
    assert list(imports_of('wctls_rplidar', package / 'protocol.py')) == [('wctls_ros', 'core')]
