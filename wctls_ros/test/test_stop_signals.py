# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
A stop signal never crashes a node or a tool: it ends it within a second, with its status.

Before, the handlers raised where the main thread stood, inside numba's boxing of the compiled
pipeline's results (numba/numba#2324): feature_node with 100000-beam scans in flight died of a
segmentation fault on Ctrl-C, score and evaluate on Ctrl-C, SIGTERM or SIGHUP, or went on as if
no signal had come (the exception lost in a callback). Each case runs beside two CPU hogs.
"""

import os
import random
import re
import signal
import subprocess
import sys
import time

from conftest import spin_until
import pytest

pytest.importorskip('rclpy')
pytest.importorskip('numba')

from scans import room_scan_message  # noqa: E402, I100
from test_feature_node import installed_executable  # noqa: E402
from test_feature_node_load import NodeProcess  # noqa: E402
from wctls_ros.bags import BagWriter  # noqa: E402

# One of the suite's slowest modules (make test-fast leaves it out), and one that runs
# nodes, emulators or signals against deadlines (make test runs it in its realtime group).
pytestmark = [pytest.mark.slow, pytest.mark.realtime]

BEAMS = 100_000
# From the signal to the end of the process, s.
DEADLINE_S = 1.0
# Signals per case: on the old handlers one in two at least crashed or was lost.
TRIES = 4


@pytest.fixture
def two_cpu_hogs():
    hogs = [subprocess.Popen([sys.executable, '-c', 'while True: pass']) for _ in range(2)]
    yield
    for hog in hogs:
        hog.kill()
        hog.wait()


def ended_by(process, number, meanwhile=lambda: None):
    """
    Send a signal; return (exit status, seconds to the end, what it printed).

    :param meanwhile: called until the process has ended (or for 30 s at most)
    """
    sent = time.monotonic()
    process.send_signal(number)
    while process.poll() is None and time.monotonic() - sent < 30.0:
        meanwhile()
    try:
        output, errors = process.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        output, errors = process.communicate()
    return process.returncode, time.monotonic() - sent, (output or '') + (errors or '')


@pytest.mark.parametrize('number', [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_with_large_scans_in_flight_ends_feature_node_cleanly(
        ros_context, executor, two_cpu_hogs, number):
    heavy = [room_scan_message(beams=BEAMS, seed=seed, stamp=(seed, 0)) for seed in range(3)]
    endings = []
    for _ in range(TRIES):
        node = NodeProcess(ros_context, executor)
        try:
            # The compiled pipeline serves (settled), and is busy on a large scan.
            assert spin_until(executor, lambda: any(
                report['feature pipeline'] == 'numba'
                and report['feature pipeline settled'] == 'yes'
                for report in node.diagnostics), 60.0), node.diagnostics[-1:]
            answered = len(node.corners)

            def flood():
                node.scans.publish(random.choice(heavy))
                spin_until(executor, lambda: False, timeout_s=0.02)
            deadline = time.monotonic() + 30.0
            while len(node.corners) <= answered and time.monotonic() < deadline:
                flood()
            assert len(node.corners) > answered, 'no answer to a large scan within 30 s'
            # Scans keep coming: the node is in the compiled pipeline most of the time.
            for _ in range(random.randint(5, 15)):
                flood()
            endings.append(ended_by(node.process, number, flood))
        finally:
            if node.process.poll() is None:
                node.process.kill()
            node.process.communicate()
            executor.remove_node(node.peer)
            node.peer.destroy_node()
    assert [status for status, _, _ in endings] == [0] * TRIES, [e[2][-500:] for e in endings]
    assert max(seconds for _, seconds, _ in endings) < DEADLINE_S, endings
    assert not any('Traceback' in output for _, _, output in endings), endings


@pytest.fixture(scope='module')
def heavy_bag(tmp_path_factory):
    """Return a bag of 20 still 100000-beam scans (score needs about 10 s on it)."""
    path = tmp_path_factory.mktemp('heavy') / 'bag'
    with BagWriter(path) as bag:
        for index in range(20):
            bag.write('/scan', 1_700_000_000_000_000_000 + index * 100_000_000,
                      room_scan_message(seed=index, beams=BEAMS, stamp=(1_700_000_000 + index, 0)))
    return path


def figures_begin_s(*command) -> float:
    """
    Run a tool to its end; return when it began to draw its figures, s after its start.

    Python reports each module as its import completes (PYTHONPROFILEIMPORTTIME): the tools
    import matplotlib when they draw.
    """
    started = time.monotonic()
    process = subprocess.Popen(command, env=dict(os.environ, PYTHONPROFILEIMPORTTIME='1'),
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    begun = None
    for line in process.stderr:
        if begun is None and re.search(r'\|\s+matplotlib\b', line):
            begun = time.monotonic() - started
    assert process.wait(timeout=300) == 0 and begun is not None
    return begun


@pytest.mark.parametrize('prog, arguments', [
    ('score', ['--still', 'yes']),
    ('evaluate', ['--range-sigma', '0.01', '--bearing-sigma-deg', '0.1']),
])
def test_a_stop_signal_while_a_tool_extracts_ends_it_with_its_status(
        heavy_bag, tmp_path, two_cpu_hogs, prog, arguments):
    executable = str(installed_executable(prog))
    # The signals land from 60 to 85 % of the time a whole run takes to reach its figures:
    # past the imports (a quiet end), in the compiled pipeline's load or the extraction, and
    # before the figures (each one step, of a second or two beside the hogs).
    figures_s = figures_begin_s(executable, str(heavy_bag), '--out', str(tmp_path / 'whole'),
                                *arguments)
    delays = [figures_s * (0.6 + 0.25 * k / (TRIES - 1)) for k in range(TRIES)]
    endings = []
    for attempt, (number, delay) in enumerate(zip(
            [signal.SIGINT, signal.SIGHUP, signal.SIGTERM, signal.SIGINT], delays)):
        out = tmp_path / f'out{attempt}'
        process = subprocess.Popen([executable, str(heavy_bag), '--out', str(out), *arguments],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            time.sleep(delay)
            status, seconds, stderr = ended_by(process, number)
        finally:
            if process.poll() is None:
                process.kill()
                process.communicate()
        endings.append((number, round(delay, 1), status, seconds,
                        stderr.strip().splitlines()[-1:]))
        assert not out.exists()
    assert [status for _, _, status, _, _ in endings] == [
        128 + number for number, _, _, _, _ in endings], endings
    assert [line for _, _, _, _, line in endings] == [
        [f'{prog}: stopped by {signal.Signals(number).name}'] for number, _, _, _, _ in endings]
    assert max(seconds for _, _, _, seconds, _ in endings) < DEADLINE_S, endings
    assert sorted(path.name for path in tmp_path.iterdir()) == ['whole']


@pytest.mark.parametrize('number', [signal.SIGINT, signal.SIGHUP])
def test_a_stop_signal_while_a_tool_loads_the_compiled_pipeline_ends_it_at_once(
        heavy_bag, tmp_path, two_cpu_hogs, number):
    # The load is one step of several seconds beside the hogs, with no safe point in it; the
    # stop waited for its end. Python reports each module as its import completes
    # (PYTHONPROFILEIMPORTTIME): numba's first is the load under way.
    out = tmp_path / 'out'
    process = subprocess.Popen(
        [str(installed_executable('score')), str(heavy_bag), '--out', str(out), '--still', 'yes'],
        env=dict(os.environ, PYTHONPROFILEIMPORTTIME='1'), stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True)
    try:
        for line in process.stderr:
            if re.search(r'\|\s+numba\b', line):
                break
        status, seconds, stderr = ended_by(process, number)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert status == 128 + number, stderr[-2000:]
    assert stderr.strip().splitlines()[-1] == f'score: stopped by {signal.Signals(number).name}'
    assert seconds < DEADLINE_S
    assert list(tmp_path.iterdir()) == []
