# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Every function docs/derivation.md's equation map names exists where the map says."""

import ast
import pathlib
import re

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
DERIVATION = REPOSITORY / 'docs' / 'derivation.md'
# The map's code paths are relative to the numpy implementation's folder.
BASE = REPOSITORY / 'wctls_ros' / 'wctls_ros' / 'core' / 'numpy_core'


def map_rows():
    """Yield (result, code cell) of the equation map's rows."""
    text = DERIVATION.read_text().split('## Equation map', 1)[1].split('\n## ', 1)[0]
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.strip().strip('|').split('|')]
        if len(cells) == 4 and cells[0] not in ('result', '---'):
            yield cells[0], cells[3]


def defined_names(path: pathlib.Path) -> set:
    """Return the module-level functions and classes of a file, and Class.attribute names."""
    names = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        if isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                    names.add(f'{node.name}.{item.target.id}')
                elif isinstance(item, ast.FunctionDef):
                    names.add(f'{node.name}.{item.name}')
    return names


def test_the_map_has_its_rows():
    assert len(list(map_rows())) >= 25


def test_every_named_file_and_function_exists_where_the_map_says():
    missing = []
    for result, code in map_rows():
        path = None
        for token in re.findall(r'`([^`]+)`', code):
            if token.endswith('.py'):
                # A path from the repository (another package's module), else from the core.
                path = (REPOSITORY if token.startswith('wctls_') else BASE) / token
                if not path.is_file():
                    missing.append(f'{result}: no file {token}')
                    path = None
            elif path is not None and path.suffix == '.py' and 'test' not in path.name:
                if token not in defined_names(path):
                    missing.append(f'{result}: {token} is not in {path.relative_to(REPOSITORY)}')
    assert not missing, '\n'.join(missing)
