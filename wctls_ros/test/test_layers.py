# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
docs/architecture.md's package map is the code's: every module is in it, no import runs upward.

The map's table gives each module or subpackage of ``wctls_ros`` a layer; a module may import
its own layer and the layers below, never one above (imports inside functions count too).
"""

import ast
import pathlib
import re

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
PACKAGE = REPOSITORY / 'wctls_ros' / 'wctls_ros'
ARCHITECTURE = REPOSITORY / 'docs' / 'architecture.md'


def map_layers() -> dict:
    """Return the package map's unit (a top-level module or subpackage name) -> its layer."""
    text = ARCHITECTURE.read_text().split('## The package map', 1)[1].split('\n## ', 1)[0]
    layers = {}
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.strip().strip('|').split('|')]
        if len(cells) != 3 or not cells[0].isdigit():
            continue
        # The units are the backticked names outside parentheses: `core/` (6.7k): `config`, ...
        outside = re.sub(r'\([^()]*(\([^()]*\)[^()]*)*\)', '', cells[1])
        for token in re.findall(r'`([^`]+)`', outside.split(':')[0] + ', ' + ', '.join(
                re.findall(r'`[a-z_]+\.py`', outside))):
            layers[token.rstrip('/').removesuffix('.py')] = int(cells[0])
    return layers


def unit_of(path: pathlib.Path) -> str:
    """Return the unit of a package file: its top-level module or subpackage."""
    return path.relative_to(PACKAGE).parts[0].removesuffix('.py')


def imported_units(path: pathlib.Path) -> set:
    """Return the units of wctls_ros a file imports (relative or absolute, anywhere in it)."""
    parts = path.relative_to(PACKAGE).with_suffix('').parts
    units = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.level:
            base = parts[:len(parts) - node.level]
            module = list(base) + (node.module.split('.') if node.module else [])
            names = [module + [alias.name] for alias in node.names] if not module else [module]
        elif isinstance(node, ast.ImportFrom) and (node.module or '').startswith('wctls_ros.'):
            names = [node.module.split('.')[1:]]
        elif isinstance(node, ast.Import):
            names = [alias.name.split('.')[1:] for alias in node.names
                     if alias.name.startswith('wctls_ros.')]
        units.update(name[0] for name in names if name and name[0] != '__init__')
    return units


def package_files():
    return [path for path in sorted(PACKAGE.rglob('*.py')) if path.name != '__init__.py'
            or path.parent != PACKAGE]


def test_every_module_of_the_package_is_on_the_map():
    layers = map_layers()
    missing = sorted({unit_of(path) for path in package_files()} - set(layers))
    assert not missing, f"not in docs/architecture.md's package map: {missing}"


def test_no_import_runs_upward():
    layers = map_layers()
    upward = []
    for path in package_files():
        source = unit_of(path)
        for target in imported_units(path):
            if target in layers and layers[target] > layers.get(source, 0):
                upward.append(f'{path.relative_to(PACKAGE)} (layer {layers[source]}) imports '
                              f'{target} (layer {layers[target]})')
    assert not upward, '\n'.join(upward)


# A module's size on the map may lag its file by this fraction before the map must be redrawn.
SIZE_SLACK = 0.1


def map_sizes() -> dict:
    """Return the package map's stated sizes: the unit's path -> lines (``core/ (5.7k)``)."""
    text = ARCHITECTURE.read_text().split('## The package map', 1)[1].split('\n## ', 1)[0]
    sizes = {}
    for name, size, thousands in re.findall(r'`([a-z_0-9]+/?(?:\.py)?)` \((\d+(?:\.\d+)?)(k?)\)',
                                            text):
        sizes[name] = float(size) * (1000 if thousands else 1)
    return sizes


def lines_of(unit: str) -> int:
    """Return the lines of a unit of the map (a file, or a folder's .py files), as wc -l counts."""
    for root in (PACKAGE, PACKAGE.parent):          # benchmark/ and launch/ sit beside the package
        path = root / unit
        if path.exists():
            files = sorted(path.rglob('*.py')) if path.is_dir() else [path]
            return sum(len(file.read_text().splitlines()) for file in files)
    raise AssertionError(f'docs/architecture.md names {unit}, which is not in the package')


def test_the_map_states_each_units_size_as_it_is():
    sizes = map_sizes()
    assert len(sizes) >= 20, sizes            # the parser still reads the table
    wrong = [f'{unit}: the map says {stated:.0f}, the code has {lines_of(unit)}'
             for unit, stated in sizes.items()
             if abs(lines_of(unit) - stated) > SIZE_SLACK * stated]
    assert not wrong, '\n'.join(wrong)
