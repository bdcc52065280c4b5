# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The RPLIDAR session on a background thread: handshake, scanning, turn assembly and recovery.

A session stops any stale stream (STOP, then drain), reads the device info and health, learns
how the model's motor is driven (as SLAMTEC's SDK does: the S-series in rpm with MOTOR_SPEED;
an A2, A3 or C1 whose accessory board says so by PWM with SET_MOTOR_PWM; otherwise the serial
DTR line, cleared to run), lists the scan modes (GET_LIDAR_CONF; GET_SAMPLERATE on an A-series
firmware older than 1.24), starts the motor (at ``scan_frequency`` where the model can) and
starts the requested mode (the typical one by default, or when the device lacks the requested
one, with a warning that lists its modes: DenseBoost on the S1). It then decodes the
stream with the decoder of the mode's answer type (standard nodes 0x81, express capsules 0x82,
HQ capsules 0x83, ultra capsules 0x84, dense capsules 0x85, ultra-dense capsules 0x86) and
hands every complete turn to a callback, on this thread.

The handshake's answers carry no checksum: a scan mode's sample time and range and the number
of modes are checked for plausibility, and an implausible value is replaced (the S1's own, an
A-series device's sample time for express and ultra capsules; the Standard mode every RPLIDAR
has for an implausible mode list) with a warning, so that a damaged
answer neither stalls the driver nor empties its scans.

Recovery, without ever ending the thread: a link that cannot be opened or breaks (unplugged
device, closed socket), a silent device, unanswered or unusable requests and a stream with no
valid frame restart the session after an exponential back-off (50 ms doubling to 2 s, back to
50 ms once a turn is published), counted as reconnects; a health warning is logged; a health
error gets a RESET, a ~2 s wait and a new session, and after ``health_reset_attempts`` failed
resets the driver gives up with a clear error until the motor is started again.

