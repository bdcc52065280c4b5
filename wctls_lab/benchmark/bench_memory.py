#!/usr/bin/env python3
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Benchmark the memory of score, evaluate and calibrate against the length of the recording.

Simulates a still S1-like sensor (1080 beams, 1 cm range and 0.05 deg bearing noise) in a
five-corner room for each number of scans (default 1,000, 3,000 and 10,000), then runs each tool
on each bag in a process of its own, as a user would (``score`` with the four methods and
``--still yes``, ``evaluate --out``, ``calibrate``), and prints its peak resident memory (the
child's ru_maxrss, from wait4) and its wall time. Each child runs under an address-space limit
(``--limit-gb``), so a tool whose memory grows with the square of the scans fails with a
MemoryError instead of swapping the machine; the table says so.

With ``--baseline SRC`` the same runs use the ``wctls_ros`` package of another source tree
(e.g. ``git archive <commit> wctls_ros | tar -x -C OLD``, then ``--baseline
OLD/wctls_ros``) in this tree's environment, for a before/after table in one run.

Usage: python bench_memory.py [--scans N ...] [--limit-gb G] [--baseline SRC]
"""

import argparse
import os
import pathlib
import resource
import subprocess
import sys
import tempfile
import time

import yaml

# A convex pentagon, walls 3.5 m long, the sensor inside: five corners, each seen on both walls.
PENTAGON = {
    'name': 'pentagon', 'description': 'five walls of 3.5 m, five corners in view',
    'sensor': {'x': 0.2, 'y': -0.1, 'yaw_deg': 10.0},
    'polylines': [{'closed': True, 'points': [[3.0, 0.0], [0.927, 2.853], [-2.427, 1.763],
                                              [-2.427, -1.763], [0.927, -2.853]]}]}
TOOLS = {
    'score': lambda bag, out: ['score', str(bag), '--still', 'yes'],
    'evaluate': lambda bag, out: ['evaluate', str(bag), '--out', str(out / 'evaluate')],
    'calibrate': lambda bag, out: ['calibrate', str(bag)],
}
# calibrate's own exit status for a model it finds implausible: the run itself was complete.
DONE = (0, 3)


def simulate(bag: pathlib.Path, plan: pathlib.Path, scans: int) -> None:
    """Write a bag of ``scans`` scans of the plan."""
    subprocess.run(tool_command('simulate', [str(plan), str(bag), '--scans', str(scans),
                                             '--seed', '1', '--range-sigma', '0.01',
                                             '--bearing-sigma-deg', '0.05']),
                   check=True, stdout=subprocess.DEVNULL)


def tool_command(name: str, arguments: list) -> list:
    """Return the command line that runs a tool's ``main`` with the package on the path."""
    modules = {'score': 'score_cli', 'evaluate': 'evaluate_cli', 'calibrate': 'calibrate_cli',
               'simulate': 'simulate_cli'}
    return [sys.executable, '-c', f'import sys; from wctls_lab.evaluation.{modules[name]} '
            'import main; sys.exit(main(sys.argv[1:]))'] + arguments


def measure(command: list, limit_bytes: int, package) -> tuple:
    """
    Run one tool in a process of its own under an address-space limit.

    :param command: the tool and its arguments
    :param limit_bytes: the child's RLIMIT_AS, bytes
    :param package: a source tree whose package the child imports first, or None
    :return: (peak resident memory MB, wall time s, exit status, last line of its stderr)
    """
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))

    environment = dict(os.environ)
    if package is not None:
        environment['PYTHONPATH'] = f'{package}:{environment.get("PYTHONPATH", "")}'
    started = time.perf_counter()
    with tempfile.TemporaryFile() as errors:
        child = subprocess.Popen(tool_command(command[0], command[1:]), env=environment,
                                 stdout=subprocess.DEVNULL, stderr=errors, preexec_fn=limit)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
        errors.seek(0)
        lines = errors.read().decode(errors='replace').strip().splitlines()
    return (usage.ru_maxrss / 1024.0, time.perf_counter() - started, child.returncode,
            lines[-1] if lines else '')


def main() -> None:
    """Print the table."""
    cli = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    cli.add_argument('--scans', type=int, nargs='+', default=[1000, 3000, 10000],
                     help='scans of each simulated bag (default: 1000 3000 10000)')
    cli.add_argument('--limit-gb', type=float, default=4.0,
                     help="each tool's address-space limit, GB (default: 4)")
    cli.add_argument('--baseline', type=pathlib.Path, default=None,
                     help='a wctls_ros package source tree to measure too (default: none)')
    cli.add_argument('--tools', nargs='+', choices=tuple(TOOLS), default=list(TOOLS),
                     help='the tools to measure (default: all three)')
    args = cli.parse_args()
    trees = [('this tree', None)] + ([('baseline', args.baseline.resolve())]
                                     if args.baseline else [])
    limit_bytes = int(args.limit_gb * 2 ** 30)
    print(f'# peak resident memory (MB) and wall time (s) per tool and recording; address-space '
          f'limit {args.limit_gb:g} GB; {os.cpu_count()} CPUs, load '
          f'{os.getloadavg()[0]:.1f} at the start')
    print('| tool | tree | scans | peak RSS MB | wall s | status |')
    print('|---|---|---|---|---|---|')
    with tempfile.TemporaryDirectory() as folder:
        work = pathlib.Path(folder)
        plan = work / 'pentagon.yaml'
        plan.write_text(yaml.safe_dump(PENTAGON))
        for scans in args.scans:
            bag = work / f'pentagon_{scans}'
            simulate(bag, plan, scans)
            for tool in args.tools:
                for label, package in trees:
                    out = work / f'{tool}_{scans}_{label.replace(" ", "_")}'
                    out.mkdir()
                    peak, wall, status, last = measure(TOOLS[tool](bag, out), limit_bytes,
                                                       package)
                    verdict = 'done' if status in DONE else f'failed ({status}): {last[:80]}'
                    print(f'| {tool} | {label} | {scans} | {peak:.0f} | {wall:.1f} | '
                          f'{verdict} |', flush=True)


if __name__ == '__main__':
    main()
