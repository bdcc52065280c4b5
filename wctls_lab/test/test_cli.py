# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The command-line tools as a user meets them: defaults in --help, one-line errors, status 2."""

import importlib
import os
import subprocess

import pytest
from test_feature_node import installed_executable

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

# (module, function returning its parser) of every argparse tool.
PARSERS = [
    ('wctls_lab.evaluation.simulate_cli', 'parser'),
    ('wctls_lab.evaluation.score_cli', 'parser'),
    ('wctls_rplidar.emulator.cli', 'parser'),
    ('wctls_lab.simulated_rplidar', 'parser'),
    ('wctls_lab.demo', 'parser'),
    ('wctls_ros.bags.process_bag', 'parser'),
    ('wctls_lab.evaluation.evaluate_cli', 'evaluate_parser'),
    ('wctls_lab.evaluation.calibrate_cli', 'parser'),
]


@pytest.mark.parametrize('module, function', PARSERS)
def test_every_option_of_every_tool_states_its_default_in_help(module, function):
    parser = getattr(importlib.import_module(module), function)()
    undocumented = [action.option_strings[-1] for action in parser._actions
                    if action.option_strings and action.nargs != 0   # flags: off unless given
                    and 'default' not in (action.help or '')]
    assert undocumented == []
    # What the reader sees: %(default)s expanded, no leftover format codes.
    assert '%(' not in parser.format_help()


def run(tool, *args, cwd=None, **environment):
    """Run an installed tool as a user would, with ``environment`` added; return the process."""
    return subprocess.run([str(installed_executable(tool)), *map(str, args)], capture_output=True,
                          text=True, timeout=120, stdin=subprocess.DEVNULL, cwd=cwd,
                          env=dict(os.environ, **environment))


def assert_one_line_error(result, tool, says):
    """Check a user error: status 2, one line on stderr with the tool and the reason."""
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stderr.startswith(f'{tool}: error: ') and result.stderr.count('\n') == 1, \
        result.stderr
    assert says in result.stderr


@pytest.mark.parametrize('count', ['-5', '0', 'many'])
def test_simulate_refuses_a_scan_count_below_one_and_writes_nothing(tmp_path, count):
    result = run('simulate', 'environment_a', tmp_path / 'bag', '--scans', count)
    assert_one_line_error(result, 'simulate', 'argument --scans: ')
    assert 'at least 1' in result.stderr or 'not an integer' in result.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize('make_args, says', [
    (lambda tmp: ['/nonexistent/plan.yaml', tmp / 'bag'], "no floor plan '/nonexistent/"),
    (lambda tmp: [write(tmp / 'plan.yaml', 'walls: ['), tmp / 'bag'], 'not valid YAML'),
    (lambda tmp: ['environment_a', tmp / 'bag', '--range-sigma', '-1'], 'range_sigma_m'),
])
def test_simulate_refuses_a_bad_plan_or_value_in_one_line(tmp_path, make_args, says):
    result = run('simulate', *make_args(tmp_path))
    assert_one_line_error(result, 'simulate', says)
    assert not (tmp_path / 'bag').exists()


def write(path, text):
    """Write ``text`` to ``path`` (its folder made); return the path."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_simulate_replaces_only_its_own_bag_and_only_with_force(tmp_path):
    pytest.importorskip('rclpy')
    from wctls_ros.bags import bag_info
    bag = tmp_path / 'bag'
    assert run('simulate', 'environment_a', bag, '--scans', '2').returncode == 0
    refused = run('simulate', 'environment_a', bag, '--scans', '3')
    assert_one_line_error(refused, 'simulate', 'refusing to overwrite it (--force replaces')
    assert run('simulate', 'environment_a', bag, '--scans', '3', '--force').returncode == 0
    assert bag_info(bag).topics['/scan'][1] == 3
    assert sorted(p.name for p in bag.iterdir()) == ['bag.mcap', 'metadata.yaml', 'truth.yaml']
    # A folder holding something simulate did not write, or not written by simulate at all.
    write(bag / 'notes.txt', 'mine')
    mine = tmp_path / 'mine'
    mine.mkdir()
    write(mine / 'thesis.tex', 'keep me')
    for target in (bag, mine):
        result = run('simulate', 'environment_a', target, '--scans', '2', '--force')
        assert_one_line_error(result, 'simulate', f'--force refused: {target} is not a bag '
                                                  'folder simulate wrote')
    assert (bag / 'notes.txt').read_text() == 'mine' and bag_info(bag).topics['/scan'][1] == 3
    assert (mine / 'thesis.tex').read_text() == 'keep me'


@pytest.mark.parametrize('args, says', [
    (['--floor-plan', '/nonexistent/plan.yaml'], '--floor-plan: no floor plan'),
    (['--seconds', '-3'], 'argument --seconds: must be at least 1.0'),
    (['--method', 'tls'], 'argument --method: invalid choice'),
])
def test_demo_refuses_bad_arguments_before_starting_anything(tmp_path, args, says):
    result = run('demo', '--out', tmp_path / 'demo', *args, cwd=tmp_path)
    assert_one_line_error(result, 'demo', says)
    assert not (tmp_path / 'demo').exists()


@pytest.mark.parametrize('args, says', [
    (['/nonexistent/bag'], '/nonexistent/bag: no such bag'),
    (['/nonexistent/bag', '--limit', '3'], 'argument --limit: must be at least 6'),
    (['--holdout'], 'give a bag to calibrate on'),
    (['--validate', '/nonexistent/bag', '--write-preset', 'x.yaml'], '--write-preset needs a bag'),
])
def test_calibrate_refuses_what_it_cannot_use_in_one_line(tmp_path, args, says):
    result = run('calibrate', *args, cwd=tmp_path)
    assert_one_line_error(result, 'calibrate', says)
    assert result.stdout == '' and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize('make_args, says', [
    (lambda tmp: ['/nonexistent/bag'], '/nonexistent/bag'),
    (lambda tmp: [write(tmp / 'bag' / 'metadata.yaml', 'x').parent], 'cannot read'),
    (lambda tmp: ['/nonexistent/bag', '--methods', 'wtls,tls'], "unknown methods ['tls']"),
    (lambda tmp: ['/nonexistent/bag', '--min-presence', '2'], 'argument --min-presence'),
])
def test_evaluate_refuses_what_it_cannot_use_in_one_line(tmp_path, make_args, says):
    result = run('evaluate', *make_args(tmp_path), '--out', tmp_path / 'out', cwd=tmp_path)
    assert_one_line_error(result, 'evaluate', says)
    assert not (tmp_path / 'out').exists() and result.stdout == ''


@pytest.mark.parametrize('core', ['numpy', 'auto'])
def test_a_user_error_stays_one_line_whichever_core_the_user_asked_for(tmp_path, core):
    bag = write(tmp_path / 'bag' / 'metadata.yaml', 'x').parent
    result = run('score', bag, '--out', tmp_path / 'out', cwd=tmp_path, WCTLS_ROS_CORE=core)
    assert_one_line_error(result, 'score', 'cannot read')
