# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""process_bag: output bags that rosbags reads back, corner tables, clear errors, all-or-none."""

import csv
import dataclasses
import json
import math
import os
import pathlib
import resource
import signal
import subprocess
import sys
import time
import tracemalloc

import numpy as np
import pytest

pytest.importorskip('rclpy')

from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import get_typestore, Stores  # noqa: E402
from scan_bags import (real_bag, REAL_BAGS, truncated_copy,  # noqa: E402
                       write_bag_with_bad_message, write_empty_scan_bag, write_scan_bag,
                       write_string_bag, write_wide_invalid_bag)
from test_feature_node import installed_executable  # noqa: E402
from wctls_ros.bags import read_scans, typestore  # noqa: E402
from wctls_ros.bags.process_bag import CSV_COLUMNS, main, process  # noqa: E402
from wctls_ros.core import METHODS  # noqa: E402
from wctls_ros.params import feature_settings, load_parameters  # noqa: E402

# One of the suite's slowest modules: make test-fast leaves it out.
pytestmark = pytest.mark.slow

CORNERS = 'wctls_msgs/msg/CornerArray'
LINES = 'wctls_msgs/msg/LineSegmentArray'
MARKERS = 'visualization_msgs/msg/MarkerArray'
SCAN = 'sensor_msgs/msg/LaserScan'


