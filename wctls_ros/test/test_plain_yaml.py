# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""YAML files from users and bags: no aliases standing for billions, no nesting thousands deep."""

import subprocess
import sys
import time

from conftest import REAL_DATA
import pytest
from wctls_lab.evaluation.truth import load_truth, TruthError
from wctls_lab.simulation import load_floor_plan
from wctls_ros.params import ConfigError, load_parameters
from wctls_ros.plain_yaml import load_without_aliases
import yaml


def nested_aliases(levels: int) -> str:
    """Return a flow list that YAML aliases expand to 9 ** levels strings (a 'billion laughs')."""
    node = '&l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]'
    for level in range(1, levels):
        node = f'&l{level} [{node}, ' + ', '.join([f'*l{level - 1}'] * 8) + ']'
    return node


ROOM = 'polylines:\n  - {closed: true, points: [[0, 0], [4, 0], [4, 3], [0, 3]]}\n'


@pytest.mark.parametrize('load, error, text', [
    (load_floor_plan, ValueError, ROOM + 'name: ALIASES\n'),
    (load_floor_plan, ValueError, ROOM + 'name: room\ndescription: ALIASES\n'),
    (load_floor_plan, ValueError,
     'name: room\npolylines: [{points: [[0, 0], [1, 0], ALIASES]}]\n'),
    (load_parameters, ConfigError, 'feature_node:\n  ros__parameters:\n    method: ALIASES\n'),
    (load_truth, TruthError, 'corners: ALIASES\n'),
])
def test_aliases_are_refused_at_once_in_one_line_that_says_where(tmp_path, load, error, text):
    # Before, a 400-byte floor plan like these (8 levels) took 3.7 GB and 16 s to fail, or
    # over a minute to load; with 5 levels the loaders accepted 59 049 values, or named one of
    # them in the error: neither was refused for its aliases.
    path = tmp_path / 'aliases.yaml'
    path.write_text(text.replace('ALIASES', nested_aliases(5)))
    start = time.monotonic()
    with pytest.raises(error, match=r'alias \(\*name\) at line \d+, column \d+') as refused:
        load(path)
    assert time.monotonic() - start < 1.0
    assert '\n' not in str(refused.value) and len(str(refused.value)) < 300


@pytest.mark.parametrize('load, error, text', [
    (load_floor_plan, ValueError, ROOM + 'name: DEEP\n'),
    (load_parameters, ConfigError, 'feature_node:\n  ros__parameters:\n    method: DEEP\n'),
    (load_truth, TruthError, 'corners: DEEP\n'),
])
@pytest.mark.parametrize('opening, closing', [('[', ']'), ('{a: ', '}')])
def test_a_deep_nesting_is_refused_in_one_line_that_says_where(tmp_path, load, error, text,
                                                               opening, closing):
    # Before, 20 000 levels ended in a RecursionError whose traceback ran 3 000 lines.
    path = tmp_path / 'deep.yaml'
    path.write_text(text.replace('DEEP', opening * 20000 + '1' + closing * 20000))
    with pytest.raises(error, match=r'nested more than 50 deep at line \d+, column \d+') as \
            refused:
        load(path)
    assert '\n' not in str(refused.value) and len(str(refused.value)) < 300


def test_a_deep_nesting_is_one_line_from_a_tool(tmp_path):
    labels = tmp_path / 'labels.yaml'
    labels.write_text('corners: ' + '[' * 20000 + ']' * 20000 + '\n')
    done = subprocess.run([sys.executable, '-m', 'wctls_lab.evaluation.score_cli',
                           str(REAL_DATA / 'sick_lms1xx_static'), '--labels', str(labels)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr[-500:]
    assert done.stderr.startswith('score: error: ') and len(done.stderr.splitlines()) == 1
    assert 'nested more than 50 deep' in done.stderr


def test_nesting_up_to_the_limit_reads_as_safe_load_reads_it():
    text = '[' * 50 + '1' + ']' * 50
    assert load_without_aliases(text) == yaml.safe_load(text)


def test_an_eight_level_plan_fails_in_bounded_memory():
    # The plan the issue found: about 400 bytes, 9 ** 8 = 43 million values once expanded.
    text = ROOM + f'name: {nested_aliases(8)}\n'
    assert len(text) < 500
    script = ('import resource, sys\n'
              'resource.setrlimit(resource.RLIMIT_AS, (2 ** 30, 2 ** 30))\n'
              'from wctls_lab.simulation import floor_plan_from_dict\n'
              'from wctls_ros.plain_yaml import load_without_aliases\n'
              'try:\n'
              '    floor_plan_from_dict(load_without_aliases(sys.stdin.read()))\n'
              'except Exception as error:\n'
              '    print(type(error).__name__, error)\n')
    done = subprocess.run([sys.executable, '-c', script], input=text, capture_output=True,
                          text=True, timeout=60)
    # Under a 1 GB address space limit: what expanded the aliases ends in a MemoryError.
    assert done.stdout.startswith('ComposerError an alias'), done.stdout + done.stderr[-500:]


def test_documents_without_aliases_read_as_safe_load_reads_them():
    text = 'a: &anchor [1, 2.5, x]\nb: {c: null, d: true}\n'
    assert load_without_aliases(text) == yaml.safe_load(text)
