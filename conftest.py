# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The packages' shared fixtures: a private ROS domain per test session, an rclpy context."""

import fcntl
import os
import pathlib
import tempfile
import time

# A failing test's report shows the stacks of the process's other threads.
from failure_report import pytest_runtest_makereport  # noqa: F401
import pytest

# Test sessions take their ROS domain ids from here, one each.
_SESSION_DOMAINS = range(100, 200)
_held_domain = []


def _free_domain_id() -> int:
    """
    Return a domain id no other test session on this machine holds, and hold it.

    Each id has a lock file; the session keeps the lock of its id until it exits (the kernel
    drops it then, even after a crash). Chosen by the process id alone, two concurrent sessions
    shared an id about one time in a hundred and received each other's scans.
    """
    for offset in range(len(_SESSION_DOMAINS)):
        domain = _SESSION_DOMAINS[(os.getpid() + offset) % len(_SESSION_DOMAINS)]
        lock = open(pathlib.Path(tempfile.gettempdir()) / f'wctls_ros_test_domain_{domain}.lock',
                    'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _held_domain.append(lock)
        return domain
    return _SESSION_DOMAINS[os.getpid() % len(_SESSION_DOMAINS)]


# Keep this session's DDS traffic away from anything else running on the machine (a demo, another
# test run); subprocesses started by the tests inherit the variable. A pytest-xdist worker
# inherits its controller's environment too: it takes a domain of its own unless the user set one.
_DOMAIN_CHOSEN_HERE = 'WCTLS_ROS_TEST_DOMAIN_ID'
if 'ROS_DOMAIN_ID' not in os.environ or (
        'PYTEST_XDIST_WORKER' in os.environ
        and os.environ.get(_DOMAIN_CHOSEN_HERE) == os.environ['ROS_DOMAIN_ID']):
    os.environ['ROS_DOMAIN_ID'] = os.environ[_DOMAIN_CHOSEN_HERE] = str(_free_domain_id())


# The real recordings, with their licenses, in the repository's data/ folder. Tests that use them
# never skip: a checkout without them fails.
REAL_DATA = pathlib.Path(__file__).resolve().parent / 'data'


@pytest.fixture(scope='module')
def emulator(tmp_path_factory):
    """
    Yield an S1 emulator process (pseudo-terminal and TCP) shared by a test module.

    :return: the running emulator (see rplidar_testing.start_emulator)
    """
    from rplidar_testing import start_emulator
    with start_emulator(tmp_path_factory.mktemp('s1'), '--tcp-port', '0') as process:
        yield process


@pytest.fixture
def ros_context():
    """
    Yield an initialised rclpy context that is shut down after the test.

    :return: an ``rclpy.context.Context``
    """
    rclpy = pytest.importorskip('rclpy')
    context = rclpy.context.Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


@pytest.fixture
def executor(ros_context):
    """
    Yield a single-threaded executor bound to the test's context.

    :return: an ``rclpy.executors.SingleThreadedExecutor``
    """
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        yield executor
    finally:
        for node in list(executor.get_nodes()):
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown()


def spin_until(executor, predicate, timeout_s=5.0):
    """
    Step the executor until ``predicate()`` is true or the timeout passes.

    :param executor: executor with the nodes to step
    :param predicate: callable returning True when done
    :param timeout_s: wall-clock limit, s
    :return: the final value of ``predicate()``
    """
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    return predicate()


def keep_all_sent():
    """
    Return a best-effort QoS profile deep enough to keep every message a test is sent.

    A test's subscriptions wait behind the nodes' callbacks in its executor: on a busy machine
    the sensor-data profile's five kept messages lost scans the node had published.

    :return: an ``rclpy.qos.QoSProfile`` (best effort, as scans are published; the last 100)
    """
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.BEST_EFFORT)
