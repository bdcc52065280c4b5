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

:class:`Faults` (shared with the server's control commands) corrupts or drops streamed bytes, cuts
frames short (a run of bytes lost, as when a USB packet or a burst of the UART's input is lost),
silences the device, sets the health it reports and replaces the values of GET_LIDAR_CONF
entries it reports (:func:`parse_conf_answer`).
"""

from dataclasses import dataclass, field
import math
import struct
from typing import Optional, Protocol

import numpy as np

from ..express import (encode_express_capsules, EXPRESS_CAPSULE_SIZE,
                       EXPRESS_MAX_CORRECTION_Q3, EXPRESS_MAX_DISTANCE_MM,
                       EXPRESS_SAMPLES_PER_CAPSULE)
from ..protocol import (AnswerType, CAPSULE_SIZE, Command, CONF_COMMANDS_FIRMWARE, ConfType,
                        decode_conf_request, DeviceHealth, DeviceInfo, encode_answer,
                        encode_conf_value, encode_dense_capsules, encode_standard_nodes,
                        FULL_TURN_Q6, HealthStatus, MODE_CONF_TYPES, NODE_SIZE, ProtocolError,
                        RequestParser, ResponseDescriptor, SampleRate, SAMPLES_PER_CAPSULE,
                        ScanMode, SendMode)
from ..ultra import (encode_ultra_capsules, offset_deg, ULTRA_CAPSULE_SIZE, ULTRA_MAX_DISTANCE_MM,
                     ULTRA_SAMPLES_PER_CAPSULE, varbitscale_decode, varbitscale_encode)

MODES = (ScanMode(0, 'Standard', 244.0, 40.0, AnswerType.MEASUREMENT),
         ScanMode(1, 'DenseBoost', 108.0, 40.0, AnswerType.DENSE_CAPSULE))
TYPICAL_MODE = 1
# An A-series device's modes (the S1's have no express or ultra capsules): Standard, Express
# (0x82) and Boost (0x84).
A_SERIES_MODES = (ScanMode(0, 'Standard', 500.0, 12.0, AnswerType.MEASUREMENT),
                  ScanMode(1, 'Express', 250.0, 12.0, AnswerType.EXPRESS_CAPSULE),
                  ScanMode(2, 'Boost', 125.0, 12.0, AnswerType.ULTRA_CAPSULE))
# Passes measuring each ultra capsule sample where the offset of the distance it sends puts it.
_ULTRA_PASSES = 3
# A triangulating device's laser sits beside its lens: the angle it measures at lies
# atan(baseline / distance) before where the capsule's angles place a sample.
TRIANGULATION_BASELINE_MM = 20.0
# Per answer type of a scan mode: samples per frame and frame size, bytes.
_FRAMES = {AnswerType.MEASUREMENT: (1, NODE_SIZE),
           AnswerType.EXPRESS_CAPSULE: (EXPRESS_SAMPLES_PER_CAPSULE, EXPRESS_CAPSULE_SIZE),
           AnswerType.ULTRA_CAPSULE: (ULTRA_SAMPLES_PER_CAPSULE, ULTRA_CAPSULE_SIZE),
           AnswerType.DENSE_CAPSULE: (SAMPLES_PER_CAPSULE, CAPSULE_SIZE)}
MODEL_S1M1 = 0x61
# The models the emulator can report, by name: their model byte (major id << 4 | sub-model,
# see the protocol's MODEL_FAMILIES) and scan modes with the typical one's id: an A-series
# device's modes for the A-series (typical Express), the S1's for the dTOF C1 and S-series.
EMULATED_MODELS = {'a1': (0x18, A_SERIES_MODES, 1), 'a2': (0x28, A_SERIES_MODES, 1),
                   'a3': (0x31, A_SERIES_MODES, 1), 'c1': (0x41, MODES, TYPICAL_MODE),
                   's1': (MODEL_S1M1, MODES, TYPICAL_MODE), 's2': (0x71, MODES, TYPICAL_MODE),
                   's3': (0x81, MODES, TYPICAL_MODE)}
HARDWARE = 18
SERIAL_NUMBER = b'WCTLS-S1-EMULATR'
DEFAULT_RPM = 600
SERIAL_BAUD = 256000
RESET_SILENCE_S = 1.5
HEALTH_ERROR_CODE = 0x0001
MAX_NODE_DISTANCE_Q2 = 0xFFFF
_CATCH_UP_LIMIT_S = 0.5
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

    def distances_mm(self, raw_angle_deg: np.ndarray) -> np.ndarray:
        """
        Return the measured distance at each raw clockwise angle.

        :param raw_angle_deg: device angles, degrees clockwise from the front
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
    :ivar silent_from_s: monotonic time from which the device neither answers nor streams
    :ivar silent_until_s: monotonic time at which it speaks again
    :ivar health: :class:`HealthStatus` reported by GET_HEALTH
    :ivar resets_to_clear: RESETs still needed before an error health clears
    :ivar conf_answers: GET_LIDAR_CONF values reported instead of the device's own, by
        :class:`ConfType` (for every mode); None: the type echo alone
    """

    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    cut_rate: float = 0.0
    silent_from_s: float = 0.0
    silent_until_s: float = 0.0
    health: int = HealthStatus.OK
    resets_to_clear: int = 1
    conf_answers: dict = field(default_factory=dict)

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
    One emulated S1 behind one link: answers requests and produces the scan stream.

    :param scene: what the device sees
    :param faults: shared fault settings
    :param firmware: (major, minor)
    :param rng: random generator (rotation phase, faults)
    :param modes: its scan modes (mode i is ``modes[i]``; the first is Standard): the S1's, or
        e.g. :data:`A_SERIES_MODES`
    :param typical_mode: the id of its typical mode
    :param model: the model byte GET_INFO reports (the S1M1's by default)
    """

    def __init__(self, scene: Scene, faults: Faults, firmware: tuple, rng: np.random.Generator,
                 modes: tuple = MODES, typical_mode: int = TYPICAL_MODE,
                 model: int = MODEL_S1M1):
        self._model = model
        self._modes = modes
        self._typical_mode = typical_mode
        self._scene = scene
        self._faults = faults
        self._firmware = firmware
        self._rng = rng
        self._parser = RequestParser()
        self._rpm = DEFAULT_RPM
        self._mode: Optional[ScanMode] = None
        self._booting_until_s = 0.0
        self._phase_q6 = int(rng.integers(FULL_TURN_Q6))

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
            answers += self._answer(request.command, request.payload, now_s)
        return answers

    def _answer(self, command: int, payload: bytes, now_s: float) -> bytes:
        """Return the answer to one request (and change state)."""
        if command == Command.STOP:
            self._stop()
        elif command == Command.RESET:
            self._stop()
            self._booting_until_s = now_s + RESET_SILENCE_S
            self._faults.resets_to_clear -= 1
            if self._faults.resets_to_clear <= 0 and self._faults.health == HealthStatus.ERROR:
                self._faults.health = HealthStatus.OK
        elif command == Command.MOTOR_SPEED and len(payload) == 2:
            self._rpm = int.from_bytes(payload, 'little')
            if self._rpm == 0:
                self._stop()
        elif self._mode is not None:
            return b''      # busy streaming: only STOP, RESET and MOTOR_SPEED are heard
        elif command in (Command.SCAN, Command.FORCE_SCAN):
            return self._start(self._modes[0], now_s)
        elif command == Command.EXPRESS_SCAN and payload and payload[0] < len(self._modes):
            return self._start(self._modes[payload[0]], now_s)
        elif command == Command.GET_INFO:
            return encode_answer(AnswerType.DEVICE_INFO, DeviceInfo(
                self._model, self._firmware[1], self._firmware[0], HARDWARE,
                SERIAL_NUMBER).encode())
        elif command == Command.GET_HEALTH:
            code = 0 if self._faults.health == HealthStatus.OK else HEALTH_ERROR_CODE
            return encode_answer(AnswerType.DEVICE_HEALTH,
                                 DeviceHealth(self._faults.health, code).encode())
        elif command == Command.GET_SAMPLERATE:
            return encode_answer(AnswerType.SAMPLE_RATE, SampleRate(
                int(self._modes[0].us_per_sample),
                int(self._modes[min(1, len(self._modes) - 1)].us_per_sample)).encode())
        elif command == Command.GET_LIDAR_CONF and self._firmware >= CONF_COMMANDS_FIRMWARE:
            return self._conf_answer(payload)
        return b''

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
                     ConfType.DESIRED_ROTATION: (DEFAULT_RPM, 0)}.get(conf_type)
        value = self._faults.conf_answers.get(conf_type, value)
        return encode_answer(AnswerType.LIDAR_CONF, encode_conf_value(conf_type, value))

    def _start(self, mode: ScanMode, now_s: float) -> bytes:
        """Start streaming a mode; return its descriptor."""
        self._mode = mode
        self._start_s = now_s
        self._sent = 0
        self._samples_per_frame, self._frame_size = _FRAMES[mode.answer_type]
        self._frame_s = self._samples_per_frame * mode.us_per_sample * 1e-6
        rpm = self._rpm or DEFAULT_RPM
        # Whole 1/64 degrees per frame keep every sample on one exact, uniform angle grid.
        self._step_q6 = round(rpm / 60.0 * FULL_TURN_Q6 * self._frame_s)
        self._previous_angle_q6 = None
        self._next_ultra_mm = None          # the next ultra capsule's first distance, decided
        return ResponseDescriptor(self._frame_size, SendMode.MULTIPLE, mode.answer_type).encode()

    def _stop(self):
        if self._mode is not None:
            self._phase_q6 = int((self._phase_q6 + self._sent * self._step_q6) % FULL_TURN_Q6)
        self._mode = None

    def clock(self) -> Optional[StreamClock]:
        """
        Return the sample clock of the stream being sent (the truth for timing tests).

        :return: the clock, or None when not streaming
        """
        if self._mode is None:
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
        if self._mode is None:
            return math.inf
        return max(self._due_s(self._sent) - now_s, 0.0)

    def _due_s(self, frame: int) -> float:
        """When frame ``frame``'s last byte arrives at the host."""
        return (self._start_s + (frame + 1) * self._frame_s
                + self._frame_size * 10.0 / SERIAL_BAUD)

    def stream(self, now_s: float) -> bytes:
        """
        Return the stream bytes due by ``now_s`` (with faults applied).

        :param now_s: monotonic time, s
        :return: bytes to send
        """
        if self._mode is None:
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
        for _ in range(_ULTRA_PASSES):
            distances = np.rint(self._scene.distances_mm((uniform - offset_deg(sent)) % 360.0))
            distances[distances > ULTRA_MAX_DISTANCE_MM] = 0
            if self._next_ultra_mm is not None:
                distances[0] = self._next_ultra_mm
            data, sent = self._encode_ultra(start_q6, frames == 0, distances)
        # Where the offset of the distance sent keeps moving the sample (an edge, or a distance
        # where the offset steps), the scene there may not show that distance: then the sample
        # is sent as no return.
        seen = self._scene.distances_mm((uniform - offset_deg(sent)) % 360.0)
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
        """Corrupt and drop streamed bytes and cut frames short at the configured rates."""
        faults = self._faults
        if not (faults.corrupt_rate or faults.drop_rate or faults.cut_rate):
            return data
        raw = np.frombuffer(data, np.uint8).copy()
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
        return raw[kept].tobytes()