:meth:`RplidarDriver.close` ends scanning and stops the motor the model's way (STOP, then
MOTOR_SPEED 0, SET_MOTOR_PWM 0 or DTR set; all three while the model is not yet known), in
whatever state the driver is: scanning, in a handshake, backing off after a failed session or
given up. When the session's link is gone (or there is none) it reopens the link briefly to
send them: a device still powered behind a link that broke is stopped too. A driver that gives
up stops the motor as well. close may be called from a signal handler and after the port is gone.
"""

from dataclasses import dataclass, replace
import enum
import threading
import time
from typing import Callable, Optional

import numpy as np

from .capsules import DenseCapsuleDecoder
from .express import ExpressCapsuleDecoder
from .framing import LinkDamage
from .hq import HqCapsuleDecoder
from .protocol import (ACC_BOARD_MAJOR_IDS, AccBoardFlag, AnswerType, Command, ConfType,
                       decode_conf_value, DESCRIPTOR_SIZE, DeviceHealth, DeviceInfo,
                       encode_acc_board_flag_request, encode_conf_request, encode_express_scan,
                       encode_motor_pwm, encode_motor_speed, encode_request, find_descriptor,
                       HealthStatus, MotorControl, ProtocolError, RPM_MOTOR_MAJOR_ID,
                       SampleRate, ScanMode, SendMode, StreamCounts)
from .standard import CheckedStandardNodeDecoder
from .transport import drain, LinkError, SerialLink, TcpLink
from .turns import PublishGate, TurnAssembler
from .ultra import UltraCapsuleDecoder
from .ultradense import UltraDenseCapsuleDecoder

ANSWER_TIMEOUT_S = 1.0
# The SDK waits this long for GET_ACC_BOARD_FLAG; no answer means no accessory board.
ACC_BOARD_TIMEOUT_S = 0.5
# An accessory board's PWM for the device's desired rotation, when the device does not report
# it (firmware without GET_LIDAR_CONF): the 1.x SDK's default PWM and the A-series' 600 rpm.
DEFAULT_PWM_REFERENCE = (600, 660)
# What each family's serial rate is (SLAMTEC's SDK and sllidar_ros2's launch files), for hints.
BAUDRATE_HINT = ('A1, A2M8 115200; A2M7, A2M12, A3, S1 256000; C1 460800; S2, S3 1000000; '
                 '0 probes them')
# serial_baudrate 0: probe the rates of the RPLIDAR family with GET_INFO, answered within
# milliseconds by a device at the right rate.
AUTO_BAUDRATE = 0
PROBED_BAUDRATES = (115200, 256000, 460800, 1000000)
PROBE_TIMEOUT_S = 0.3
RESET_WAIT_S = 2.0             # an S1 is silent for about 2 s after RESET
BACKOFF_FIRST_S = 0.05
BACKOFF_MAX_S = 2.0
STREAM_READ_TIMEOUT_S = 0.1
# Waking up and decoding cost more than the work per byte, so the stream is read and decoded at
# most this often, except around the predicted end of each turn: from shortly before it every
# arrival is read (the turn's last frames, timestamped on arrival, pin down its stamp), and from
# one frame after it, when the turn can be complete, every arrival is also decoded, so the turn
# is published without extra delay.
STREAM_READ_PERIOD_S = 0.05
TURN_END_MARGIN_S = 0.005
LOG_THROTTLE_S = 5.0
LEGACY_MAX_DISTANCE_M = 16.0       # what the SDK assumes for devices without GET_LIDAR_CONF
# What a handshake answer may plausibly say: RPLIDARs sample at 2 to 32 kHz (500 to 31.25 us per
# sample) and reach 12 to 40 m, within the 65.535 m of a 16-bit millimetre distance; a few
# scan modes each. Far outside, the answer was damaged on the way.
PLAUSIBLE_US_PER_SAMPLE = (10.0, 5000.0)
PLAUSIBLE_MAX_DISTANCE_M = (1.0, 65.535)
MAX_SCAN_MODES = 16
# What replaces an implausible sample time, by the mode's answer type: the S1's for standard
# nodes and dense capsules; for the capsules an S1 does not stream, an A-series device's 4 kHz
# Express and 8 kHz Boost (and HQ), and an S2/S3's 32 kHz for ultra-dense capsules. An
# implausible range is replaced by the S1's.
FALLBACK_US_PER_SAMPLE = {AnswerType.MEASUREMENT: 244.0, AnswerType.DENSE_CAPSULE: 108.0,
                          AnswerType.EXPRESS_CAPSULE: 250.0, AnswerType.ULTRA_CAPSULE: 125.0,
                          AnswerType.ULTRA_DENSE_CAPSULE: 31.25, AnswerType.HQ_CAPSULE: 125.0}
S1_MAX_DISTANCE_M = 40.0
_CHUNK_LOG_SIZE = 256
# The capsule decoder of each capsule answer type (started by EXPRESS_SCAN with the mode's id,
# built with the mode's sample time and range); standard nodes are started by SCAN.
CAPSULE_DECODERS = {AnswerType.EXPRESS_CAPSULE: ExpressCapsuleDecoder,
                    AnswerType.HQ_CAPSULE: HqCapsuleDecoder,
                    AnswerType.ULTRA_CAPSULE: UltraCapsuleDecoder,
                    AnswerType.DENSE_CAPSULE: DenseCapsuleDecoder,
                    AnswerType.ULTRA_DENSE_CAPSULE: UltraDenseCapsuleDecoder}
_DECODED_ANSWERS = (AnswerType.MEASUREMENT, *CAPSULE_DECODERS)


def stream_decoder(mode: ScanMode):
    """
    Return the decoder of a scan mode's stream (standard nodes are checked by their sequence).

    :param mode: a mode whose answer type this driver decodes
    :return: a fresh decoder, built with the mode's sample time and range
    """
    decoder = CAPSULE_DECODERS.get(AnswerType(mode.answer_type), CheckedStandardNodeDecoder)
    return decoder(mode.us_per_sample, mode.max_distance_m)


@dataclass(frozen=True)
class DriverConfig:
    """
    What to connect to and how to scan (sllidar_ros2's parameters plus recovery settings).

    :ivar channel_type: ``'serial'`` or ``'tcp'``
    :ivar serial_port: serial device path
    :ivar serial_baudrate: bits per second (the model's: :data:`BAUDRATE_HINT`);
        :data:`AUTO_BAUDRATE` (0) probes :data:`PROBED_BAUDRATES`
    :ivar tcp_ip: address for ``'tcp'``
    :ivar tcp_port: port for ``'tcp'``
    :ivar scan_mode: scan mode name; ``''`` = the device's typical mode
    :ivar scan_frequency_hz: requested rotation frequency, Hz: MOTOR_SPEED 60 x this rpm on the
        S-series, the PWM scaled from the device's desired rotation with an accessory board;
        a motor on the DTR line only turns on and off
    :ivar data_timeout_s: silence (or garbage) that restarts the session, s
    :ivar health_reset_attempts: RESETs tried on a health error before giving up
    """

    channel_type: str = 'serial'
    serial_port: str = '/dev/ttyUSB0'
    serial_baudrate: int = AUTO_BAUDRATE
    tcp_ip: str = '192.168.0.7'
    tcp_port: int = 20108
    scan_mode: str = ''
    scan_frequency_hz: float = 10.0
    data_timeout_s: float = 1.0
    health_reset_attempts: int = 3

    def __post_init__(self):
        if self.channel_type not in ('serial', 'tcp'):
            raise ValueError(f"channel_type must be 'serial' or 'tcp', got {self.channel_type!r}")


class DriverState(enum.Enum):
    """What the driver is doing."""

    CONNECTING = 'connecting'
    SCANNING = 'scanning'
    MOTOR_STOPPED = 'motor stopped'
    RESETTING = 'resetting'
    FAILED = 'failed'
    CLOSED = 'closed'


@dataclass(frozen=True)
class DriverStatus:
    """
    A snapshot of the driver for diagnostics.

    :ivar state: :class:`DriverState`
    :ivar message: what happened last, in words
    :ivar link: the link's name
    :ivar baudrate: the serial link's rate, bits per second (the probed one with
        :data:`AUTO_BAUDRATE`; 0 for TCP or before a rate answered)
    :ivar device: the device info, once read
    :ivar motor: how the device's motor is driven, once learned
    :ivar health: the last health answer
    :ivar mode: the scan mode streaming (or last streamed)
    :ivar turns: turns handed to the callback
    :ivar dropped_turns: turns not handed over: without a usable angle step or a turn boundary
        in sight, not one plausible rotation (:class:`~wctls_rplidar.turns.PublishGate`:
        a damaged stream), or whose publishing failed
    :ivar withheld_turns: turns handed over (counted in ``turns`` too) that hold samples the
        decoder withheld, the link too damaged to vouch for them (:class:`LinkDamage`): their
        returns were published as none
    :ivar stream: what the scan stream decoders met, summed over sessions (frames, damage,
        repairs, losses, rejected samples)
    :ivar damage: the share of bytes damaged the session's decoder measures and whether it
        withholds the samples it decodes (:class:`~wctls_rplidar.framing.LinkDamage`)
    :ivar flushed_bytes: stale bytes discarded before a session or while the motor is stopped
    :ivar reconnects: sessions that ended in an error
    :ivar backoff_s: the wait before the next attempt after a failure, s (doubles with each
        failure up to its cap, back to the first once a turn is published)
    :ivar resets: RESETs sent after health errors
    :ivar handshake_warnings: the implausible handshake answers replaced in the last session
    :ivar mode_fallback: why the typical mode streams instead of the configured one ('' when
        it does not)
    """

    state: DriverState = DriverState.CONNECTING
    message: str = 'starting'
    link: str = ''
    baudrate: int = 0
    device: Optional[DeviceInfo] = None
    motor: Optional[MotorControl] = None
    health: Optional[DeviceHealth] = None
    mode: Optional[ScanMode] = None
    turns: int = 0
    dropped_turns: int = 0
    withheld_turns: int = 0
    stream: StreamCounts = StreamCounts()
    damage: LinkDamage = LinkDamage()
    flushed_bytes: int = 0
    reconnects: int = 0
    backoff_s: float = BACKOFF_FIRST_S
    resets: int = 0
    handshake_warnings: tuple = ()
    mode_fallback: str = ''


class DeviceError(Exception):
    """The device did not answer, answered wrongly or streamed nothing usable."""


class UnexpectedAnswer(DeviceError):
    """The device answered a request, but with another answer type than the request's."""


class GiveUp(Exception):
    """Retrying cannot help: an unsupported scan mode or a health error that RESET does not fix."""


class _Closing(Exception):
    """close() was called: the handshake under way is abandoned."""


def plausible_mode(mode: ScanMode) -> tuple:
    """
    Replace a scan mode's implausible sample time (by its answer type) or range (the S1's).

    :param mode: the mode as the device described it
    :return: ``(mode, warnings)``: the mode to use and a line per value replaced
    """
    warnings = []
    us_per_sample, max_distance_m = mode.us_per_sample, mode.max_distance_m
    low, high = PLAUSIBLE_US_PER_SAMPLE
    if not low <= us_per_sample <= high:
        us_per_sample = FALLBACK_US_PER_SAMPLE.get(
            mode.answer_type, FALLBACK_US_PER_SAMPLE[AnswerType.MEASUREMENT])
        warnings.append(f'mode {mode.name!r}: {mode.us_per_sample:g} us/sample (plausible: '
                        f'{low:g}-{high:g}): using {us_per_sample:g}')
    low, high = PLAUSIBLE_MAX_DISTANCE_M
    if not low <= max_distance_m <= high:
        max_distance_m = S1_MAX_DISTANCE_M
        warnings.append(f'mode {mode.name!r}: {mode.max_distance_m:g} m range (plausible: '
                        f'{low:g}-{high:g} m): using {max_distance_m:g} m')
    return replace(mode, us_per_sample=us_per_sample, max_distance_m=max_distance_m), warnings


def open_link(config: DriverConfig):
    """
    Open the link the configuration names.

    :param config: the driver configuration
    :return: a :class:`SerialLink` or :class:`TcpLink`
    :raises LinkError: when it cannot be opened
    """
    if config.channel_type == 'tcp':
        return TcpLink(config.tcp_ip, config.tcp_port)
    return SerialLink(config.serial_port, config.serial_baudrate)


class RplidarDriver:
    """
    Runs RPLIDAR sessions on a background thread and hands complete turns to a callback.

    :param config: what to connect to and how to scan
    :param on_turn: called on the reader thread as ``on_turn(turn, mode)`` for each turn
    :param logger: an rclpy-style logger (``info/warning/error(msg, throttle_duration_sec=)``)
    :param link_factory: opens the link for a configuration (for tests; :func:`open_link`)
    """

    def __init__(self, config: DriverConfig, on_turn: Callable, logger,
                 link_factory: Callable = open_link):
        self._config = config
        self._on_turn = on_turn
        self._log = logger
        self._link_factory = link_factory
        self._closing = threading.Event()
        # The service threads and the reader both change the motor request: under this lock,
        # with a count of the requests so a failing session can tell whether one came after it
        # began (and must be honoured) or not.
        self._motor_lock = threading.Lock()
        self._motor_on = True
        self._motor_requests = 0
        # Writers of the status hold this lock; readers take the snapshot without it. Reentrant,
        # and never held while waiting, so that close() in a signal handler cannot deadlock.
        self._lock = threading.RLock()
        self._status = DriverStatus()
        self._dtr_hint_logged = False
        self._thread = threading.Thread(target=self._run, name='rplidar_reader', daemon=True)

    def start(self):
        """Start the reader thread."""
        self._thread.start()

    def close(self, timeout_s: float = 3.0):
        """
        Stop the reader thread, which stops scanning and the motor if the device is reachable.

        Safe to call more than once, from a signal handler, and after the port is gone.

        :param timeout_s: longest wait for the thread, s
        """
        self._closing.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        self._update(state=DriverState.CLOSED, message='closed')

    def set_motor(self, running: bool):
        """
        Request the motor (and scanning) on or off; also retries after the driver gave up.

        :param running: True to scan, False to stop scanning and idle the motor
        """
        with self._motor_lock:
            self._motor_on = running
            self._motor_requests += 1

    def status(self) -> DriverStatus:
        """
        Return a snapshot of the driver's state and counters.

        :return: :class:`DriverStatus`
        """
        return self._status

    def reader_cpu_s(self) -> float:
        """
        Return the CPU time the reader thread has used.

        :return: CPU seconds (0 before the thread started)
        """
        if self._thread.ident is None or not self._thread.is_alive():
            return 0.0
        return time.clock_gettime(time.pthread_getcpuclockid(self._thread.ident))

    def _update(self, **changes):
        """Replace status fields; counters given as ``add_<name>=n`` are incremented."""
        with self._lock:
            for key in [k for k in changes if k.startswith('add_')]:
                name = key[4:]
                changes[name] = getattr(self._status, name) + changes.pop(key)
            self._status = replace(self._status, **changes)

    def _run(self):
        stopped = False
        while not self._closing.is_set():
            try:
                link, baudrate = self._open()
            except _Closing:
                break
            except (LinkError, DeviceError, ProtocolError) as error:
                self._update(state=DriverState.CONNECTING, message=str(error))
                self._log.warning(f'{error}; retrying', throttle_duration_sec=LOG_THROTTLE_S)
                self._back_off()
                continue
            self._update(link=link.name, baudrate=baudrate)
            with self._motor_lock:
                requests = self._motor_requests
            failed = True
            try:
                self._serve(link)
                failed = False
            except _Closing:
                failed = False
            except GiveUp as error:
                failed = False
                self._give_up(link, str(error), requests)
            except (LinkError, DeviceError, ProtocolError) as error:
                self._update(state=DriverState.CONNECTING, message=str(error), add_reconnects=1)
                self._log.warning(f'{error}; reconnecting', throttle_duration_sec=LOG_THROTTLE_S)
            except Exception as error:  # a bug must not end the reader thread
                self._update(state=DriverState.CONNECTING, add_reconnects=1,
                             message=f'unexpected {type(error).__name__}: {error}')
                self._log.error(f'unexpected {type(error).__name__} in the RPLIDAR reader: '
                                f'{error}; reconnecting', throttle_duration_sec=LOG_THROTTLE_S)
            finally:
                if self._closing.is_set():
                    stopped = self._shut_down(link)
                link.close()
            if failed:
                self._back_off()
        if not stopped:
            self._shut_down_through_new_link()

    def _open(self):
        """
        Open the configured link; with an automatic serial rate, the first rate that answers.

        :return: ``(link, baudrate)``: the open link and its serial rate (0 for TCP)
        :raises LinkError: when the port cannot be opened
        :raises DeviceError: when no probed rate gets an answer to GET_INFO
        """
        config = self._config
        if config.channel_type == 'tcp':
            return self._link_factory(config), 0
        if config.serial_baudrate != AUTO_BAUDRATE:
            return self._link_factory(config), config.serial_baudrate
        # The rate that answered last is tried first: a reconnect costs no probe.
        answered = self.status().baudrate
        unexpected = None
        for baudrate in sorted(PROBED_BAUDRATES, key=lambda rate: rate != answered):
            link = self._link_factory(replace(config, serial_baudrate=baudrate))
            try:
                self._stop_stream(link)
                self._ask(link, Command.GET_INFO, AnswerType.DEVICE_INFO,
                          timeout_s=PROBE_TIMEOUT_S)
            except UnexpectedAnswer as error:
                link.close()
                unexpected = error          # the rate is right: the answer is not
                continue
            except (DeviceError, ProtocolError):
                link.close()
                continue
            except BaseException:
                link.close()
                raise
            self._log.info(f'serial_baudrate 0: {config.serial_port} answered GET_INFO at '
                           f'{baudrate} baud (probed {", ".join(map(str, PROBED_BAUDRATES))})')
            return link, baudrate
        if unexpected is not None:
            raise unexpected
        raise DeviceError(f'no answer to GET_INFO at any rate ('
                          f'{", ".join(map(str, PROBED_BAUDRATES))} baud) on '
                          f'{config.serial_port}: not an RPLIDAR, or not powered (a weak USB '
                          'port cannot run it), or a wrong port or cable')

    def _back_off(self):
        """Wait before the next attempt after a failure; double the wait for the one after."""
        backoff_s = self.status().backoff_s
        self._closing.wait(backoff_s)
        self._update(backoff_s=min(2.0 * backoff_s, BACKOFF_MAX_S))

    def _give_up(self, link, reason: str, requests_before: int):
        """
        Report a failure retrying cannot fix; stop the motor; wait until it is requested again.

        A start_motor that arrived after the failing session began is not swallowed: the driver
        tries once more instead of waiting.
        """
        with self._motor_lock:
            requested_since = self._motor_requests != requests_before
            if not requested_since:
                self._motor_on = False
        if requested_since and self._motor_on:
            self._log.warning(f'{reason}; start_motor was requested meanwhile: retrying')
            return
        self._update(state=DriverState.FAILED, message=reason)
        self._log.error(f'{reason} (call the start_motor service to retry)')
        self._shut_down(link)
        while not self._closing.is_set() and not self._motor_on:
            self._closing.wait(STREAM_READ_TIMEOUT_S)

    def _serve(self, link):
        """Run sessions on an open link until closing; raise on link or device trouble."""
        failed_resets = 0
        while not self._closing.is_set():
            self._stop_stream(link)
            device = DeviceInfo.decode(self._ask(link, Command.GET_INFO, AnswerType.DEVICE_INFO))
            health = DeviceHealth.decode(
                self._ask(link, Command.GET_HEALTH, AnswerType.DEVICE_HEALTH))
            self._update(device=device, health=health)
            if health.status == HealthStatus.ERROR:
                if failed_resets >= self._config.health_reset_attempts:
                    raise GiveUp('the device reports a health error (code '
                                 f'0x{health.error_code:04X}) after {failed_resets} resets: '
                                 'power-cycle the device')
                failed_resets += 1
                self._reset(link, health, failed_resets)
                continue
            failed_resets = 0
            if health.status != HealthStatus.OK:
                self._log.warning(f'the device reports a health warning (status {health.status}, '
                                  f'code 0x{health.error_code:04X}); scanning anyway',
                                  throttle_duration_sec=LOG_THROTTLE_S)
            self._update(motor=self._motor_control(link, device))
            mode = self._select_mode(*self._list_modes(link, device))
            if self._motor_on:
                self._scan(link, device, mode)
            else:
                self._idle(link)

    def _motor_control(self, link, device: DeviceInfo) -> MotorControl:
        """Learn how the device's motor is driven, as the SDK does (checkMotorCtrlSupport)."""
        major = device.model >> 4
        if major >= RPM_MOTOR_MAJOR_ID:
            return MotorControl.RPM
        if major not in ACC_BOARD_MAJOR_IDS:
            return MotorControl.DTR
        try:
            flag = AccBoardFlag.decode(self._ask(
                link, Command.GET_ACC_BOARD_FLAG, AnswerType.ACC_BOARD_FLAG,
                encode_acc_board_flag_request(), timeout_s=ACC_BOARD_TIMEOUT_S))
        except (DeviceError, ProtocolError):
            return MotorControl.DTR        # no accessory board to answer
        return MotorControl.PWM if flag.motor_pwm else MotorControl.DTR

    def _start_motor(self, link, device: DeviceInfo):
        """Run the motor the model's way, at ``scan_frequency`` where the model can."""
        motor = self.status().motor
        frequency_hz = self._config.scan_frequency_hz
        if motor == MotorControl.RPM:
            link.write(encode_motor_speed(round(60.0 * frequency_hz)))
        elif motor == MotorControl.PWM:
            rpm, pwm = DEFAULT_PWM_REFERENCE
            if device.supports_conf:
                rpm, pwm = self._conf(link, ConfType.DESIRED_ROTATION)
                rpm, pwm = (rpm, pwm) if rpm and pwm else DEFAULT_PWM_REFERENCE
            # The board's PWM sets the motor's voltage, not its speed: proportional is close.
            link.write(encode_motor_pwm(min(round(pwm * 60.0 * frequency_hz / rpm), 0xFFFF)))
        else:
            wired = link.set_dtr(False)
            if not self._dtr_hint_logged:
                self._dtr_hint_logged = True
                self._log.info(
                    f'the {device.model_name} motor is switched by the DTR line: on and off only, '
                    f'scan_frequency ({frequency_hz:g} Hz) is not applied'
                    + ('' if wired else f'; {link.name} has no DTR line, the motor runs as the '
                       'device leaves it'))

    def _stop_motor(self, link):
        """
        Stop the motor the model's way; before the model is known, every way.

        A device ignores the motor commands of the other families (SLAMTEC's SDK sends each
        family its own), so an unknown model gets all three: STOP alone leaves an S-series motor
        turning, an A2/A3 board's PWM and an A1's DTR line as they were.
        """
        motor = self.status().motor
        if motor in (MotorControl.RPM, None):
            link.write(encode_motor_speed(0))
        if motor in (MotorControl.PWM, None):
            link.write(encode_motor_pwm(0))
        if motor in (MotorControl.DTR, None):
            link.set_dtr(True)

    def _shut_down(self, link) -> bool:
        """
        End scanning, then stop the motor; a link already gone is no error.

        :return: whether the commands were sent
        """
        try:
            link.write(encode_request(Command.STOP))
            self._stop_motor(link)
        except LinkError as error:
            self._log.info(f'the motor could not be told to stop ({error})')
            return False
        return True

    def _shut_down_through_new_link(self):
        """
        On close without a link that took the stop: open one briefly and stop through it.

        With an automatic serial rate not yet found, every probed rate is tried (bytes at a
        wrong rate are garbage the device discards).
        """
        config = self._config
        baudrates = [config.serial_baudrate]
        if config.channel_type == 'serial' and config.serial_baudrate == AUTO_BAUDRATE:
            baudrates = [self.status().baudrate] if self.status().baudrate else PROBED_BAUDRATES
        for baudrate in baudrates:
            try:
                link = self._link_factory(replace(config, serial_baudrate=baudrate))
            except LinkError as error:
                self._log.info(f'closing: the motor could not be told to stop ({error})')
                return
            try:
                self._shut_down(link)
            finally:
                link.close()

    def _stop_stream(self, link):
        """Stop any scan in progress and discard the bytes still arriving."""
        link.write(encode_request(Command.STOP))
        self._closing.wait(0.002)
        self._update(add_flushed_bytes=drain(link, quiet_s=0.02, limit_s=0.5))

    def _reset(self, link, health: DeviceHealth, attempt: int):
        """Send RESET after a health error and wait for the device to come back."""
        self._update(state=DriverState.RESETTING, add_resets=1,
                     message=f'health error (code 0x{health.error_code:04X}): reset '
                             f'{attempt}/{self._config.health_reset_attempts}')
        self._log.error(f'the device reports a health error (code 0x{health.error_code:04X}); '
                        f'resetting it ({attempt}/{self._config.health_reset_attempts})')
        link.write(encode_request(Command.RESET))
        self._closing.wait(RESET_WAIT_S)

    def _read_more(self, link, deadline: float, what: str,
                   timeout_s: float = ANSWER_TIMEOUT_S) -> bytes:
        """Read the next bytes before ``deadline`` (``timeout_s`` after the request) or raise."""
        if self._closing.is_set():
            raise _Closing()
        remaining = deadline - time.monotonic()
        data = link.read(remaining) if remaining > 0 else b''
        if not data:
            raise DeviceError(f'no {what} within {timeout_s:g} s on {link.name}: check '
                              f'the port, serial_baudrate ({BAUDRATE_HINT}), the cable and the '
                              'power (a weak USB port cannot run the motor)')
        return data

    def _request(self, link, request: bytes, answer_type: int, what: str,
                 timeout_s: float = ANSWER_TIMEOUT_S) -> tuple:
        """Send a request; return the answer's descriptor and the bytes received after it."""
        link.write(request)
        deadline = time.monotonic() + timeout_s
        buffer = b''
        others = []
        while True:
            descriptor, end = find_descriptor(buffer)
            if descriptor is not None and descriptor.answer_type == answer_type:
                return descriptor, buffer[end:]
            if descriptor is not None:
                # Stale bytes that look like another answer: search on past their sync.
                others.append(f'0x{descriptor.answer_type:02X}')
                buffer = buffer[end - DESCRIPTOR_SIZE + 1:]
                continue
            try:
                buffer = buffer[end:] + self._read_more(link, deadline, what, timeout_s)
            except DeviceError:
                if not others:
                    raise
                # The device answers, in another way: the port, rate and cable are right.
                raise UnexpectedAnswer(
                    f'no {what} within {timeout_s:g} s on {link.name}: the device answered '
                    f'with answer type {", ".join(dict.fromkeys(others))} instead of '
                    f'0x{answer_type:02X} (a protocol or firmware this driver does not '
                    'speak, or a damaged answer)') from None

    def _ask(self, link, command: int, answer_type: int, request: bytes = b'',
             timeout_s: float = ANSWER_TIMEOUT_S) -> bytes:
        """Send a request and return its single answer's payload (within ``timeout_s``, s)."""
        what = f'answer to {Command(command).name}'
        descriptor, payload = self._request(link, request or encode_request(command),
                                            answer_type, what, timeout_s)
        deadline = time.monotonic() + timeout_s
        while len(payload) < descriptor.length:
            payload += self._read_more(link, deadline, what, timeout_s)
        return payload[:descriptor.length]

    def _conf(self, link, conf_type: int, mode: Optional[int] = None):
        """Read one GET_LIDAR_CONF entry."""
        payload = self._ask(link, Command.GET_LIDAR_CONF, AnswerType.LIDAR_CONF,
                            encode_conf_request(conf_type, mode))
        return decode_conf_value(conf_type, payload)

    def _list_modes(self, link, device: DeviceInfo) -> tuple:
        """
        Return the device's scan modes and the typical mode's id, made plausible.

        Implausible answers are replaced, with a warning, and listed in the status.
        """
        warnings = []
        count = None
        max_distance_m = LEGACY_MAX_DISTANCE_M
        if device.supports_conf:
            count = self._conf(link, ConfType.MODE_COUNT)
            if not 1 <= count <= MAX_SCAN_MODES:
                warnings.append(f'{count} scan modes (plausible: 1-{MAX_SCAN_MODES}): using the '
                                f'Standard mode every RPLIDAR has, {S1_MAX_DISTANCE_M:g} m')
                count, max_distance_m = None, S1_MAX_DISTANCE_M
        if count is None:
            rate = SampleRate.decode(self._ask(link, Command.GET_SAMPLERATE,
                                               AnswerType.SAMPLE_RATE))
            modes = [ScanMode(0, 'Standard', float(rate.standard_us), max_distance_m,
                              AnswerType.MEASUREMENT)]
            typical = 0
        else:
            modes = [ScanMode(mode_id=i, name=self._conf(link, ConfType.MODE_NAME, i),
                              us_per_sample=self._conf(link, ConfType.US_PER_SAMPLE, i),
                              max_distance_m=self._conf(link, ConfType.MAX_DISTANCE, i),
                              answer_type=self._conf(link, ConfType.ANSWER_TYPE, i))
                     for i in range(count)]
            typical = self._conf(link, ConfType.TYPICAL_MODE)
            if typical >= count:
                usable = [m for m in modes if m.answer_type in _DECODED_ANSWERS] or modes
                warnings.append(f'typical mode {typical} of {count} modes: using '
                                f'{usable[0].name!r} instead')
                typical = usable[0].mode_id
        checked = [plausible_mode(mode) for mode in modes]
        warnings += [warning for _, mode_warnings in checked for warning in mode_warnings]
        self._update(handshake_warnings=tuple(warnings))
        if warnings:
            self._log.warning('implausible answers from the device (they carry no checksum) '
                              f'replaced: {"; ".join(warnings)}',
                              throttle_duration_sec=LOG_THROTTLE_S)
        return [mode for mode, _ in checked], typical

    def _select_mode(self, modes: list, typical: int) -> ScanMode:
        """
        Pick the configured mode (or the typical one); give up on an undecodable one.

        A configured mode the device lacks is replaced by its typical mode, with a warning.
        """
        wanted = self._config.scan_mode
        # The typical mode's id is one of the modes' (checked as the list was read).
        typical_mode = next(m for m in modes if m.mode_id == typical)
        mode = next((m for m in modes if wanted and m.name == wanted), typical_mode)
        fallback = ''
        if wanted and mode.name != wanted:
            fallback = (f"scan_mode '{wanted}' is not supported by this device: scanning in its "
                        f"typical mode '{mode.name}'; supported modes: "
                        f"{'; '.join(m.describe() for m in modes)}")
            self._log.warning(fallback, throttle_duration_sec=LOG_THROTTLE_S)
        self._update(mode_fallback=fallback)
        if mode.answer_type not in _DECODED_ANSWERS:
            usable = [m.name for m in modes if m.answer_type in _DECODED_ANSWERS]
            raise GiveUp(f"scan mode '{mode.name}' streams answer type 0x{mode.answer_type:02X}, "
                         f'which this driver does not decode; use one of {usable}')
        return mode

    def _idle(self, link):
        """Keep the motor idle and the link watched until scanning is requested."""
        self._stop_motor(link)
        self._update(state=DriverState.MOTOR_STOPPED, message='motor stopped on request')
        while not self._closing.is_set() and not self._motor_on:
            self._update(add_flushed_bytes=len(link.read(STREAM_READ_TIMEOUT_S)))

    def _scan(self, link, device: DeviceInfo, mode: ScanMode):
        """Start ``mode`` and stream turns until closing or a motor stop request."""
        self._start_motor(link, device)
        decoder = stream_decoder(mode)
        request = (encode_request(Command.SCAN) if mode.answer_type == AnswerType.MEASUREMENT
                   else encode_express_scan(mode.mode_id))
        descriptor, data = self._request(link, request, mode.answer_type,
                                         f'{mode.name} scan descriptor')
        if descriptor.send_mode != SendMode.MULTIPLE or descriptor.length != decoder.FRAME_SIZE:
            raise DeviceError(f'unexpected scan descriptor {descriptor}')
        assembler = TurnAssembler(mode.us_per_sample, decoder.FRAME_SIZE * link.byte_time_s)
        self._update(state=DriverState.SCANNING, mode=mode, damage=decoder.damage,
                     message=f'scanning in {mode.name}')
        self._log.info(f'{device.describe()}; scanning {mode.describe()} on {link.name}')
        self._stream(link, decoder, assembler, mode, data)
        link.write(encode_request(Command.STOP))

    def _stream(self, link, decoder, assembler: TurnAssembler, mode: ScanMode, data: bytes):
        """Decode the stream into turns until closing or a motor stop request."""
        offsets, times, pending = [], [], []
        gate = PublishGate()
        # Whether samples of the turn under way were withheld (judged per decoded chunk).
        withheld = False
        stream_end = 0
        earlier = self.status().stream
        seen = (StreamCounts(), 0)
        frame_s = decoder.SAMPLES_PER_FRAME * mode.us_per_sample * 1e-6
        now = time.monotonic()
        last_bytes_s = last_samples_s = next_decode_s = warn_s = now
        while not self._closing.is_set() and self._motor_on:
            if data:
                stream_end += len(data)
                offsets.append(stream_end)
                times.append(now)
                pending.append(data)
                last_bytes_s = now
            eta_s = assembler.turn_end_eta_s()
            if pending and (eta_s is None or now >= min(next_decode_s, eta_s + frame_s)):
                del offsets[:-_CHUNK_LOG_SIZE], times[:-_CHUNK_LOG_SIZE]
                samples = decoder.feed(b''.join(pending))
                pending.clear()
                next_decode_s = now + STREAM_READ_PERIOD_S
                damage = decoder.damage
                if damage != self.status().damage:
                    self._update(damage=damage)
                if len(samples):
                    last_samples_s = now
                    withheld |= damage.withheld
                    chunk = np.minimum(np.searchsorted(offsets, samples.frame_end), len(times) - 1)
                    for turn in assembler.push(samples, np.asarray(times)[chunk]):
                        if gate.admit(turn):
                            self._hand_over(turn, mode, withheld)
                        else:
                            self._update(add_dropped_turns=1)
                        # The chunk's samples after the turn's end begin the next one.
                        withheld = damage.withheld
                counts = (decoder.counts, assembler.dropped_turns)
                if counts != seen:
                    self._update(stream=earlier + counts[0],
                                 add_dropped_turns=counts[1] - seen[1])
                    damage = counts[0].damaged_frames + counts[0].resyncs
                    # Throttled here: an rclpy log call inspects the caller's source even when
                    # its own throttle then drops the message, at 0.3 ms a call.
                    if damage > seen[0].damaged_frames + seen[0].resyncs and now >= warn_s:
                        warn_s = now + LOG_THROTTLE_S
                        self._log.warning(
                            f'damaged stream: {counts[0].damaged_frames} of '
                            f'{counts[0].frames} frames damaged, {counts[0].resyncs} resyncs, '
                            f'{counts[0].rejected_samples} samples rejected in this session '
                            '(check the cable and the USB power)')
                    seen = counts
                eta_s = assembler.turn_end_eta_s()
            # Judged after the bytes just read are counted and decoded: a reader thread that
            # was not scheduled for a while finds the device's bytes waiting, not a silence.
            if now - last_bytes_s > self._config.data_timeout_s:
                raise DeviceError(f'no scan data for {self._config.data_timeout_s:g} s on '
                                  f'{link.name}')
            if now - last_samples_s > self._config.data_timeout_s:
                raise DeviceError(f'bytes arrive on {link.name} but no valid {mode.name} frame '
                                  f'for {self._config.data_timeout_s:g} s: wrong '
                                  f'serial_baudrate ({BAUDRATE_HINT}) or a damaged link?')
            if eta_s is not None:
                self._closing.wait(max(min(now + STREAM_READ_PERIOD_S,
                                           eta_s - TURN_END_MARGIN_S) - time.monotonic(), 0.0))
            data = link.read(STREAM_READ_TIMEOUT_S)
            now = time.monotonic()

    def _hand_over(self, turn, mode: ScanMode, withheld: bool):
        """
        Give a turn to the callback (a success: the back-off restarts); never fatal.

        :param withheld: it holds samples the decoder withheld (counted once handed over)
        """
        try:
            self._on_turn(turn, mode)
        except Exception as error:  # the callback must not end the reader
            self._log.error(f'publishing a turn failed: {type(error).__name__}: {error}',
                            throttle_duration_sec=LOG_THROTTLE_S)
            self._update(add_dropped_turns=1)
            return
        self._update(add_turns=1, add_withheld_turns=int(withheld), backoff_s=BACKOFF_FIRST_S)
