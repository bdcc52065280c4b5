# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The tools write only what they own: a folder (or preset file) of their own, or one line.

``demo --out``, ``score --out``, ``evaluate --out`` and ``calibrate --write-preset`` once replaced
or deleted same-named files of the user or of another tool (a bag of the user's in
``DEMO/bag``, process_bag's ``corners.csv``) and exited 0.
"""

import json
import pathlib
import shutil
import signal
import subprocess
import sys
import time

from conftest import REAL_DATA
import pytest
from wctls_ros.cli import UserError
from wctls_ros.output_folders import claim, mark, owned_folder

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

STILL = REAL_DATA / 'sick_lms1xx_static'
SCORE = ('wctls_lab.evaluation.score_cli', STILL, '--methods', 'wctls', '--scans', '0-9',
         '--still', 'yes')
EVALUATE = ('wctls_lab.evaluation.evaluate_cli', STILL, '--methods', 'wctls', '--limit', '10')


def tool(module, *arguments):
    """Run a tool as a user would; return the finished process."""
    return subprocess.run([sys.executable, '-m', module, *map(str, arguments)],
                          capture_output=True, text=True, timeout=300)


def snapshot(folder):
    """Return every file under a folder with its bytes."""
    return {path.relative_to(folder): path.read_bytes()
            for path in sorted(pathlib.Path(folder).rglob('*')) if path.is_file()}


def users_folder(tmp_path, *names):
    """Return a folder holding files of the user's (a bag folder among them)."""
    folder = tmp_path / 'mine'
    (folder / 'bag').mkdir(parents=True)
    (folder / 'bag' / 'metadata.yaml').write_text('a bag of the user\n')
    for name in names:
        (folder / name).write_text(f"the user's {name}\n")
    return folder


def assert_refused(done, prog, folder, before):
    assert done.returncode == 2, done.stdout + done.stderr
    assert len(done.stderr.splitlines()) == 1 and 'Traceback' not in done.stderr, done.stderr
    assert done.stderr.startswith(f'{prog}: error: ') and str(folder) in done.stderr
    assert snapshot(folder) == before
    assert sorted(p.name for p in folder.parent.iterdir()) == [folder.name]   # no staging


@pytest.mark.parametrize('module, prog, names, arguments', [
    ('wctls_lab.demo', 'demo', ('summary.md', 'scan.png'), ['--seconds', '1']),
    (SCORE[0], 'score', ('table.md', 'corners.csv'), SCORE[1:]),
    (EVALUATE[0], 'evaluate', ('report.md', 'summary.csv'), EVALUATE[1:]),
])
def test_a_folder_of_the_users_is_refused_and_left_as_it_was(tmp_path, module, prog, names,
                                                             arguments):
    folder = users_folder(tmp_path, *names)
    before = snapshot(folder)
    assert_refused(tool(module, *arguments, '--out', folder), prog, folder, before)


def test_score_and_evaluate_do_not_write_into_each_others_output(tmp_path):
    score_out, evaluate_out = tmp_path / 'score', tmp_path / 'evaluate'
    assert tool(*SCORE, '--out', score_out).returncode == 0
    assert tool(*EVALUATE, '--out', evaluate_out).returncode == 0
    for command, prog, folder in ((EVALUATE, 'evaluate', score_out),
                                  (SCORE, 'score', evaluate_out)):
        before = snapshot(folder)
        done = tool(*command, '--out', folder)
        assert done.returncode == 2 and f'not an output folder of {prog}' in done.stderr
        assert snapshot(folder) == before
    # Each replaces its own earlier output.
    (score_out / 'table.md').write_text('stale\n')
    assert tool(*SCORE, '--out', score_out).returncode == 0
    assert (score_out / 'table.md').read_text().startswith('# sick_lms1xx_static')
    assert sorted(p.name for p in score_out.iterdir()) == [
        '.score', 'corners.csv', 'score.png', 'table.csv', 'table.md']


def test_process_bags_output_is_not_score_s(tmp_path):
    from wctls_ros.bags.process_bag import main
    output = tmp_path / 'features'
    assert main([str(STILL), '--output', str(output), '--jobs', '1', '--no-progress']) == 0
    before = snapshot(output)
    done = tool(*SCORE, '--out', output)
    assert done.returncode == 2 and 'corners.csv' in done.stderr
    assert snapshot(output) == before


def test_calibrate_writes_a_new_preset_or_its_own_and_refuses_any_other_file(tmp_path):
    from wctls_ros.sensors import SensorPreset
    preset = tmp_path / 'mine.yaml'
    preset.write_text("description: the user's own preset\n")
    done = tool('wctls_lab.evaluation.calibrate_cli', STILL, '--limit', '20', '--write-preset',
                preset)
    assert done.returncode == 2 and len(done.stderr.splitlines()) == 1, done.stderr
    assert done.stderr.startswith('calibrate: error: --write-preset') and str(preset) in \
        done.stderr
    assert preset.read_text() == "description: the user's own preset\n"
    written = tmp_path / 'measured.yaml'
    for _ in range(2):          # a new file, then calibrate's own earlier file
        done = tool('wctls_lab.evaluation.calibrate_cli', STILL, '--limit', '20',
                    '--write-preset', written, '--accept-implausible')
        assert done.returncode == 0, done.stderr
        assert SensorPreset.from_file(written).parameters['range_sigma_m'] > 0.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ['measured.yaml', 'mine.yaml']


def test_the_rule_itself(tmp_path):
    missing, empty = tmp_path / 'missing', tmp_path / 'empty'
    empty.mkdir()
    assert claim(missing, 'score') == [] and claim(empty, 'score') == []
    (tmp_path / 'file').write_text('x')
    with pytest.raises(UserError, match='not a folder'):
        claim(tmp_path / 'file', 'score')
    with owned_folder(missing, 'score') as staging:
        (staging / 'a.csv').write_text('a')
        (staging / 'b.csv').write_text('b')
    assert claim(missing, 'score') == ['.score', 'a.csv', 'b.csv']
    with owned_folder(missing, 'score') as staging:         # b.csv is not written again
        (staging / 'a.csv').write_text('A')
    assert sorted(p.name for p in missing.iterdir()) == ['.score', 'a.csv']
    assert (missing / 'a.csv').read_text() == 'A'
    with pytest.raises(UserError, match='not an output folder of evaluate'):
        claim(missing, 'evaluate')
    mark(empty, 'evaluate', ['report.md'])
    (empty / 'notes.md').write_text("the user's")
    with pytest.raises(UserError, match=r'did not write \(notes.md\)'):
        claim(empty, 'evaluate')


@pytest.mark.parametrize('command', [SCORE, EVALUATE], ids=['score', 'evaluate'])
@pytest.mark.parametrize('number', [signal.SIGHUP, signal.SIGTERM, signal.SIGINT])
def test_a_stop_signal_while_the_output_is_staged_leaves_nothing(tmp_path, command, number):
    # Before, SIGHUP (a closed terminal) or SIGTERM killed the tool with its staging folder
    # left beside the output, and Ctrl-C printed a traceback.
    out = tmp_path / 'out'
    tool_process = subprocess.Popen([sys.executable, '-m', *map(str, command), '--out', str(out)],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob('.partial-*')) and time.monotonic() < deadline:
        time.sleep(0.002)
    tool_process.send_signal(signal.SIGSTOP)
    assert list(tmp_path.glob('.partial-*')), 'the tool never staged its output'
    tool_process.send_signal(number)
    tool_process.send_signal(signal.SIGCONT)
    _, stderr = tool_process.communicate(timeout=60)
    prog = command[0].split('.')[-1].split('_')[0]
    assert tool_process.returncode == 128 + number, stderr
    # (A line before it may say the feature pipeline was compiled, on a busy machine.)
    assert stderr.splitlines()[-1] == f'{prog}: stopped by {signal.Signals(number).name}'
    assert 'Traceback' not in stderr
    assert list(tmp_path.iterdir()) == []


def test_calibrate_writes_its_preset_through_no_link_planted_beside_it(tmp_path):
    # Before, the preset was written through the fixed path .partial-NAME: a link planted there
    # had its target overwritten, and the preset became that link.
    victim = tmp_path / 'victim.txt'
    victim.write_text("the user's\n")
    (tmp_path / '.partial-measured.yaml').symlink_to(victim)
    preset = tmp_path / 'measured.yaml'
    done = tool('wctls_lab.evaluation.calibrate_cli', STILL, '--limit', '20', '--write-preset',
                preset, '--accept-implausible')
    assert done.returncode == 0, done.stderr
    assert victim.read_text() == "the user's\n"
    assert preset.is_file() and not preset.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        '.partial-measured.yaml', 'measured.yaml', 'victim.txt']