def output_messages(path):
    """Yield (topic, message) of an output bag, read with only the definitions stored in it."""
    with AnyReader([path], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        for connection, _, raw in reader.messages():
            yield connection.topic, reader.deserialize(raw, connection.msgtype)


def read_output(path):
    """Read an output bag's topics, types, counts and stamps (as Foxglove would)."""
    counts, stamps = {}, {}
    with AnyReader([path], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    for topic, message in output_messages(path):
        counts[topic] = counts.get(topic, 0) + 1
        if hasattr(message, 'header'):
            stamp = message.header.stamp
            stamps.setdefault(topic, []).append((stamp.sec, stamp.nanosec))
    return types, counts, stamps


def run(argv, capsys):
    status = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_one_method_writes_scans_corners_lines_markers_and_tables(tmp_path, capsys):
    stamps = write_scan_bag(tmp_path / 'bag', count=5)
    status, out, err = run([tmp_path / 'bag', '-o', tmp_path / 'out', '--method', 'ml'], capsys)
    assert status == 0, err
    assert 'wrote' in out and 'ml: 25 corners' in out
    types, counts, read_stamps = read_output(tmp_path / 'out')
    assert types == {'/scan': SCAN, '/corners': CORNERS, '/lines': LINES, '/markers': MARKERS}
    assert counts == dict.fromkeys(types, 5)
    assert read_stamps['/scan'] == read_stamps['/corners'] == read_stamps['/lines'] == stamps
    with open(tmp_path / 'out' / 'corners.csv', newline='') as table:
        rows = list(csv.DictReader(table))
    assert len(rows) == 25 and tuple(rows[0]) == CSV_COLUMNS
    assert {row['method'] for row in rows} == {'ml'}
    assert rows[0]['stamp'] == f'{stamps[0][0]}.{stamps[0][1]:09d}'
    assert float(rows[0]['var_x_m2']) > 0 and float(rows[0]['var_yaw_rad2']) > 0
    # Each corner's wall columns repeat that wall's entry of the scan's LineSegmentArray.
    lines = next(m for topic, m in output_messages(tmp_path / 'out') if topic == '/lines')
    for row in rows[:5]:
        for side in ('first', 'second'):
            wall = lines.segments[int(row[f'{side}_line'])]
            assert int(row[f'{side}_line_points']) == wall.num_points
            assert float(row[f'{side}_line_chi2_dof']) == pytest.approx(wall.residual_chi2_dof)
            assert row[f'{side}_end_seen'] in ('True', 'False')
    document = json.loads((tmp_path / 'out' / 'corners.json').read_text())
    assert document['methods'] == ['ml'] and len(document['scans']) == 5
    first = document['scans'][0]['corners']['ml'][0]
    assert first['x_m'] == pytest.approx(float(rows[0]['x_m']))


@pytest.mark.parametrize('name,method', [
    ('urg04lx_office', 'wctls'), ('ros1/urg04lx_office.bag', 'wctls'),
    ('sick_lms111_static', 'all'), ('ros1/sick_lms1xx_static.bag', 'all')])
def test_real_bags_give_an_output_bag_with_every_scan_and_method(name, method, tmp_path,
                                                                 capsys):
    path = real_bag(name)
    status, out, err = run([path, '-o', tmp_path / 'out', '-m', method, '--no-progress'],
                           capsys)
    assert status == 0, err
    types, counts, stamps = read_output(tmp_path / 'out')
    scan_topic = next(t for t, kind in types.items() if kind == SCAN)
    methods = METHODS if method == 'all' else (method,)
    expected = {scan_topic: SCAN}
    for m in methods:
        suffix = f'/{m}' if method == 'all' else ''
        expected.update({f'/corners{suffix}': CORNERS, f'/lines{suffix}': LINES,
                         f'/markers{suffix}': MARKERS})
    count = dict(REAL_BAGS)[name]
    assert types == expected and counts == dict.fromkeys(expected, count)
    recorded = [(r.scan.header.stamp.sec, r.scan.header.stamp.nanosec)
                for r in read_scans(path)]
    corners_topic = '/corners/wctls' if method == 'all' else '/corners'
    assert stamps[scan_topic] == stamps[corners_topic] == recorded
    with open(tmp_path / 'out' / 'corners.csv', newline='') as table:
        rows = list(csv.DictReader(table))
    assert {row['method'] for row in rows} == set(methods)
    segments = {}
    for topic, message in output_messages(tmp_path / 'out'):
        if topic.startswith('/lines'):
            segments.setdefault(topic, []).extend(message.segments)
    bound_rad = math.radians(load_parameters(None)['max_landmark_angle_sigma_deg'])
    for m in methods:
        # Every scan of these recordings shows a corner (the LMS111 its room corner, and
        # hardly ever one of the two hidden beside the sensor).
        corners = sum(row['method'] == m for row in rows)
        # Every segment is on the lines topic, flagged a line landmark by its angle std.
        lines = segments[f'/lines/{m}' if method == 'all' else '/lines']
        flags = [s.landmark for s in lines]
        assert flags == [math.sqrt(s.covariance[0]) <= bound_rad for s in lines]
        assert corners >= count and (f'{m}: {corners} corners, {len(lines)} segments '
                                     f'({sum(flags)} line landmarks)') in out


def test_config_file_is_checked_like_the_node_does(tmp_path, capsys):
    write_scan_bag(tmp_path / 'bag', count=2)
    config = tmp_path / 'params.yaml'
    config.write_text('/**:\n  ros__parameters:\n    range_sigma_m: 0.01\n'
                      'feature_node:\n  ros__parameters:\n    method: utls\n'
                      '    publish_markers: false\n    use_sim_time: true\n')
    status, out, err = run([tmp_path / 'bag', '-o', tmp_path / 'out', '-c', config], capsys)
    assert status == 0, err
    types, _, _ = read_output(tmp_path / 'out')
    assert set(types) == {'/scan', '/corners', '/lines'}     # publish_markers: false
    assert 'utls: 10 corners' in out
    assert load_parameters(config, overrides={'method': 'ml'})['method'] == 'ml'
    bad = {
        'unknown': ('feature_node:\n  ros__parameters:\n    range_sigma: 0.1\n',
                    "unknown feature_node parameters ['range_sigma']"),
        'type': ('feature_node:\n  ros__parameters:\n    min_segment_points: 8.5\n',
                 'min_segment_points must be of type int'),
        'range': ('feature_node:\n  ros__parameters:\n    iepf_threshold_m: 20.0\n',
                  'iepf_threshold_m = 20.0 is outside its range'),
        'rule': ('feature_node:\n  ros__parameters:\n    range_min_m: 5.0\n'
                 '    range_max_m: 4.0\n', 'range_min_m (5) must be below range_max_m (4)'),
        'method': ('feature_node:\n  ros__parameters:\n    method: tls\n', 'method must be one'),
        'section': ('other_node:\n  ros__parameters:\n    x: 1\n', 'no parameters for'),
        'yaml': ('feature_node: [\n', 'cannot read the parameter file'),
    }
    for name, (text, reason) in bad.items():
        config.write_text(text)
        status, out, err = run([tmp_path / 'bag', '-o', tmp_path / name, '-c', config], capsys)
        assert status == 2 and reason in err and len(err.splitlines()) == 1, (name, err)
        assert not (tmp_path / name).exists()


def test_bad_inputs_give_exit_2_one_line_and_write_nothing(tmp_path, capsys):
    inputs = tmp_path / 'inputs'
    inputs.mkdir()
    write_string_bag(inputs / 'strings')
    write_scan_bag(inputs / 'scans', count=4)
    write_bag_with_bad_message(inputs / 'bad_message', count=6, bad_index=4)
    (inputs / 'garbage.mcap').write_bytes(bytes(range(256)) * 16)
    cases = [
        ([inputs / 'missing'], 'no bag at'),
        ([inputs / 'garbage.mcap'], 'corrupt, truncated'),
        ([truncated_copy(inputs / 'scans', inputs / 'truncated')], 'corrupt, truncated'),
        ([inputs / 'strings'], 'holds no sensor_msgs/msg/LaserScan'),
        ([inputs / 'strings', '--topic', '/chatter'], 'carries std_msgs/msg/String'),
        ([inputs / 'bad_message'], 'damaged after 4 messages of /scan'),
        ([inputs / 'scans', '-c', inputs / 'missing.yaml'], 'cannot read the parameter file'),
    ]
    office = real_bag('ros1/urg04lx_office.bag')
    if office is not None:
        cases.append(([truncated_copy(office, inputs / 'office.bag', 0.7)], 'corrupt'))
    out_dir = tmp_path / 'out'
    out_dir.mkdir()
    for argv, reason in cases:
        status, out, err = run(argv + ['-o', out_dir / 'result'], capsys)
        assert status == 2, (argv, err)
        assert err.startswith('process_bag: error: ') and reason in err, (argv, err)
        assert len(err.splitlines()) == 1 and out == ''
        assert list(out_dir.iterdir()) == []        # no output, no staging folder left


def test_force_replaces_only_an_output_of_process_bag_that_holds_nothing_else(tmp_path, capsys):
    write_scan_bag(tmp_path / 'scans', count=4)
    output = tmp_path / 'result'
    assert run([tmp_path / 'scans', '-o', output], capsys)[0] == 0
    status, _, err = run([tmp_path / 'scans', '-o', output], capsys)
    assert status == 2 and err.splitlines() == [
        f'process_bag: error: {output} exists: refusing to overwrite it (--force replaces an '
        'earlier output of process_bag)']
    status, _, err = run([tmp_path / 'scans', '-o', output, '--force', '-m', 'ml'], capsys)
    assert status == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ['result', 'scans']
    assert {row['method'] for row in csv.DictReader(open(output / 'corners.csv'))} == {'ml'}

    def refused(argv, reason):
        before = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob('*'))
        status, out, err = run(argv + ['--force'], capsys)
        assert status == 2 and out == '', err
        assert err.startswith('process_bag: error: ') and reason in err, err
        assert len(err.splitlines()) == 1
        assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob('*')) == before

    # A user's folder, a user's file, and an output with a user's document added: kept.
    (tmp_path / 'documents').mkdir()
    (tmp_path / 'documents' / 'thesis.tex').write_text('years of work')
    refused([tmp_path / 'scans', '-o', tmp_path / 'documents'], 'not an output of process_bag')
    (tmp_path / 'notes.txt').write_text('notes')
    refused([tmp_path / 'scans', '-o', tmp_path / 'notes.txt'], 'not an output of process_bag')
    (output / 'analysis.ipynb').write_text('{}')
    refused([tmp_path / 'scans', '-o', output],
            'holds files process_bag did not write (analysis.ipynb)')
    (output / 'analysis.ipynb').unlink()
    # An output folder that holds the input: the folder of the bag, or the bag of an output.
    refused([tmp_path / 'scans', '-o', tmp_path], 'holds the input bag')
    refused([output / 'result.mcap', '-o', output], 'holds the input bag')
    refused([tmp_path / 'scans', '-o', tmp_path / 'scans'], 'holds the input bag')
    assert read_output(output)[1]['/corners'] == 4


