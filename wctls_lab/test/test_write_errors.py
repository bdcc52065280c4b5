# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""A write that fails midway (full disk, file-size limit): one line, and nothing half written."""

import resource
import subprocess
import sys

import pytest
from scan_bags import simulated_bag

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

# Enough for the CSV tables, too little for a figure: the tools fail midway through their output.
FILE_SIZE_LIMIT_BYTES = 16 * 1024


@pytest.fixture(scope='module')
def still_bag(tmp_path_factory):
    pytest.importorskip('rclpy')
    return simulated_bag(tmp_path_factory.mktemp('writes'), 'environment_a', 30, 2, '1cm')


def limit_file_size():
    resource.setrlimit(resource.RLIMIT_FSIZE, (FILE_SIZE_LIMIT_BYTES, FILE_SIZE_LIMIT_BYTES))


@pytest.mark.parametrize('module, arguments, status', [
    ('score_cli', ['--methods', 'wctls'], 2),
    ('evaluate_cli', ['--methods', 'wctls', '--range-sigma', '0.01',
                      '--bearing-sigma-deg', '0.05'], 2),
])
def test_a_file_size_limit_midway_is_one_line_and_leaves_the_folder_as_it_was(
        still_bag, tmp_path, module, arguments, status):
    # Before, evaluate ended in a 55-line traceback and both left the tables they had written
    # in the output folder.
    out = tmp_path / 'report'
    out.mkdir()
    done = subprocess.run(
        [sys.executable, '-m', f'wctls_lab.evaluation.{module}', str(still_bag), '--out',
         str(out), *arguments], capture_output=True, text=True, timeout=300,
        preexec_fn=limit_file_size)
    prog = module.split('_')[0]
    assert done.returncode == status, done.stderr
    assert len(done.stderr.splitlines()) == 1 and 'Traceback' not in done.stderr, done.stderr
    assert done.stderr.startswith(f'{prog}: ') and f'cannot write {out}' in done.stderr
    assert 'File too large' in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ['report']       # no staging left
    assert not any(out.iterdir())
    # Without the limit the same command writes its report there.
    done = subprocess.run(
        [sys.executable, '-m', f'wctls_lab.evaluation.{module}', str(still_bag), '--out',
         str(out), *arguments], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert {f'.{prog}', 'table.md' if prog == 'score' else 'report.md'} <= {
        p.name for p in out.iterdir()}
    assert sorted(p.name for p in tmp_path.iterdir()) == ['report']
