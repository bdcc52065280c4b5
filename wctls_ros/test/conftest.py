# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Shared fixtures: a private ROS domain per test session and a per-test rclpy context."""

import ast
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


# The work unit of the modules marked realtime.
REALTIME_UNIT = 'realtime'


def _marked_realtime(module: pathlib.Path) -> bool:
    """Tell whether a test module's ``pytestmark`` holds the ``realtime`` mark (read, not run)."""
    for statement in ast.parse(module.read_text()).body:
        if isinstance(statement, ast.Assign) and any(
                isinstance(target, ast.Name) and target.id == 'pytestmark'
                for target in statement.targets):
            return any(isinstance(node, ast.Attribute) and node.attr == 'realtime'
                       for node in ast.walk(statement.value))
    return False


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """
    Schedule for pytest-xdist (``make test`` runs two workers) one module at a time.

    Every module not marked ``realtime`` is a unit of its own, run whole by either worker, so
    its module fixtures are set up once. The modules marked ``realtime`` (they run nodes,
    emulators or signals against deadlines) form one unit, given out last and only once no
    other worker has a test left: they run one after another with the machine to themselves,
    as in a serial run. The scheduler sees test ids only, so it reads the marks from the
    modules' source.
    """
    from xdist.scheduler import LoadScopeScheduling

    realtime = {}

    class RealtimeModulesLast(LoadScopeScheduling):

        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split('::', 1)[0]
            if module not in realtime:
                realtime[module] = _marked_realtime(config.rootpath / module)
            return REALTIME_UNIT if realtime[module] else module

        def _assign_work_unit(self, node) -> None:
            if any(scope != REALTIME_UNIT for scope in self.workqueue):
                if REALTIME_UNIT in self.workqueue:
                    self.workqueue.move_to_end(REALTIME_UNIT)
                super()._assign_work_unit(node)
                return
            # Only the realtime unit is left. A worker holds back its last test until it gets
            # more work or is told to stop: the unit waits while another worker has more than
            # that one test left, then goes to this worker, and the others are told to stop.
            others = [other for other in self.nodes if other is not node]
            if any(self._pending_of(self.assigned_work[other]) > 1 for other in others):
                return
            super()._assign_work_unit(node)
            for other in others:
                if not other.shutting_down:
                    other.shutdown()

    return RealtimeModulesLast(config, log)


# The real recordings, with their licenses, in the repository's data/ folder. Tests that use them
# never skip: a checkout without them fails.
REAL_DATA = pathlib.Path(__file__).resolve().parents[2] / 'data'


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