def test_installed_command_has_help_and_fails_cleanly(tmp_path):
    executable = installed_executable('process_bag')
    result = subprocess.run([str(executable), '--help'], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0
    for option in ('--method', '--config', '--topic', '--output', 'all'):
        assert option in result.stdout
    result = subprocess.run([str(executable), str(tmp_path / 'missing')], cwd=tmp_path,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and 'Traceback' not in result.stderr
    assert result.stderr.strip().splitlines() == [
        f'process_bag: error: no bag at {tmp_path / "missing"}']
    write_scan_bag(tmp_path / 'run', count=2)
    result = subprocess.run([str(executable), str(tmp_path / 'run')], cwd=tmp_path,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / 'run_features' / 'corners.csv').is_file()


def peak_memory(path, output, parameters):
    tracemalloc.start()
    try:
        process(path, output, parameters)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_the_length_of_the_bag(tmp_path):
    parameters = load_parameters(None)
    write_wide_invalid_bag(tmp_path / 'short', count=40)      # 80 kB scans: 3.2 MB of scans
    write_wide_invalid_bag(tmp_path / 'long', count=240)      # 19 MB of scans
    short = peak_memory(tmp_path / 'short', tmp_path / 'short_out', parameters)
    long = peak_memory(tmp_path / 'long', tmp_path / 'long_out', parameters)
    # Holding the 200 extra scans would take 16 MB; streaming keeps the peak where it was.
    assert long < short + 2_000_000, (short, long)


def run_with_file_size_limit(argv, limit_bytes, **kwargs):
    """Run the installed process_bag with RLIMIT_FSIZE: a write past it fails with EFBIG."""
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)    # the write fails instead of killing
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))
    return subprocess.run([str(installed_executable('process_bag'))] + [str(a) for a in argv],
                          capture_output=True, text=True, timeout=120, preexec_fn=limit,
                          **kwargs)


