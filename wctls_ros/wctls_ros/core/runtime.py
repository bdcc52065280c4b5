# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Which implementation of the feature pipeline runs: the compiled one (numba) or the numpy one.

Both compute the same features: the tests hold them to the same segments and corners, every
value within 1e-9 relative, on every scan of the test corpus. The compiled one
(:mod:`.numba_core`) takes about a twentieth of the numpy one's time per scan (``SPEEDUP``), but
it needs numba (``OLDEST_NUMBA`` or newer) and compiles once per machine, 20-60 s on a 2-core VM,
after which it loads from numba's disk cache in about a second. The numpy one
(:mod:`.numpy_core`) needs numpy alone. The landmark tracker's compiled kernels
(:mod:`.numba_core.tracking`) and the dock's fit to the returns (:mod:`.numba_core.dock`) are
compiled and loaded with the compiled pipeline, and serve while it serves
(:func:`compiled_kernels`).

The environment variable ``WCTLS_ROS_CORE`` chooses:

- ``auto`` (the default): the compiled core when numba gives it; the numpy core while numba
  loads it or compiles it (in a thread and a process of their own, so nothing waits for them)
  and whenever numba is missing, too old, or fails to compile;
- ``numba``: the compiled core, compiled before :func:`start` returns; whatever stands in its
  way is an error (:class:`CoreUnavailable`);
- ``numpy``: the numpy core; numba is never imported.