def test_a_forged_marker_does_not_make_a_users_file_the_tools(tmp_path):
    # Before, a marker that listed a user's file made score replace or delete it, exit 0.
    real = tmp_path / 'real'
    assert tool(*SCORE, '--out', real).returncode == 0
    written_by_hand = users_folder(tmp_path, 'thesis.tex')
    (written_by_hand / '.score').write_text(json.dumps(
        {'written_by': 'score of wctls_ros', 'files': ['.score', 'bag', 'thesis.tex']}))
    copied = tmp_path / 'copied'
    copied.mkdir()
    (copied / 'table.md').write_text("the user's table\n")
    shutil.copy(real / '.score', copied / '.score')
    for folder in (written_by_hand, copied):
        before = snapshot(folder)
        done = tool(*SCORE, '--out', folder)
        assert done.returncode == 2 and len(done.stderr.splitlines()) == 1, done.stderr
        assert 'refusing to write into it' in done.stderr
        assert snapshot(folder) == before


def test_the_staging_folder_of_a_killed_run_is_removed_by_the_next(tmp_path):
    out = tmp_path / 'out'
    killed = subprocess.Popen([sys.executable, '-m', *map(str, SCORE), '--out', str(out)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob('.partial-*/.score')) and time.monotonic() < deadline:
        time.sleep(0.002)
    killed.kill()
    killed.wait()
    assert list(tmp_path.glob('.partial-out-*')), 'the tool never staged its output'
    # Left alone: a live run's staging folder, and a folder of that name that is no staging.
    live = tmp_path / '.partial-out-live'
    live.mkdir()
    mark(live, 'score', [])
    unmarked = tmp_path / '.partial-out-mine'
    unmarked.mkdir()
    (unmarked / 'notes.md').write_text("the user's\n")
    assert tool(*SCORE, '--out', out).returncode == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        '.partial-out-live', '.partial-out-mine', 'out']
    assert (unmarked / 'notes.md').read_text() == "the user's\n"