def test_a_failing_write_gives_exit_2_one_line_and_leaves_nothing(tmp_path):
    bag = real_bag('sick_lms1xx_static')
    complete = tmp_path / 'complete'
    result = run_with_file_size_limit([bag, '-o', complete], resource.RLIM_INFINITY)
    assert result.returncode == 0, result.stderr
    sizes = sorted(path.stat().st_size for path in complete.iterdir())
    mcap_size = (complete / 'complete.mcap').stat().st_size
    assert mcap_size == sizes[-1]
    # Each limit stops a different write first: the marker file, the tables, a chunk of the
    # mcap file, and its summary section written when the bag is closed.
    for limit_bytes in (sizes[0] // 2, sizes[-2] // 2, mcap_size // 2, mcap_size - 16):
        out = tmp_path / f'limit_{limit_bytes}'
        out.mkdir()
        result = run_with_file_size_limit([bag, '-o', out / 'result'], limit_bytes)
        assert result.returncode == 2, (limit_bytes, result.stderr)
        assert result.stderr.splitlines() == [
            f'process_bag: error: cannot write {out / "result"}: File too large'], limit_bytes
        assert result.stdout == '' and list(out.iterdir()) == []


def test_a_summary_that_cannot_be_printed_is_one_line_and_exit_2(tmp_path):
    with open('/dev/full', 'w') as full:      # every write: ENOSPC, as on a full disk
        result = subprocess.run(
            [str(installed_executable('process_bag')), str(real_bag('sick_lms1xx_static')),
             '-o', str(tmp_path / 'out')], stdout=full, stderr=subprocess.PIPE, text=True,
            timeout=120)
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        'process_bag: error: cannot print the summary (No space left on device); the output '
        f'{tmp_path / "out"} is complete']


def run_installed(argv, **kwargs):
    """Run the installed process_bag; a hang fails the test instead of stopping it."""
    return subprocess.run([str(installed_executable('process_bag'))] + [str(a) for a in argv],
                          capture_output=True, text=True, timeout=60, **kwargs)