Nothing happens at import. Nodes and tools call :func:`start` before their first scan; a
script that calls :func:`extract_features` without it starts the choice at its first call.
A process forked after :func:`start` keeps the implementation that served its parent then.
"""

from dataclasses import dataclass
import functools
from importlib import metadata
import importlib.util
import math
import os
import re
import subprocess
import sys
import threading
import time
from typing import Any, Callable, Dict, List, Optional

from . import numpy_core
from .config import FeatureConfig
from .features import Features
from ..process import die_with_parent

CORE_VARIABLE = 'WCTLS_ROS_CORE'
CHOICES = ('auto', 'numba', 'numpy')
# The oldest numba that compiles the core (older ones lack math.log2 and other functions it
# uses; checked in ``make test`` with this version).
OLDEST_NUMBA = (0, 60, 0)
INSTALL_NUMBA = f"pip install 'numba>={'.'.join(map(str, OLDEST_NUMBA))}'"
# The numpy core's time per 1080-beam room scan over the compiled core's, measured side by side
# in alternating processes by benchmark/bench_core.py (18x; 11x at 4320 beams, 30x on 541-beam
# SICK scans: docs/performance.md).
SPEEDUP = 20
# The modules of numba_core whose kernels are compiled and loaded with the compiled pipeline
# (:func:`compiled_kernels`), each with what its kernels are, for a refusal's message.
COMPILED_KERNELS = {'tracking': 'tracker', 'dock': 'dock fit', 'odometry': 'odometry'}


class CoreUnavailable(RuntimeError):
    """The compiled core was required (``WCTLS_ROS_CORE=numba``) and cannot be had."""


@dataclass(frozen=True)
class CoreStatus:
    """
    Which implementation serves :func:`extract_features`, and why.

    :ivar name: 'numba' (compiled) or 'numpy'
    :ivar reason: why this one, in a few words (for a log line)
    :ivar pending: the compiled core is being loaded or compiled in the background, and
        replaces the numpy one when it is ready
    :ivar compiling: that takes a compile (the first start on a machine), not a load
    :ivar seconds: how long loading or compiling the compiled core took, s (0 for numpy)
    :ivar compiled_here: the compiled core was compiled for this start (by this process or
        its compile process), not loaded from numba's cache
    :ivar advice: how to get the compiled core, when installing something would
    """

    name: str
    reason: str
    pending: bool = False
    compiling: bool = False
    seconds: float = 0.0
    compiled_here: bool = False
    advice: str = ''

    @property
    def forced(self) -> bool:
        """Return whether the user chose this implementation (``WCTLS_ROS_CORE``)."""
        return self.reason.startswith(CORE_VARIABLE)

    def describe(self) -> str:
        """Return one line for a log: which core runs, why, and what the other one would give."""
        if self.name == 'numba':
            how = 'compiled for this machine' if self.compiled_here else 'loaded'
            return f'compiled feature pipeline ({self.reason}): {how} in {self.seconds:.1f} s'
        if self.compiling:
            meanwhile = (f'; the numpy one serves meanwhile (about {SPEEDUP}x slower per scan)'
                         if self.pending else '')
            return ('compiling the feature pipeline for this machine in another process, '
                    f'20-60 s once per machine{meanwhile}')
        if self.pending:
            return ('numpy feature pipeline for now: the compiled one is loading in the '
                    'background')
        if self.forced:
            return f'numpy feature pipeline ({self.reason})'
        advice = f'; {self.advice}' if self.advice else ''
        return (f'numpy feature pipeline: {self.reason} (the compiled one is about {SPEEDUP}x '
                f'faster per scan{advice})')


Listener = Callable[[CoreStatus], None]
_lock = threading.Lock()
_extract: Callable[..., Features] = numpy_core.extract_features
# The modules of numba_core loaded with the compiled pipeline, by name, once it serves.
_kernels: Dict[str, Any] = {}
_status: Optional[CoreStatus] = None
_compiler: Optional[subprocess.Popen] = None
_listeners: List[Listener] = []
# Set once nothing is pending any more (the background thread has ended, or there was none).
_settled = threading.Event()


def extract_features(ranges_m, angle_min_rad: float, angle_increment_rad: float,
                     config: FeatureConfig = FeatureConfig(), range_min_m: float = 0.0,
                     range_max_m: float = math.inf) -> Features:
    """
    Extract straight segments and corners with covariances from one 2D scan.

    The scan is a LaserScan's geometry: beam i has bearing angle_min + i * angle_increment and
    range ``ranges_m[i]``; invalid returns (NaN, +-inf, outside the range limits) are skipped.
    Steps: adaptive breakpoints, Iterative End Point Fit, merging of collinear neighbours,
    trimming of the returns at segment ends that fit both walls of a corner or lie off the
    segment's line together, the configured line fit with its covariance, and the corners of
    adjacent segments (across the +-pi seam on a full turn) with their propagated (x, y, yaw)
    covariance. Runs the implementation :func:`status` names.

    :param ranges_m: ranges, shape (N,), m
    :param angle_min_rad: bearing of the first beam, rad
    :param angle_increment_rad: bearing step, rad (non-zero, either sign)
    :param config: the pipeline's settings (noise model, thresholds, method)
    :param range_min_m: the scan's own range_min (LaserScan.range_min), m
    :param range_max_m: the scan's own range_max (LaserScan.range_max), m
    :return: the segments and corners, in scan order
    :raises wctls_ros.core.ScanError: when the scan geometry makes no sense, or the scan has
        more than ``config.max_beams`` beams (a ValueError)
    """
    if _status is None:
        start()
    return _extract(ranges_m, angle_min_rad, angle_increment_rad, config, range_min_m,
                    range_max_m)


def compiled_kernels(name: str, compiled: Optional[bool] = None) -> Any:
    """
    Return a module of compiled kernels beside the pipeline, as a caller's choice asks.

    The landmark tracker's (``'tracking'``: :mod:`.numba_core.tracking`, the twin of
    :class:`wctls_ros.frontend.tracking.Tracker`'s numpy steps), the dock's fit to the returns
    (``'dock'``: :mod:`.numba_core.dock`, the twin of :func:`wctls_ros.frontend.dock.fit_returns`)
    and the odometry's search and fit (``'odometry'``: :mod:`.numba_core.odometry`, the twin of
    :func:`wctls_ros.frontend.odometry.estimate_step`'s numpy steps) are compiled and loaded with
    the compiled pipeline. Without them (numba missing, too old or failed, the compiled core
    still loading or compiling, before :func:`start`, ``WCTLS_ROS_CORE=numpy``) the caller runs
    its numpy steps.

    :param name: which: one of :data:`COMPILED_KERNELS`
    :param compiled: None: the kernels while the compiled core serves, else None; True: the
        kernels, the compiled core started and waited for first; False: None (the numpy steps)
    :return: the module of the kernels, or None
    :raises ValueError: on another name
    :raises CoreUnavailable: with ``compiled`` True, when the compiled core cannot serve (the
        reason said)
    """
    if name not in COMPILED_KERNELS:
        raise ValueError(f'no compiled kernels {name!r}: one of {", ".join(COMPILED_KERNELS)}')
    if compiled is False:
        return None
    if compiled:
        start(wait=True)
        if name not in _kernels:
            state = status()
            raise CoreUnavailable(f'the compiled {COMPILED_KERNELS[name]} needs the compiled '
                                  'core: ' + (state.reason if state is not None else
                                              'not started'))
    return _kernels.get(name)


def status() -> Optional[CoreStatus]:
    """Return which implementation serves :func:`extract_features`; None before :func:`start`."""
    return _status


def choice() -> str:
    """
    Return the implementation asked for in ``WCTLS_ROS_CORE``: auto, numba or numpy.

    :raises CoreUnavailable: on any other value
    """
    value = os.environ.get(CORE_VARIABLE, 'auto').strip().lower() or 'auto'
    if value not in CHOICES:
        raise CoreUnavailable(f'{CORE_VARIABLE}={value!r}: use one of {", ".join(CHOICES)}')
    return value


def numba_problem() -> Optional[str]:
    """
    Return why numba cannot compile the core here (not installed, too old), or None.

    Reads the installed version without importing numba (which takes most of a second).
    """
    if 'numba' in sys.modules and sys.modules['numba'] is None:   # blocked from import
        return 'numba is not installed'
    try:
        version = metadata.version('numba')
    except metadata.PackageNotFoundError:
        try:
            found = importlib.util.find_spec('numba') is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            return 'numba is not installed'
        try:                                  # a numba without its metadata: ask it
            import numba
            version = numba.__version__
        except Exception as error:  # noqa: B902 - a broken numba install is no numba
            return f'numba cannot be imported ({error!r})'
    if _version_tuple(version) < OLDEST_NUMBA:
        return (f'numba {version} is older than {".".join(map(str, OLDEST_NUMBA))}, the oldest '
                'that compiles the core')
    return None


def _version_tuple(text: str) -> tuple:
    """Return (major, minor, patch) of a version string such as '0.61.0rc1' (pre-releases too)."""
    numbers = []
    for part in text.split('.')[:3]:
        leading = re.match(r'\d+', part)
        numbers.append(int(leading.group()) if leading else 0)
        if not part.isdigit():
            break
    return tuple(numbers + [0] * (3 - len(numbers)))


def start(wait: bool = False, on_change: Optional[Listener] = None,
          give_up: Optional[Callable[[], bool]] = None, load_now: bool = False) -> CoreStatus:
    """
    Choose the implementation for this process, once; later calls return the choice.

    With ``auto`` and numba at hand, the numpy core serves at once while a thread of this
    process loads the compiled one from numba's cache (about a second) or, on the first start
    on a machine, has it compiled in a process of its own; the compiled one serves from then on.
    With ``wait`` (or ``WCTLS_ROS_CORE=numba``) that happens before this returns: a tool about
    to fork workers, a build step. Ctrl-C and SIGTERM are honoured while waiting, and the
    compile process ends with this one, however this one ends.

    :param wait: load or compile the compiled core before returning (also when an earlier call
        started it in the background)
    :param on_change: called (from another thread) with each later status: when a compile
        starts, and when the compiled core serves or has failed
    :param give_up: with ``wait``, asked ten times a second during a compile whether to stop
        waiting (a tool's signal handler was called): then the compile is ended and the numpy
        core serves
    :param load_now: load the compiled core before returning when numba's cache holds it
        (about a second), compiling in the background only when it does not: a batch tool,
        whose results should not depend on when a load ended (the two cores agree to 1e-9, not
        bit for bit)
    :return: the status now
    :raises CoreUnavailable: when ``WCTLS_ROS_CORE=numba`` and numba cannot give the core
    """
    global _status
    with _lock:
        if _status is not None:
            if _status.pending and on_change is not None:
                _listeners.append(on_change)
            if not (_status.pending and wait):
                return _status
        else:
            _status = _choose(wait, on_change, give_up, load_now)
            if not _status.pending:
                _settled.set()
            return _status
    # Started in the background before, waited for now.
    while not _settled.wait(timeout=0.1):
        if give_up is not None and give_up():
            break
    return _status


def _choose(wait: bool, on_change: Optional[Listener], give_up: Optional[Callable[[], bool]],
            load_now: bool) -> CoreStatus:
    """Make :func:`start`'s first choice (called holding the lock); return the status."""
    asked = choice()
    if asked == 'numpy':
        return CoreStatus('numpy', f'{CORE_VARIABLE}=numpy')
    problem = numba_problem()
    if problem is not None:
        if asked == 'numba':
            raise CoreUnavailable(f'{CORE_VARIABLE}=numba, but {problem} ({INSTALL_NUMBA})')
        return CoreStatus('numpy', problem, advice=INSTALL_NUMBA)
    if load_now and not wait:
        from .numba_core import precompile
        wait = precompile.pipeline_is_cached()
    if wait or asked == 'numba':
        def compiling() -> None:
            if on_change is not None:
                on_change(CoreStatus('numpy', 'compiling the compiled core', compiling=True))
        return _bring_in_compiled(asked, on_compile=compiling, give_up=give_up)
    if on_change is not None:
        _listeners.append(on_change)
    # The thread's first status change waits for this lock, so it comes after this status.
    threading.Thread(target=_bring_in_compiled_in_background, name='wctls_ros core',
                     daemon=True).start()
    return CoreStatus('numpy', 'loading the compiled core', pending=True)


def warm_up() -> float:
    """
    Make the fastest available implementation ready now, compiling it if need be.

    For scripts, benchmarks and build steps that would rather wait than run the numpy core
    meanwhile. The compile runs in a process of its own (Ctrl-C ends it too).

    :return: how long it took, s (about 0 when numba is missing or the numpy core is asked for)
    """
    started = time.perf_counter()
    start(wait=True)
    return time.perf_counter() - started


def _bring_in_compiled(asked: str, on_compile: Optional[Callable[[], None]],
                       give_up: Optional[Callable[[], bool]] = None) -> CoreStatus:
    """
    Load the compiled pipeline, compiling it first in a process of its own if not cached.

    :param asked: the choice of ``WCTLS_ROS_CORE`` ('auto' falls back to numpy on failure)
    :param on_compile: called when a compile is needed, before it starts
    :param give_up: asked during the compile whether to end it (see :func:`start`)
    :return: the status: numba, or numpy with the reason the compiled core failed
    :raises CoreUnavailable: when ``asked`` is 'numba' and the compiled core fails
    """
    global _extract, _kernels
    started = time.perf_counter()
    try:
        import numba
        from .numba_core import pipeline, precompile
        compiled_here = not precompile.pipeline_is_cached()
        if compiled_here:
            if on_compile is not None:
                on_compile()
            _compile_in_child(give_up)
        precompile.warm_up()                   # from the cache
    except Exception as error:  # noqa: B902 - any failure of numba falls back to numpy
        version = sys.modules['numba'].__version__ if sys.modules.get('numba') else '?'
        reason = f'numba {version} failed to compile the core ({_first_line(error)})'
        if asked == 'numba':
            raise CoreUnavailable(reason) from error
        return CoreStatus('numpy', reason)
    _extract = pipeline.extract_features
    _kernels = {name: importlib.import_module(f'.numba_core.{name}', __package__)
                for name in COMPILED_KERNELS}
    return CoreStatus('numba', f'numba {numba.__version__}', seconds=time.perf_counter() - started,
                      compiled_here=compiled_here)


def _bring_in_compiled_in_background() -> None:
    """Bring in the compiled core, then tell the listeners (:func:`start`'s thread)."""
    def compiling() -> None:
        _tell(CoreStatus('numpy', 'compiling the compiled core', pending=True, compiling=True))
    _tell(_bring_in_compiled('auto', on_compile=compiling))


def _tell(new: CoreStatus) -> None:
    """Make ``new`` the status and call the listeners with it (the last time, unless pending)."""
    global _status
    with _lock:
        _status = new
        listeners = list(_listeners)
        if not new.pending:
            _listeners.clear()
    for listener in listeners:
        listener(new)
    if not new.pending:
        _settled.set()


def _first_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return f'{type(error).__name__}: {text[0] if text else ""}'[:200]


def _compile_in_child(give_up: Optional[Callable[[], bool]] = None) -> None:
    """
    Compile the pipeline into numba's cache in a process of its own, and wait for it.

    In another process, so that this one goes on (the numpy core serving) without sharing its
    interpreter lock with numba's compiler. Interruptible: the compile ends with the wait, and
    with this process however it ends (PR_SET_PDEATHSIG).

    :param give_up: asked ten times a second whether to end the compile
    :raises RuntimeError: with the last line the compile printed, when it failed or was ended
    """
    global _compiler
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(path for path in sys.path if path))
    _compiler = subprocess.Popen(
        [sys.executable, '-c', 'from wctls_ros.core.numba_core.precompile import warm_up; '
                               'warm_up()'],
        env=environment, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, preexec_fn=functools.partial(die_with_parent, os.getpid()))
    try:
        while True:
            try:
                _, errors = _compiler.communicate(timeout=0.1)
                break
            except subprocess.TimeoutExpired:
                if give_up is not None and give_up():
                    raise RuntimeError('the compile was ended before it finished') from None
    finally:
        if _compiler.poll() is None:
            _compiler.kill()
            _compiler.wait()
    if _compiler.returncode != 0:
        lines = errors.decode(errors='replace').strip().splitlines() or [
            f'exit status {_compiler.returncode}']
        raise RuntimeError(lines[-1])
