# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The emulated S1 itself: requests in, answers and the timed scan stream out (no I/O).

It answers like a real S1 (model 0x61, firmware 1.28, hardware 18; modes 0 Standard, 244 us,
answer 0x81 and 1 DenseBoost, 108 us, answer 0x85, typical 1; no answer to RESET, then about
1.5 s of silence; requests other than STOP, RESET and MOTOR_SPEED are ignored while streaming)
and streams what a :class:`Scene` shows in real time: every frame is due when its last byte would
arrive over a 256000-baud line after its samples were measured. Dense capsule distances are
whole millimetres and standard node distances quarter millimetres. Given other scan modes (such
as :data:`A_SERIES_MODES`, an A-series device's, and another model byte: :data:`EMULATED_MODELS`)
it streams express and ultra capsules too, whose
samples it measures a distance-dependent angle correction before their place on the capsule's
grid, as a triangulating device does (for ultra capsules, the offset SLAMTEC's SDK applies to
the distance sent, where a few passes find it; the distances sent are those the capsule's scale
and predictions carry).

:class:`Faults` (shared with the server's control commands) corrupts, drops or inserts streamed
bytes, cuts frames short (a run of bytes lost, as when a USB packet or a burst of the UART's
input is lost), flips one bit in two bytes of a frame (a double error its XOR checksum does not
see), replays earlier frames, swaps and duplicates the 64-byte packets of a USB full-speed bulk
link, silences the device, sets the health it reports, answers with another answer type and
replaces the values of GET_LIDAR_CONF entries it reports (:func:`parse_conf_answer`).
"""

from dataclasses import dataclass, field, replace
import math
import struct
from typing import Optional, Protocol

import numpy as np

from ..express import (encode_express_capsules, EXPRESS_CAPSULE_SIZE,
                       EXPRESS_MAX_CORRECTION_Q3, EXPRESS_MAX_DISTANCE_MM,
                       EXPRESS_SAMPLES_PER_CAPSULE)
from ..hq import encode_hq_capsules, HQ_CAPSULE_SIZE, HQ_SAMPLES_PER_CAPSULE
from ..protocol import (AccBoardFlag, AnswerType, CAPSULE_SIZE, Command, ConfType,
                        decode_conf_request, DeviceHealth, DeviceInfo, encode_answer,
                        encode_conf_value, encode_dense_capsules, encode_standard_nodes,
                        FULL_TURN_Q6, HealthStatus, MODE_CONF_TYPES, MotorControl, NODE_SIZE,
                        ProtocolError, RequestParser, ResponseDescriptor, SampleRate,
                        SAMPLES_PER_CAPSULE, ScanMode, SendMode)
from ..ultra import (encode_ultra_capsules, offset_deg, ULTRA_CAPSULE_SIZE, ULTRA_MAX_DISTANCE_MM,
                     ULTRA_SAMPLES_PER_CAPSULE, varbitscale_decode, varbitscale_encode)
from ..ultradense import (encode_ultra_dense_capsules, ULTRA_DENSE_CAPSULE_SIZE,
                          ULTRA_DENSE_MAX_DISTANCE_MM, ULTRA_DENSE_SAMPLES_PER_CAPSULE)

MODES = (ScanMode(0, 'Standard', 244.0, 40.0, AnswerType.MEASUREMENT),
         ScanMode(1, 'DenseBoost', 108.0, 40.0, AnswerType.DENSE_CAPSULE))
TYPICAL_MODE = 1
# An A2M8's modes as its firmware 1.2x lists them (Standard 2 kHz, Express 4 kHz, Boost and
# Sensitivity 8 kHz, Stability 4 kHz: SLAMTEC's protocol notes and the A2 datasheet; 12 m, the
# A2M8's datasheet range). Boost, Sensitivity and Stability stream ultra capsules (0x84).
A_SERIES_MODES = (ScanMode(0, 'Standard', 500.0, 12.0, AnswerType.MEASUREMENT),
                  ScanMode(1, 'Express', 250.0, 12.0, AnswerType.EXPRESS_CAPSULE),
                  ScanMode(2, 'Boost', 125.0, 12.0, AnswerType.ULTRA_CAPSULE),
                  ScanMode(3, 'Sensitivity', 125.0, 12.0, AnswerType.ULTRA_CAPSULE),
                  ScanMode(4, 'Stability', 250.0, 12.0, AnswerType.ULTRA_CAPSULE))
# Passes measuring each ultra capsule sample where the offset of the distance it sends puts it.
_ULTRA_PASSES = 3
# A triangulating device's laser sits beside its lens: the angle it measures at lies
# atan(baseline / distance) before where the capsule's angles place a sample.
TRIANGULATION_BASELINE_MM = 20.0
# Per answer type of a scan mode: samples per frame and frame size, bytes.
_FRAMES = {AnswerType.MEASUREMENT: (1, NODE_SIZE),
           AnswerType.EXPRESS_CAPSULE: (EXPRESS_SAMPLES_PER_CAPSULE, EXPRESS_CAPSULE_SIZE),
           AnswerType.ULTRA_CAPSULE: (ULTRA_SAMPLES_PER_CAPSULE, ULTRA_CAPSULE_SIZE),
           AnswerType.DENSE_CAPSULE: (SAMPLES_PER_CAPSULE, CAPSULE_SIZE),
           AnswerType.ULTRA_DENSE_CAPSULE: (ULTRA_DENSE_SAMPLES_PER_CAPSULE,
                                            ULTRA_DENSE_CAPSULE_SIZE),
           AnswerType.HQ_CAPSULE: (HQ_SAMPLES_PER_CAPSULE, HQ_CAPSULE_SIZE)}
# The quality the emulator reports for an ultra-dense return (0-255).
ULTRA_DENSE_RETURN_QUALITY = 190
SERIAL_NUMBER = b'WCTLS-S1-EMULATR'
DEFAULT_RPM = 600
MODEL_S1M1 = 0x61
RESET_SILENCE_S = 1.5
HEALTH_ERROR_CODE = 0x0001
MAX_NODE_DISTANCE_Q2 = 0xFFFF
_CATCH_UP_LIMIT_S = 0.5
# A USB full-speed bulk packet, bytes: the unit a USB-serial adapter's packets swap or repeat in.
USB_PACKET_SIZE = 64
# A replayed frame is one of this many sent before it.
REPLAY_MAX_FRAMES_BACK = 8
# The stream faults, by the name of their rate (the server's commands: ``<name> RATE``).
STREAM_FAULTS = ('corrupt', 'drop', 'cut', 'insert', 'flip', 'replay', 'swap', 'duplicate')


@dataclass(frozen=True)
class DeviceModel:
    """
    What tells one RPLIDAR model from another on the wire, and how its motor is driven.

    :ivar model: the model byte of GET_INFO (major id << 4 | sub-model)
    :ivar firmware: default firmware (major, minor)
    :ivar hardware: hardware revision of GET_INFO
    :ivar baudrate: its serial rate, bits per second
    :ivar modes: scan modes (mode i is ``modes[i]``; the first is Standard)
    :ivar typical_mode: the id of the typical mode
    :ivar motor: how the host drives the motor; None: the device runs it itself while it
        scans and ignores the host (the C1)
    :ivar own_rpm: the speed a motor the host only switches (DTR) or does not drive runs at,
        rpm
    :ivar accessory_board: GET_ACC_BOARD_FLAG is answered (the SDK asks the A2, A3 and C1),
        with bit 0 set when :attr:`motor` is PWM
    """

    model: int
    firmware: tuple
    hardware: int
    baudrate: int
    modes: tuple
    typical_mode: int
    motor: Optional[MotorControl]
    own_rpm: int = DEFAULT_RPM
    accessory_board: bool = False

    def without_accessory_board(self) -> 'DeviceModel':
        """
        Return the model as it is without an accessory board: its motor on the DTR line.

        :return: the bare model (unchanged for a model without one)
        """
        if self.motor != MotorControl.PWM:
            return self
        return replace(self, motor=MotorControl.DTR)


# The emulated models. Model bytes, firmware and hardware revisions are what units report (the
# S3's 1.02 and 18: Slamtec/rplidar_ros#155); the rates are SLAMTEC's SDK's
# (sl_lidar_driver.cpp, _getNativeBaudRate: A-series 115200, 256000 from hardware revision 6;
# C1 460800; S1 256000; S2, S3 1000000) and those of sllidar_ros2's launch files (A1, A2M8
# 115200; A3 256000; C1 460800; S1 256000; S2, S3 1000000). Motors are driven as the SDK's
# checkMotorCtrlSupport and setMotorSpeed drive them: the A1 by the DTR line (running at its
# datasheet's typical 5.5 Hz), the A2 and A3 by PWM through their accessory board (by DTR
# without), the S-series in rpm; the SDK asks the C1 for an accessory board too and, told there
# is none, toggles a DTR line the C1 ignores: it runs its 10 Hz while it scans. Modes: the A1's
# firmware lists Standard 2K, Express 4K and Boost 8K at 12 m (robopeak/rplidar_ros#68); the
# A3's 16 kHz Boost and Sensitivity and 10 kHz Stability at 25 m are its datasheet's; the C1
# samples at 5 kHz out to 12 m; the S2 and S3 at 32 kHz in DenseBoost (30 m and 40 m) and in
# Standard at what a 1 Mbaud line carries in 5-byte nodes (the S3's 16 kHz and 16 m:
# Slamtec/rplidar_ros#150).
_A3_MODES = (ScanMode(0, 'Standard', 500.0, 25.0, AnswerType.MEASUREMENT),
             ScanMode(1, 'Express', 250.0, 25.0, AnswerType.EXPRESS_CAPSULE),
             ScanMode(2, 'Boost', 62.5, 25.0, AnswerType.ULTRA_CAPSULE),
             ScanMode(3, 'Sensitivity', 62.5, 25.0, AnswerType.ULTRA_CAPSULE),
             ScanMode(4, 'Stability', 100.0, 25.0, AnswerType.ULTRA_CAPSULE))
_C1_MODES = (ScanMode(0, 'Standard', 200.0, 12.0, AnswerType.MEASUREMENT),
             ScanMode(1, 'DenseBoost', 200.0, 12.0, AnswerType.DENSE_CAPSULE))
_S2_MODES = (ScanMode(0, 'Standard', 100.0, 30.0, AnswerType.MEASUREMENT),
             ScanMode(1, 'DenseBoost', 31.25, 30.0, AnswerType.DENSE_CAPSULE))
_S3_MODES = (ScanMode(0, 'Standard', 62.5, 16.0, AnswerType.MEASUREMENT),
             ScanMode(1, 'DenseBoost', 31.25, 40.0, AnswerType.DENSE_CAPSULE))
EMULATED_MODELS = {
    'a1': DeviceModel(0x18, (1, 29), 5, 115200, A_SERIES_MODES[:3], 2, MotorControl.DTR,
                      own_rpm=330),
    'a2': DeviceModel(0x28, (1, 27), 5, 115200, A_SERIES_MODES, 3, MotorControl.PWM,
                      accessory_board=True),
    'a3': DeviceModel(0x31, (1, 29), 6, 256000, _A3_MODES, 3, MotorControl.PWM,
                      accessory_board=True),
    'c1': DeviceModel(0x41, (1, 2), 18, 460800, _C1_MODES, 0, None, accessory_board=True),
    's1': DeviceModel(MODEL_S1M1, (1, 28), 18, 256000, MODES, TYPICAL_MODE, MotorControl.RPM),
    's2': DeviceModel(0x71, (1, 2), 18, 1000000, _S2_MODES, 1, MotorControl.RPM),
    's3': DeviceModel(0x81, (1, 2), 18, 1000000, _S3_MODES, 1, MotorControl.RPM),
}
# The PWM an accessory board runs the motor at 10 Hz with (the desired rotation's PWM
# reference the device reports; the 1.x SDK's default PWM).
PWM_AT_DEFAULT_RPM = 660


def device_model(model) -> DeviceModel:
    """
    Return an emulated model, or the one of a model byte's family with that byte.

    :param model: a :class:`DeviceModel`, or a model byte (the S1's family when unknown)
    :return: the model
    """
    if isinstance(model, DeviceModel):
        return model
    family = next((m for m in EMULATED_MODELS.values() if m.model >> 4 == model >> 4),
                  EMULATED_MODELS['s1'])
    return replace(family, model=model)


# The GET_LIDAR_CONF entries whose reported value a fault can replace, by name.
CONF_ENTRIES = {'mode_count': ConfType.MODE_COUNT, 'typical_mode': ConfType.TYPICAL_MODE,
                'us_per_sample': ConfType.US_PER_SAMPLE, 'max_distance': ConfType.MAX_DISTANCE,
                'answer_type': ConfType.ANSWER_TYPE}


def parse_conf_answer(text: str) -> tuple:
    """
    Parse a replaced GET_LIDAR_CONF answer, ``ENTRY=VALUE``.

    :param text: e.g. ``max_distance=0`` (metres), ``us_per_sample=none`` (the entry answered
        with its type echo alone, as an unknown one), ``mode_count=real`` (the device's own)
    :return: ``(conf_type, value)``; value None for ``none``, the string ``'real'`` for ``real``
    :raises ValueError: on an unknown entry or a value that does not fit the entry's field
    """
    name, equals, value = text.partition('=')
    if not equals or name not in CONF_ENTRIES:
        raise ValueError(f'expected ENTRY=VALUE with ENTRY one of {", ".join(CONF_ENTRIES)}, '
                         f'got {text!r}')
    conf_type = CONF_ENTRIES[name]
    if value in ('none', 'real'):
        return conf_type, None if value == 'none' else value
    number = float(value)
    if conf_type not in (ConfType.US_PER_SAMPLE, ConfType.MAX_DISTANCE):
        number = int(number)
    try:
        encode_conf_value(conf_type, number)
    except struct.error:
        raise ValueError(f'{value} does not fit the {name} field') from None
    return conf_type, number


class Scene(Protocol):
    """What the device sees: anything with this method (the CLI's is a simulated floor plan)."""

    def distances_mm(self, raw_angle_deg: np.ndarray, fresh_noise: bool = True) -> np.ndarray:
        """
        Return the measured distance at each raw clockwise angle.

        :param raw_angle_deg: device angles, degrees clockwise from the front
        :param fresh_noise: False: the same noise draws as the previous call (as many angles),
            for a sample whose angle depends on the distance it measures
        :return: distances, mm (float); 0 where nothing returns
        """


@dataclass
class Faults:
    """
    Fault injection settings (mutable: stdin commands change them).

    :ivar corrupt_rate: probability that a streamed byte is replaced by another value
    :ivar drop_rate: probability that a streamed byte is left out
    :ivar cut_rate: probability that a streamed frame is cut short: its bytes from a random one
        (uniform over the frame) to its end are lost
    :ivar insert_rate: probability that a random byte is inserted after a streamed byte
    :ivar flip_rate: probability that a streamed frame has one bit flipped in two of its bytes
        after the first two (the same bit: the XOR checksum of a capsule still passes)
    :ivar replay_rate: probability that a streamed frame is followed by a copy of one of the
        :data:`REPLAY_MAX_FRAMES_BACK` frames before it
    :ivar swap_rate: probability that a :data:`USB_PACKET_SIZE`-byte packet of the stream is
        swapped with the next one
    :ivar duplicate_rate: probability that a packet of the stream is delivered twice
    :ivar silent_from_s: monotonic time from which the device neither answers nor streams
    :ivar silent_until_s: monotonic time at which it speaks again
    :ivar health: :class:`HealthStatus` reported by GET_HEALTH
    :ivar resets_to_clear: RESETs still needed before an error health clears
    :ivar conf_answers: GET_LIDAR_CONF values reported instead of the device's own, by
        :class:`ConfType` (for every mode); None: the type echo alone
    :ivar answer_type: the answer type every answer's descriptor carries instead of its own
        (None: its own), as a device of another protocol generation answers
    """

    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    cut_rate: float = 0.0
    insert_rate: float = 0.0
    flip_rate: float = 0.0
    replay_rate: float = 0.0
    swap_rate: float = 0.0
    duplicate_rate: float = 0.0
    silent_from_s: float = 0.0
    silent_until_s: float = 0.0
    health: int = HealthStatus.OK
    resets_to_clear: int = 1
    conf_answers: dict = field(default_factory=dict)
    answer_type: Optional[int] = None

    def replace_conf_answer(self, text: str):
        """
        Report a GET_LIDAR_CONF entry's value instead of the device's own (or the own again).

        :param text: ``ENTRY=VALUE`` (see :func:`parse_conf_answer`)
        :raises ValueError: on an unknown entry or a value that does not fit
        """
        conf_type, value = parse_conf_answer(text)
        if value == 'real':
            self.conf_answers.pop(conf_type, None)
        else:
            self.conf_answers[conf_type] = value

    def silent(self, now_s: float) -> bool:
        """
        Tell whether the device is silent.

        :param now_s: monotonic time, s
        :return: True while neither answering nor streaming
        """
        return self.silent_from_s <= now_s < self.silent_until_s


@dataclass(frozen=True)
class StreamClock:
    """
    When and where the device measures the samples of the stream it is sending.

    Sample n (counted from the stream's first) is measured until ``start_s + (n + 1) *
    sample_s`` at raw angle ``first_angle_deg + n * step_deg`` (modulo 360).

    :ivar start_s: monotonic time at which the stream started, s
    :ivar sample_s: time per sample, s
    :ivar first_angle_deg: raw angle of the first sample, degrees
    :ivar step_deg: angle between consecutive samples, degrees
    """

    start_s: float
    sample_s: float
    first_angle_deg: float
    step_deg: float


class S1Device:
    """
    One emulated RPLIDAR behind one link: answers requests and produces the scan stream.

    Its motor runs only as its model's own control says (:class:`DeviceModel`): while the DTR
    line is cleared (DTR models; a pseudo-terminal carries no modem lines, so there it stays
    cleared unless :meth:`set_dtr` is called), at a SET_MOTOR_PWM duty (PWM models, off until
    the first), from the start of a scan at the MOTOR_SPEED rpm until MOTOR_SPEED 0 (rpm
    models: STOP ends the stream, not the motor) or while scanning (the C1). It streams only
    while the motor runs. :attr:`motor_rpm` is its speed now.

    :param scene: what the device sees
    :param faults: shared fault settings
    :param firmware: (major, minor)
    :param rng: random generator (rotation phase, faults)
    :param modes: its scan modes (mode i is ``modes[i]``; the first is Standard)
    :param typical_mode: the id of its typical mode
    :param model: its :class:`DeviceModel`, or a model byte (its family's model)
    """

    def __init__(self, scene: Scene, faults: Faults, firmware: tuple, rng: np.random.Generator,
                 modes: tuple = MODES, typical_mode: int = TYPICAL_MODE,
                 model=MODEL_S1M1):
        self._profile = device_model(model)
        self._model = self._profile.model
        self._modes = modes
        self._typical_mode = typical_mode
        self._scene = scene
        self._faults = faults
        self._firmware = firmware
        self._rng = rng
        self._parser = RequestParser()
        self._rpm = DEFAULT_RPM
        self._pwm = 0
        self._dtr_asserted = False
        self._rpm_motor_on = False
        self._mode: Optional[ScanMode] = None
        self._booting_until_s = 0.0
        self._phase_q6 = int(rng.integers(FULL_TURN_Q6))
        self._running_rpm = 0

    @property
    def motor_rpm(self) -> int:
        """Return the motor's speed now, rpm (0: stopped)."""
        return self._running_rpm

    @property
    def scanning(self) -> bool:
        """Tell whether a scan was started and not stopped (streaming while the motor runs)."""
        return self._mode is not None

    def _motor_speed_rpm(self) -> int:
        """Return the speed the motor control asks for now, rpm."""
        motor = self._profile.motor
        if motor == MotorControl.DTR:
            return 0 if self._dtr_asserted else self._profile.own_rpm
        if motor == MotorControl.PWM:
            return round(DEFAULT_RPM * self._pwm / PWM_AT_DEFAULT_RPM)
        if motor == MotorControl.RPM:
            return self._rpm if self._rpm_motor_on else 0
        return self._profile.own_rpm if self._mode is not None else 0

    def _motor_changed(self, now_s: float):
        """Follow a change of the motor control: a running stream goes on at the new speed."""
        rpm = self._motor_speed_rpm()
        if rpm == self._running_rpm:
            return
        if self._mode is not None:
            self._rebase(now_s, rpm)
        self._running_rpm = rpm

    def set_dtr(self, asserted: bool, now_s: float):
        """
        Set the DTR line as the host's serial port drives it.

        :param asserted: True when the host sets DTR (the SDK's motor off), False when it
            clears it (motor on)
        :param now_s: monotonic time, s
        """
        self._dtr_asserted = asserted
        self._motor_changed(now_s)

    def receive(self, data: bytes, now_s: float) -> bytes:
        """
        Take received bytes; return the answers to the requests they complete.

        :param data: bytes from the host
        :param now_s: monotonic time, s
        :return: answer bytes (may be empty)
        """
        answers = b''
        for request in self._parser.feed(data):
            if now_s < self._booting_until_s or self._faults.silent(now_s):
                continue
            answer = self._answer(request.command, request.payload, now_s)
            if answer and self._faults.answer_type is not None:
                # The descriptor's last byte is its answer type.
                answer = answer[:6] + bytes([self._faults.answer_type]) + answer[7:]
            answers += answer
            self._motor_changed(now_s)
        return answers

    def _answer(self, command: int, payload: bytes, now_s: float) -> bytes:
        """Return the answer to one request (and change state)."""
        if command == Command.STOP:
            self._stop()
        elif command == Command.RESET:
            self._stop()
            self._rpm_motor_on = False
            self._pwm = 0
            self._booting_until_s = now_s + RESET_SILENCE_S
            self._faults.resets_to_clear -= 1
            if self._faults.resets_to_clear <= 0 and self._faults.health == HealthStatus.ERROR:
                self._faults.health = HealthStatus.OK
        elif command == Command.MOTOR_SPEED and len(payload) == 2:
            if self._profile.motor == MotorControl.RPM:
                self._rpm = int.from_bytes(payload, 'little')
                self._rpm_motor_on = self._rpm > 0
                if self._rpm == 0:
                    self._stop()
        elif command == Command.SET_MOTOR_PWM and len(payload) == 2:
            if self._profile.motor == MotorControl.PWM:
                self._pwm = int.from_bytes(payload, 'little')
        elif self._mode is not None:
            return b''      # busy streaming: only STOP, RESET and the motor commands are heard
        elif command in (Command.SCAN, Command.FORCE_SCAN):
            return self._start(self._modes[0], now_s)
        elif command == Command.EXPRESS_SCAN and payload and payload[0] < len(self._modes):
            return self._start(self._modes[payload[0]], now_s)
        elif command == Command.GET_INFO:
            return encode_answer(AnswerType.DEVICE_INFO, DeviceInfo(
                self._model, self._firmware[1], self._firmware[0], self._profile.hardware,
                SERIAL_NUMBER).encode())
        elif command == Command.GET_HEALTH:
            code = 0 if self._faults.health == HealthStatus.OK else HEALTH_ERROR_CODE
            return encode_answer(AnswerType.DEVICE_HEALTH,
                                 DeviceHealth(self._faults.health, code).encode())
        elif command == Command.GET_SAMPLERATE:
            return encode_answer(AnswerType.SAMPLE_RATE, SampleRate(
                int(self._modes[0].us_per_sample),
                int(self._modes[min(1, len(self._modes) - 1)].us_per_sample)).encode())
        elif command == Command.GET_ACC_BOARD_FLAG and self._profile.accessory_board:
            return encode_answer(AnswerType.ACC_BOARD_FLAG, AccBoardFlag(
                int(self._profile.motor == MotorControl.PWM)).encode())
        elif command == Command.GET_LIDAR_CONF and self._supports_conf():
            return self._conf_answer(payload)
        return b''

    def _supports_conf(self) -> bool:
        """Tell whether GET_LIDAR_CONF is answered (as the SDK expects it)."""
        return DeviceInfo(self._model, self._firmware[1], self._firmware[0],
                          self._profile.hardware, SERIAL_NUMBER).supports_conf

    def _conf_answer(self, payload: bytes) -> bytes:
        """Answer GET_LIDAR_CONF (unknown entries: the type echo alone)."""
        try:
            conf_type, mode_id = decode_conf_request(payload)
        except ProtocolError:
            return b''
        if conf_type in MODE_CONF_TYPES:
            if mode_id is None or mode_id >= len(self._modes):
                return encode_answer(AnswerType.LIDAR_CONF, encode_conf_value(conf_type, None))
            mode = self._modes[mode_id]
            value = {ConfType.US_PER_SAMPLE: mode.us_per_sample,
                     ConfType.MAX_DISTANCE: mode.max_distance_m,
                     ConfType.ANSWER_TYPE: mode.answer_type,
                     ConfType.MODE_NAME: mode.name}[conf_type]
        else:
            value = {ConfType.MODE_COUNT: len(self._modes),
                     ConfType.TYPICAL_MODE: self._typical_mode,
                     ConfType.DESIRED_ROTATION: (
                         DEFAULT_RPM, PWM_AT_DEFAULT_RPM
                         if self._profile.motor == MotorControl.PWM else 0)}.get(conf_type)
        value = self._faults.conf_answers.get(conf_type, value)
        return encode_answer(AnswerType.LIDAR_CONF, encode_conf_value(conf_type, value))

    def _start(self, mode: ScanMode, now_s: float) -> bytes:
        """Start streaming a mode; return its descriptor."""
        self._mode = mode
        if self._profile.motor == MotorControl.RPM:
            # An S-series device spins up when a scan starts, at the last speed asked for.
            self._rpm = self._rpm or DEFAULT_RPM
            self._rpm_motor_on = True
        self._sent = self._step_q6 = 0
        self._samples_per_frame, self._frame_size = _FRAMES[mode.answer_type]
        self._frame_s = self._samples_per_frame * mode.us_per_sample * 1e-6
        self._running_rpm = self._motor_speed_rpm()
        self._rebase(now_s, self._running_rpm)
        self._previous_angle_q6 = None
        self._next_ultra_mm = None          # the next ultra capsule's first distance, decided
        return ResponseDescriptor(self._frame_size, SendMode.MULTIPLE, mode.answer_type).encode()

    def _rebase(self, now_s: float, rpm: int):
        """Restart the stream's clock at ``now_s``, turning at ``rpm`` (0: nothing streams)."""
        self._phase_q6 = int((self._phase_q6 + self._sent * self._step_q6) % FULL_TURN_Q6)
        self._start_s = now_s
        self._sent = 0
        # Whole 1/64 degrees per frame keep every sample on one exact, uniform angle grid.
        self._step_q6 = round(rpm / 60.0 * FULL_TURN_Q6 * self._frame_s)

    def _stop(self):
        if self._mode is not None:
            self._rebase(0.0, 0)        # keeps the angle reached for the next stream
        self._mode = None

    def clock(self) -> Optional[StreamClock]:
        """
        Return the sample clock of the stream being sent (the truth for timing tests).

        :return: the clock, or None when not streaming
        """
        if self._mode is None or not self._running_rpm:
            return None
        samples = self._samples_per_frame
        return StreamClock(self._start_s, self._frame_s / samples, self._phase_q6 / 64.0,
                           self._step_q6 / samples / 64.0)

    def next_frame_in(self, now_s: float) -> float:
        """
        Return how long until the next frame is due.

        :param now_s: monotonic time, s
        :return: seconds (inf when not streaming)
        """
        if self._mode is None or not self._running_rpm:
            return math.inf
        return max(self._due_s(self._sent) - now_s, 0.0)

    def _due_s(self, frame: int) -> float:
        """When frame ``frame``'s last byte arrives at the host."""
        return (self._start_s + (frame + 1) * self._frame_s
                + self._frame_size * 10.0 / self._profile.baudrate)

    def stream(self, now_s: float) -> bytes:
        """
        Return the stream bytes due by ``now_s`` (with faults applied).

        :param now_s: monotonic time, s
        :return: bytes to send
        """
        if self._mode is None or not self._running_rpm:
            return b''
        due = int((now_s - self._due_s(0)) // self._frame_s) + 1
        first = max(self._sent, due - int(_CATCH_UP_LIMIT_S / self._frame_s))
        if due <= first:
            return b''
        frames = np.arange(first, due)
        self._sent = due
        if self._faults.silent(now_s):
            return b''
        start_q6 = (self._phase_q6 + frames * self._step_q6) % FULL_TURN_Q6
        if self._mode.answer_type == AnswerType.DENSE_CAPSULE:
            data = self._capsules(frames, start_q6)
        elif self._mode.answer_type == AnswerType.EXPRESS_CAPSULE:
            data = self._express_capsules(frames, start_q6)
        elif self._mode.answer_type == AnswerType.ULTRA_CAPSULE:
            data = self._ultra_capsules(frames, start_q6)
        elif self._mode.answer_type == AnswerType.ULTRA_DENSE_CAPSULE:
            data = self._ultra_dense_capsules(frames, start_q6)
        elif self._mode.answer_type == AnswerType.HQ_CAPSULE:
            data = self._hq_capsules(frames, start_q6)
        else:
            data = self._nodes(start_q6)
        return self._inject_faults(data)

    def _capsules(self, frames: np.ndarray, start_q6: np.ndarray) -> bytes:
        """Encode dense capsules: sample k of capsule i at start_i + k * step / 40."""
        offsets = np.arange(SAMPLES_PER_CAPSULE) / SAMPLES_PER_CAPSULE
        angles = (start_q6[:, None] + self._step_q6 * offsets) / 64.0 % 360.0
        distances = np.rint(self._scene.distances_mm(angles.reshape(-1)))
        distances[distances > 0xFFFF] = 0
        return encode_dense_capsules(start_q6, distances.reshape(angles.shape),
                                     frames == 0)

    def _ultra_dense_capsules(self, frames: np.ndarray, start_q6: np.ndarray) -> bytes:
        """
        Encode ultra-dense capsules: sample k of capsule i at start_i + k * step / 64.

        A capsule's timestamp is when its first sample was measured, in microseconds of the
        monotonic clock, the emulated device's own.
        """
        offsets = np.arange(ULTRA_DENSE_SAMPLES_PER_CAPSULE) / ULTRA_DENSE_SAMPLES_PER_CAPSULE
        angles = (start_q6[:, None] + self._step_q6 * offsets) / 64.0 % 360.0
        distances = self._scene.distances_mm(angles.reshape(-1)).reshape(angles.shape)
        distances[distances > ULTRA_DENSE_MAX_DISTANCE_MM] = 0
        quality = np.where(distances > 0, ULTRA_DENSE_RETURN_QUALITY, 0)
        sample_s = self._frame_s / ULTRA_DENSE_SAMPLES_PER_CAPSULE
        time_us = np.rint((self._start_s + frames * self._frame_s + sample_s) * 1e6)
        return encode_ultra_dense_capsules(start_q6, distances, quality, frames == 0,
                                           time_us.astype(np.int64))

    def _hq_capsules(self, frames: np.ndarray, start_q6: np.ndarray) -> bytes:
        """Encode HQ capsules: sample k of capsule i at start_i + k * step / 96, stamped."""
        offsets = np.arange(HQ_SAMPLES_PER_CAPSULE) / HQ_SAMPLES_PER_CAPSULE
        angle_q6 = (start_q6[:, None] + self._step_q6 * offsets).reshape(-1) % FULL_TURN_Q6
        previous = np.concatenate([[angle_q6[0] if self._previous_angle_q6 is None
                                    else self._previous_angle_q6], angle_q6[:-1]])
        self._previous_angle_q6 = angle_q6[-1]
        distances = np.rint(self._scene.distances_mm(angle_q6 / 64.0) * 4.0) / 4.0
        shape = (len(frames), HQ_SAMPLES_PER_CAPSULE)
        time_us = np.rint((self._start_s + frames * self._frame_s) * 1e6).astype(np.int64)
        return encode_hq_capsules((angle_q6 / 64.0).reshape(shape), distances.reshape(shape),
                                  np.where(distances > 0, 47 << 2, 0).reshape(shape),
                                  (angle_q6 < previous).reshape(shape), time_us)

    def _express_capsules(self, frames: np.ndarray, start_q6: np.ndarray) -> bytes:
        """Encode express capsules: sample k of capsule i at start_i + k * step / 32 - dk."""
        offsets = np.arange(EXPRESS_SAMPLES_PER_CAPSULE) / EXPRESS_SAMPLES_PER_CAPSULE
        uniform = (start_q6[:, None] + self._step_q6 * offsets) / 64.0
        ahead = np.maximum(self._scene.distances_mm(uniform.reshape(-1) % 360.0), 1.0)
        correction_q3 = np.minimum(np.rint(8.0 * np.degrees(np.arctan(
            TRIANGULATION_BASELINE_MM / ahead))), EXPRESS_MAX_CORRECTION_Q3).reshape(uniform.shape)
        angles = (uniform - correction_q3 / 8.0) % 360.0
        distances = np.rint(self._scene.distances_mm(angles.reshape(-1)))
        distances[distances > EXPRESS_MAX_DISTANCE_MM] = 0
        return encode_express_capsules(start_q6, distances.reshape(angles.shape), correction_q3,
                                       frames == 0)

    def _ultra_capsules(self, frames: np.ndarray, start_q6: np.ndarray) -> bytes:
        """Encode ultra capsules: sample k of capsule i at start_i + k * step / 96 - offset."""
        offsets = np.arange(ULTRA_SAMPLES_PER_CAPSULE) / ULTRA_SAMPLES_PER_CAPSULE
        # The capsules' samples and the next capsule's first, whose major the last cabin needs.
        uniform = np.append((start_q6[:, None] + self._step_q6 * offsets).reshape(-1),
                            start_q6[-1] + self._step_q6) / 64.0
        sent = np.zeros(uniform.size)
        # One noise draw per sample: each pass and the check below measure it again at the
        # angle its distance moves it to (with fresh noise no sample would ever settle).
        for attempt in range(_ULTRA_PASSES):
            distances = np.rint(self._scene.distances_mm((uniform - offset_deg(sent)) % 360.0,
                                                         fresh_noise=attempt == 0))
            distances[distances > ULTRA_MAX_DISTANCE_MM] = 0
            if self._next_ultra_mm is not None:
                distances[0] = self._next_ultra_mm
            data, sent = self._encode_ultra(start_q6, frames == 0, distances)
        # Where the offset of the distance sent keeps moving the sample (an edge, or a distance
        # where the offset steps), the scene there may not show that distance: then the sample
        # is sent as no return.
        seen = self._scene.distances_mm((uniform - offset_deg(sent)) % 360.0, fresh_noise=False)
        step = 1 << varbitscale_decode(varbitscale_encode(sent))[1]
        astray = (sent > 0) & (np.abs(seen - sent) > step / 2 + 1)
        astray[0] &= self._next_ultra_mm is None
        distances[astray] = 0
        data, _ = self._encode_ultra(start_q6, frames == 0, distances)
        self._next_ultra_mm = distances[-1]
        return data

    @staticmethod
    def _encode_ultra(start_q6: np.ndarray, start_flag: np.ndarray, distances: np.ndarray):
        """Encode capsules and the next one's first distance; return bytes, distances sent."""
        data, sent = encode_ultra_capsules(
            start_q6, distances[:-1].reshape(len(start_q6), ULTRA_SAMPLES_PER_CAPSULE),
            start_flag, distances[-1])
        return data, np.append(sent.reshape(-1),
                               varbitscale_decode(varbitscale_encode(distances[-1]))[0])

    def _nodes(self, angle_q6: np.ndarray) -> bytes:
        """Encode standard nodes, S set on the first node of each turn."""
        previous = np.concatenate([[angle_q6[0] if self._previous_angle_q6 is None
                                    else self._previous_angle_q6], angle_q6[:-1]])
        self._previous_angle_q6 = angle_q6[-1]
        distance_q2 = np.rint(self._scene.distances_mm(angle_q6 / 64.0) * 4.0)
        distance_q2[distance_q2 > MAX_NODE_DISTANCE_Q2] = 0
        quality = np.where(distance_q2 > 0, 47, 0)
        return encode_standard_nodes(angle_q6, distance_q2, quality, angle_q6 < previous)

    def _inject_faults(self, data: bytes) -> bytes:
        """Apply the stream faults at their configured rates (``data``: whole frames)."""
        faults = self._faults
        if not any(getattr(faults, f'{name}_rate') for name in STREAM_FAULTS):
            return data
        raw = np.frombuffer(data, np.uint8).copy()
        if faults.flip_rate or faults.replay_rate:
            raw = self._damage_frames(raw.reshape(-1, self._frame_size)).reshape(-1)
        corrupt = self._rng.random(raw.size) < faults.corrupt_rate
        raw[corrupt] ^= self._rng.integers(1, 256, int(corrupt.sum()), dtype=np.uint8)
        kept = self._rng.random(raw.size) >= faults.drop_rate
        if faults.cut_rate:
            # A cut frame keeps 0 to size - 1 of its first bytes.
            frames = raw.size // self._frame_size
            cut = self._rng.random(frames) < faults.cut_rate
            first_lost = np.where(cut, self._rng.integers(0, self._frame_size, frames),
                                  self._frame_size)
            kept &= (np.arange(self._frame_size) < first_lost[:, None]).reshape(-1)
        raw = raw[kept]
        if faults.insert_rate:
            inserted = np.flatnonzero(self._rng.random(raw.size) < faults.insert_rate) + 1
            raw = np.insert(raw, inserted, self._rng.integers(0, 256, inserted.size,
                                                              dtype=np.uint8))
        if faults.swap_rate or faults.duplicate_rate:
            raw = self._damage_packets(raw)
        return raw.tobytes()

    def _damage_frames(self, frames: np.ndarray) -> np.ndarray:
        """
        Flip one bit in two bytes of frames and follow frames by replays, at their rates.

        :param frames: the frames to send, shape (n, frame size), uint8
        :return: the frames sent, shape (m, frame size)
        """
        faults, count, size = self._faults, len(frames), frames.shape[1]
        if faults.flip_rate:
            flipped = np.flatnonzero(self._rng.random(count) < faults.flip_rate)
            bits = (1 << self._rng.integers(0, 8, flipped.size)).astype(np.uint8)
            for frame, bit in zip(flipped, bits):
                first, second = self._rng.choice(np.arange(2, size), 2, replace=False)
                frames[frame, first] ^= bit
                frames[frame, second] ^= bit
        if not faults.replay_rate:
            return frames
        replayed = np.flatnonzero(self._rng.random(count) < faults.replay_rate)
        back = self._rng.integers(1, REPLAY_MAX_FRAMES_BACK + 1, replayed.size)
        copies = frames[np.maximum(replayed - back, 0)]
        return np.insert(frames, replayed + 1, copies, axis=0)

    def _damage_packets(self, raw: np.ndarray) -> np.ndarray:
        """
        Swap and duplicate the stream's USB packets at their rates.

        :param raw: the stream bytes
        :return: the bytes delivered
        """
        faults = self._faults
        packets = [raw[i:i + USB_PACKET_SIZE] for i in range(0, raw.size, USB_PACKET_SIZE)]
        swapped = self._rng.random(len(packets)) < faults.swap_rate
        for i in np.flatnonzero(swapped[:-1]):
            packets[i], packets[i + 1] = packets[i + 1], packets[i]
        twice = self._rng.random(len(packets)) < faults.duplicate_rate
        delivered = [p for packet, double in zip(packets, twice)
                     for p in ((packet, packet) if double else (packet,))]
        return np.concatenate(delivered) if delivered else raw