def test_fifos_and_empty_scan_topics_are_refused_at_once(tmp_path):
    os.mkfifo(tmp_path / 'fifo.bag')
    write_scan_bag(tmp_path / 'fifo_storage', count=2)
    storage = tmp_path / 'fifo_storage' / 'fifo_storage.mcap'
    storage.unlink()
    os.mkfifo(storage)
    write_scan_bag(tmp_path / 'fifo_metadata', count=2)
    (tmp_path / 'fifo_metadata' / 'metadata.yaml').unlink()
    os.mkfifo(tmp_path / 'fifo_metadata' / 'metadata.yaml')
    write_empty_scan_bag(tmp_path / 'empty')
    cases = [
        (tmp_path / 'fifo.bag', f'{tmp_path / "fifo.bag"} is not a regular file or a folder'),
        (tmp_path / 'fifo_storage', f'{storage} is not a regular file'),
        (tmp_path / 'fifo_metadata', 'metadata.yaml is not a regular file'),
        (tmp_path / 'empty', f'{tmp_path / "empty"}: its LaserScan topic /scan holds no '
                             'messages'),
    ]
    for bag, reason in cases:
        result = run_installed([bag, '-o', tmp_path / 'out'])
        assert result.returncode == 2, result.stderr
        assert result.stderr.splitlines() == [f'process_bag: error: {reason}'] or (
            len(result.stderr.splitlines()) == 1 and reason in result.stderr), result.stderr
        assert not (tmp_path / 'out').exists()


def test_bad_arguments_are_one_line_and_help_states_defaults_and_exit_statuses():
    result = run_installed(['bag', '--method', 'tls'])
    assert result.returncode == 2 and len(result.stderr.splitlines()) == 1
    assert result.stderr.startswith('process_bag: error: argument -m/--method: invalid choice')
    usage = ' '.join(run_installed(['--help']).stdout.split())
    for text in ('default: <bag name>_features', "default: none, feature_node's defaults",
                 'default: the only one', '0 done', '2 a user error', '130 stopped by SIGINT',
                 '143 by SIGTERM'):
        assert text in usage, text


def wait_for_staging(folder, known=(), timeout_s=60.0):
    """Return a new staging folder in ``folder`` (not one of ``known``) once it has a file."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        staging = [p for p in folder.iterdir()
                   if p.name.startswith('.partial-') and p not in known]
        # Ready when the bag inside has its tables: the run is then in its loop of scans.
        if staging and any(staging[0].glob('*/corners.csv')):
            return staging[0]
        time.sleep(0.005)
    raise AssertionError(f'no run started writing in {folder}')


def start_and_stop_in_the_middle(bag, output, known=()):
    """Start process_bag and stop (SIGSTOP) it while it writes; return it and its staging."""
    process = subprocess.Popen([str(installed_executable('process_bag')), str(bag), '-o',
                                str(output)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    staging = wait_for_staging(output.parent, known)
    process.send_signal(signal.SIGSTOP)
    return process, staging


@pytest.mark.parametrize('number,status', [(signal.SIGINT, 130), (signal.SIGTERM, 143),
                                           (signal.SIGHUP, 129)])
def test_sigint_sigterm_and_sighup_stop_a_run_and_leave_nothing(number, status, tmp_path):
    # SIGHUP (a closed terminal) once killed the run and left its staging folder behind.
    out = tmp_path / 'out'
    out.mkdir()
    process, _ = start_and_stop_in_the_middle(real_bag('ros1/urg04lx_office.bag'),
                                              out / 'result')
    process.send_signal(number)
    process.send_signal(signal.SIGCONT)      # the signal is delivered as it runs on
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == status and stdout == ''
    assert stderr.splitlines() == [
        f'process_bag: interrupted by {signal.Signals(number).name}; nothing written']
    assert list(out.iterdir()) == []


def test_what_a_killed_run_left_is_removed_by_the_next_but_never_a_live_runs(tmp_path):
    out = tmp_path / 'out'
    out.mkdir()
    bag = real_bag('ros1/urg04lx_office.bag')
    killed, left = start_and_stop_in_the_middle(bag, out / 'killed')
    killed.kill()
    killed.wait(timeout=10)
    assert (left / 'killed').is_dir()
    # The next run removes it; the run after that leaves the first (stopped, alive) alone.
    live, live_staging = start_and_stop_in_the_middle(bag, out / 'live', [left])
    assert not left.exists()
    result = run_installed([real_bag('sick_lms1xx_static'), '-o', out / 'next'])
    assert result.returncode == 0, result.stderr
    assert live_staging.is_dir()
    live.send_signal(signal.SIGCONT)
    _, stderr = live.communicate(timeout=60)
    assert live.returncode == 0, stderr
    assert sorted(p.name for p in out.iterdir()) == ['live', 'next']
    assert read_output(out / 'live')[1]['/corners'] == 360


def plain(message):
    """Return a deserialised rosbags message as nested dicts and lists (comparable with ==)."""
    if dataclasses.is_dataclass(message):
        return {f.name: plain(getattr(message, f.name)) for f in dataclasses.fields(message)}
    if isinstance(message, np.ndarray):
        return message.tolist()
    if isinstance(message, (list, tuple)):
        return [plain(item) for item in message]
    return message


def test_the_output_bag_holds_what_feature_node_publishes(tmp_path):
    """Each message equals the node's (rclpy's codec path, serialised by rclpy) field by field."""
    from rclpy.serialization import serialize_message
    from wctls_ros.conversions import (corner_array, laser_scan, line_segment_array,
                                       marker_array, scan_features)
    from wctls_ros.core import line_landmarks, warm_up
    bag = real_bag('urg04lx_office')
    parameters = load_parameters(None)
    config, style, _ = feature_settings(parameters)
    # One pipeline for the bag and the comparison: the two agree to 1e-15 m, not bit for bit,
    # and a process that starts here has the numpy one serve while the compiled one loads.
    warm_up()
    process(bag, tmp_path / 'out', parameters)
    written = {}
    with AnyReader([tmp_path / 'out'], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        for connection, _, raw in reader.messages():
            written.setdefault(connection.topic, []).append(
                plain(reader.deserialize(raw, connection.msgtype)))
    store = typestore()
    compared = 0
    for index, record in enumerate(read_scans(bag)):
        scan = laser_scan(record.scan)            # as feature_node receives it
        features, _ = scan_features(scan, config)
        is_landmark = line_landmarks(features.segments, config.max_landmark_angle_sigma_rad)
        for topic, message, kind in (
                ('/scan', scan, SCAN), ('/corners', corner_array(features, scan.header), CORNERS),
                ('/lines', line_segment_array(features, scan.header, is_landmark=is_landmark),
                 LINES),
                ('/markers', marker_array(features, scan.header, style, is_landmark=is_landmark),
                 MARKERS)):
            published = plain(store.deserialize_cdr(serialize_message(message), kind))
            assert written[topic][index] == published, (topic, index)
            compared += 1
    assert compared == 4 * 360


def test_process_bag_imports_neither_rclpy_nor_any_message_package(tmp_path):
    code = ('import sys; from wctls_ros.bags import process_bag; '
            f'status = process_bag.main([{str(real_bag("sick_lms1xx_static"))!r}, "-m", "all", '
            f'"-o", {str(tmp_path / "out")!r}]); '
            'print(status, sorted(m for m in sys.modules if m.split(".")[0] in '
            '("rclpy", "rcl_interfaces", "builtin_interfaces", "rosidl_runtime_py") '
            'or m.split(".")[0].endswith("_msgs")))')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=120)
    assert result.stdout.splitlines()[-1] == '0 []', result.stdout + result.stderr
    assert read_output(tmp_path / 'out')[1]['/corners/ml'] == 89


def raw_messages(path):
    """Return topic -> the serialised messages of a bag, in order."""
    messages = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        for connection, timestamp, raw in reader.messages():
            messages.setdefault(connection.topic, []).append((timestamp, bytes(raw)))
    return messages


def test_worker_processes_write_exactly_what_one_process_writes(tmp_path, capsys):
    bag = real_bag('ros1/urg04lx_office.bag')
    for jobs in (1, 2):
        status, out, err = run([bag, '-o', tmp_path / f'jobs{jobs}', '-m', 'all', '-j', jobs],
                               capsys)
        assert status == 0, err
    assert raw_messages(tmp_path / 'jobs1') == raw_messages(tmp_path / 'jobs2')
    for name in ('corners.csv', 'corners.json'):
        assert (tmp_path / 'jobs1' / name).read_text() == (tmp_path / 'jobs2' / name).read_text()


def test_several_bags_give_one_table_and_a_damaged_one_is_skipped_in_one_line(tmp_path, capsys):
    inputs = tmp_path / 'inputs'
    inputs.mkdir()
    write_scan_bag(inputs / 'first', count=40)
    write_bag_with_bad_message(inputs / 'damaged', count=60, bad_index=50)
    write_scan_bag(inputs / 'last', count=30)
    bags = [inputs / 'first', inputs / 'damaged', inputs / 'last']
    # Problems found before anything is written: one line each, nothing written.
    status, out, err = run(bags + [inputs / 'missing', inputs / 'first', '-d', tmp_path / 'out'],
                           capsys)
    assert status == 2 and out == ''
    twice = (f'process_bag: error: {inputs / "first"}: its output '
             f'{tmp_path / "out" / "first_features"} would be written twice: give the bags '
             'different names')
    assert err.splitlines() == [twice, f'process_bag: error: no bag at {inputs / "missing"}',
                                twice]
    assert not (tmp_path / 'out').exists()
    status, _, err = run(bags + ['-o', tmp_path / 'out'], capsys)
    assert status == 2 and err.splitlines() == [
        'process_bag: error: --output names the output of one bag; 3 bags were given: use '
        '--output-dir']
    # Damage found midway: that bag is skipped with one line, the others are written.
    status, out, err = run(bags + ['-d', tmp_path / 'out', '-j', '2'], capsys)
    assert status == 2
    assert err.splitlines() == [f'process_bag: error: {inputs / "damaged"} is damaged after 50 '
                                'messages of /scan: ' + err.split(' of /scan: ')[1].strip()]
    written = sorted(p.name for p in (tmp_path / 'out').iterdir())
    assert written == ['first_features', 'last_features']
    assert read_output(tmp_path / 'out' / 'last_features')[1]['/corners'] == 30
    table = [line.split() for line in out.splitlines()]
    assert table[0] == ['bag', 'scans', 'corners', 'wctls', 'seconds', 'scans/s', 'output']
    for row, name, scans in ((table[1], 'first', 40), (table[3], 'last', 30)):
        with open(tmp_path / 'out' / f'{name}_features' / 'corners.csv') as rows:
            corners = len(rows.readlines()) - 1
        assert row[:3] == [str(inputs / name), str(scans), str(corners)]
        assert row[-1] == str(tmp_path / 'out' / f'{name}_features')
    assert table[2] == [str(inputs / 'damaged'), 'failed', '(see', 'above)']
    assert table[4][:2] == ['all', '70'] and table[4][-2:] == ['2', 'written']


def process_ids_of_children(pid):
    """Return the ids of the processes whose parent is ``pid``."""
    children = []
    for stat in pathlib.Path('/proc').glob('[0-9]*/stat'):
        try:
            fields = stat.read_text().rsplit(')', 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            children.append(int(stat.parent.name))
    return children


@pytest.mark.parametrize('parent_gone', [False, True])
def test_a_worker_ends_at_once_when_its_parent_died_before_it_started(parent_gone):
    # The parent can die between forking a worker and the worker's set-up (a Ctrl-C at that
    # moment): no death signal comes then, and the worker would wait for work for ever (seen
    # once in this suite, an orphan worker an hour later). Here the "parent" is a process id
    # that is not the caller's parent when parent_gone, the real one otherwise.
    script = ('import os, sys\n'
              'from wctls_ros.bags.process_bag import _start_worker\n'
              f'_start_worker(None, os.getppid() + {int(parent_gone)})\n'
              'sys.exit(0)\n')
    result = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                            timeout=60)
    assert (result.returncode, result.stderr) == (1 if parent_gone else 0, '')


def wait_until_gone(pids, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        alive = [pid for pid in pids if pathlib.Path(f'/proc/{pid}').exists()
                 and 'Z' not in pathlib.Path(f'/proc/{pid}/stat').read_text().split()[2]]
        if not alive:
            return []
        time.sleep(0.05)
    return alive


@pytest.mark.parametrize('number', [signal.SIGTERM, signal.SIGKILL])
def test_stopping_a_run_with_workers_leaves_no_process_behind(number, tmp_path):
    out = tmp_path / 'out'
    out.mkdir()
    process = subprocess.Popen([str(installed_executable('process_bag')),
                                str(real_bag('ros1/urg04lx_office.bag')), '-o', str(out / 'r'),
                                '-m', 'all', '-j', '2'], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    wait_for_staging(out)
    deadline = time.monotonic() + 30
    while len(workers := process_ids_of_children(process.pid)) < 2:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    process.send_signal(number)
    _, stderr = process.communicate(timeout=60)
    assert wait_until_gone(workers) == []
    if number == signal.SIGTERM:
        assert process.returncode == 143, stderr
        assert stderr.splitlines() == ['process_bag: interrupted by SIGTERM; nothing written']
        assert list(out.iterdir()) == []
