# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The RPLIDAR S1 byte protocol: requests, answers and the two scan stream formats (pure, no I/O).

Everything is little-endian. A request is ``A5 cmd`` or, for cmd >= 0x80,
``A5 cmd size payload checksum`` (XOR of every preceding byte). An answer starts with a 7-byte
descriptor ``A5 5A u32(length | send_mode << 30) type``. Scan answers are endless streams of
5-byte standard nodes (type 0x81) or 84-byte dense capsules (type 0x85). The incremental
node decoder below takes arbitrary chunks and resynchronises on garbage exactly as SLAMTEC's SDK
does (byte-wise sync and check bits); the capsule decoder, which recovers far more of a damaged
stream than the SDK, is :mod:`wctls_rplidar.capsules`.

Angles are the device's raw angles in degrees, clockwise seen from above, 0 = device front;
distances are in millimetres with 0 meaning no return.
"""

from dataclasses import astuple, dataclass, fields
import enum
import functools
import operator
import struct
from typing import Optional, Sequence

import numpy as np

SYNC_BYTE = 0xA5
ANSWER_SYNC = b'\xa5\x5a'
DESCRIPTOR_SIZE = 7
# The SDK reports this quality (0x2F << 2) for a dense-capsule return; 47 in the 6-bit scale.
DENSE_RETURN_QUALITY = 0x2F
SAMPLES_PER_CAPSULE = 40
FULL_TURN_Q6 = 360 << 6
CONF_COMMANDS_FIRMWARE = (1, 24)   # GET_LIDAR_CONF exists from this firmware (major, minor) on


class ProtocolError(ValueError):
    """Bytes that do not follow the protocol (bad size, checksum, echo or answer type)."""


class Command(enum.IntEnum):
    """Request command bytes."""

    STOP = 0x25
    RESET = 0x40
    SCAN = 0x20
    FORCE_SCAN = 0x21
    EXPRESS_SCAN = 0x82
    GET_INFO = 0x50
    GET_HEALTH = 0x52
    GET_SAMPLERATE = 0x59
    GET_LIDAR_CONF = 0x84
    MOTOR_SPEED = 0xA8
    SET_MOTOR_PWM = 0xF0
    GET_ACC_BOARD_FLAG = 0xFF


class AnswerType(enum.IntEnum):
    """Answer type bytes of response descriptors."""

    DEVICE_INFO = 0x04
    DEVICE_HEALTH = 0x06
    SAMPLE_RATE = 0x15
    LIDAR_CONF = 0x20
    MEASUREMENT = 0x81
    EXPRESS_CAPSULE = 0x82
    HQ_CAPSULE = 0x83
    ULTRA_CAPSULE = 0x84
    DENSE_CAPSULE = 0x85
    ULTRA_DENSE_CAPSULE = 0x86
    ACC_BOARD_FLAG = 0xFF


class SendMode(enum.IntEnum):
    """Descriptor send mode: one payload, or payloads of that length forever."""

    SINGLE = 0
    MULTIPLE = 1


class HealthStatus(enum.IntEnum):
    """GET_HEALTH status byte."""

    OK = 0
    WARNING = 1
    ERROR = 2


class ConfType(enum.IntEnum):
    """GET_LIDAR_CONF entry types."""

    DESIRED_ROTATION = 0x01
    MODE_COUNT = 0x70
    US_PER_SAMPLE = 0x71
    MAX_DISTANCE = 0x74
    ANSWER_TYPE = 0x75
    TYPICAL_MODE = 0x7C
    MODE_NAME = 0x7F


# struct format of each numeric configuration value; Q8 entries are fixed point value / 256.
_CONF_FORMATS = {
    ConfType.DESIRED_ROTATION: '<HH',
    ConfType.MODE_COUNT: '<H',
    ConfType.US_PER_SAMPLE: '<I',
    ConfType.MAX_DISTANCE: '<I',
    ConfType.ANSWER_TYPE: '<B',
    ConfType.TYPICAL_MODE: '<H',
}
_CONF_Q8 = (ConfType.US_PER_SAMPLE, ConfType.MAX_DISTANCE)
# Entries that describe one scan mode: the request carries a u16 mode id after the type.
MODE_CONF_TYPES = (ConfType.US_PER_SAMPLE, ConfType.MAX_DISTANCE, ConfType.ANSWER_TYPE,
                   ConfType.MODE_NAME)


def checksum(data: bytes) -> int:
    """
    Return the XOR of all bytes.

    :param data: bytes to fold
    :return: the checksum byte, 0-255
    """
    return functools.reduce(operator.xor, data, 0)


def encode_request(command: int, payload: bytes = b'') -> bytes:
    """
    Encode a request: ``A5 cmd`` or ``A5 cmd size payload checksum`` for cmd >= 0x80.

    :param command: command byte (see :class:`Command`)
    :param payload: payload bytes; only commands >= 0x80 carry one
    :return: the request bytes
    :raises ProtocolError: on a payload for a command < 0x80 or longer than 255 bytes
    """
    if command < 0x80:
        if payload:
            raise ProtocolError(f'command 0x{command:02X} < 0x80 cannot carry a payload')
        return bytes((SYNC_BYTE, command))
    if len(payload) > 0xFF:
        raise ProtocolError(f'payload of {len(payload)} bytes exceeds 255')
    body = bytes((SYNC_BYTE, command, len(payload))) + bytes(payload)
    return body + bytes((checksum(body),))


def encode_motor_speed(rpm: int) -> bytes:
    """
    Encode MOTOR_SPEED (0xA8): u16 rpm, 600 = 10 Hz, 0 = idle.

    :param rpm: motor speed, revolutions per minute
    :return: the request bytes
    """
    return encode_request(Command.MOTOR_SPEED, struct.pack('<H', rpm))


def encode_motor_pwm(pwm: int) -> bytes:
    """
    Encode SET_MOTOR_PWM (0xF0): u16 duty of an A2/A3 accessory board's motor driver, 0 = off.

    :param pwm: PWM value
    :return: the request bytes
    """
    return encode_request(Command.SET_MOTOR_PWM, struct.pack('<H', pwm))


def encode_acc_board_flag_request() -> bytes:
    """
    Encode GET_ACC_BOARD_FLAG (0xFF) with its reserved u32 (0).

    :return: the request bytes
    """
    return encode_request(Command.GET_ACC_BOARD_FLAG, struct.pack('<I', 0))


def encode_express_scan(working_mode: int, flags: int = 0, param: int = 0) -> bytes:
    """
    Encode EXPRESS_SCAN (0x82): u8 working mode (the scan mode id), u16 flags, u16 param.

    :param working_mode: scan mode id (1 = DenseBoost on the S1)
    :param flags: working flags (0)
    :param param: parameter (0)
    :return: the request bytes
    """
    return encode_request(Command.EXPRESS_SCAN, struct.pack('<BHH', working_mode, flags, param))


@dataclass(frozen=True)
class Request:
    """
    A decoded request (the emulator's side of the protocol).

    :ivar command: command byte
    :ivar payload: payload bytes (empty for commands < 0x80)
    """

    command: int
    payload: bytes = b''


class RequestParser:
    """
    Incremental request decoder: feed arbitrary chunks, get whole requests.

    Bytes before a ``A5`` are skipped; a request with a wrong checksum is dropped (its ``A5`` is
    skipped and the search goes on), counted in :attr:`checksum_errors`.
    """

    def __init__(self):
        self._buffer = b''
        self.checksum_errors = 0

    def feed(self, data: bytes) -> list:
        """
        Decode the requests completed by ``data``.

        :param data: the next received bytes
        :return: list of :class:`Request`
        """
        buffer = self._buffer + bytes(data)
        requests = []
        pos = 0
        while True:
            start = buffer.find(SYNC_BYTE, pos)
            if start < 0:
                pos = len(buffer)
                break
            if start + 2 > len(buffer):
                pos = start
                break
            command = buffer[start + 1]
            if command < 0x80:
                requests.append(Request(command))
                pos = start + 2
                continue
            if start + 3 > len(buffer) or start + 4 + buffer[start + 2] > len(buffer):
                pos = start
                break
            end = start + 3 + buffer[start + 2]
            if checksum(buffer[start:end]) != buffer[end]:
                self.checksum_errors += 1
                pos = start + 1
                continue
            requests.append(Request(command, buffer[start + 3:end]))
            pos = end + 1
        self._buffer = buffer[pos:]
        return requests


@dataclass(frozen=True)
class ResponseDescriptor:
    """
    The 7-byte header of every answer.

    :ivar length: payload length, bytes (30 bits)
    :ivar send_mode: :class:`SendMode` (single answer or endless stream)
    :ivar answer_type: answer type byte (see :class:`AnswerType`)
    """

    length: int
    send_mode: int
    answer_type: int

    def encode(self) -> bytes:
        """
        Encode the descriptor.

        :return: 7 bytes
        """
        size_mode = (self.length & 0x3FFFFFFF) | (self.send_mode << 30)
        return ANSWER_SYNC + struct.pack('<IB', size_mode, self.answer_type)

    @classmethod
    def decode(cls, raw: bytes) -> 'ResponseDescriptor':
        """
        Decode a descriptor.

        :param raw: exactly 7 bytes starting with ``A5 5A``
        :return: the descriptor
        :raises ProtocolError: on a wrong size or sync
        """
        if len(raw) != DESCRIPTOR_SIZE or raw[:2] != ANSWER_SYNC:
            raise ProtocolError(f'not a response descriptor: {bytes(raw).hex(" ")}')
        size_mode, answer_type = struct.unpack_from('<IB', raw, 2)
        return cls(size_mode & 0x3FFFFFFF, size_mode >> 30, answer_type)


def find_descriptor(buffer: bytes) -> tuple:
    """
    Find the first complete response descriptor in received bytes.

    :param buffer: received bytes (may start with garbage)
    :return: ``(descriptor, end)`` with the index just past it, or ``(None, keep)`` where
        ``buffer[:keep]`` can be dropped because no descriptor starts there
    """
    start = buffer.find(ANSWER_SYNC)
    if start < 0:
        return None, max(len(buffer) - 1, 0)
    if len(buffer) - start < DESCRIPTOR_SIZE:
        return None, start
    end = start + DESCRIPTOR_SIZE
    return ResponseDescriptor.decode(buffer[start:end]), end


def encode_answer(answer_type: int, payload: bytes) -> bytes:
    """
    Encode a single answer: descriptor plus payload.

    :param answer_type: answer type byte
    :param payload: payload bytes
    :return: the answer bytes
    """
    return ResponseDescriptor(len(payload), SendMode.SINGLE, answer_type).encode() + payload


class _StructAnswer:
    """A fixed-size answer payload laid out as the dataclass fields in ``_FORMAT`` order."""

    _FORMAT = ''
    ANSWER_TYPE = 0

    def encode(self) -> bytes:
        """
        Encode the payload.

        :return: the payload bytes
        """
        return struct.pack(self._FORMAT, *astuple(self))

    @classmethod
    def decode(cls, payload: bytes):
        """
        Decode the payload.

        :param payload: the answer payload
        :return: an instance
        :raises ProtocolError: on a wrong payload size
        """
        if len(payload) != struct.calcsize(cls._FORMAT):
            raise ProtocolError(f'{cls.__name__} needs {struct.calcsize(cls._FORMAT)} bytes, got '
                                f'{len(payload)}')
        return cls(*struct.unpack(cls._FORMAT, payload))


# The model families by the major id, the model byte's high nibble (its low nibble is the
# sub-model: 0x61 is the S1M1), as SLAMTEC's SDK names them.
MODEL_FAMILIES = {1: 'A1', 2: 'A2', 3: 'A3', 4: 'C1', 6: 'S1', 7: 'S2', 8: 'S3'}
# Major ids from which SLAMTEC's SDK (sl_lidar_driver.cpp) treats a device as a new design that
# always answers GET_LIDAR_CONF (the C1 on), asks an A2/A3/C1 whether an accessory board drives
# its motor by PWM (GET_ACC_BOARD_FLAG), and sets an S-series motor's speed in rpm (MOTOR_SPEED).
NEW_DESIGN_MAJOR_ID = 4
ACC_BOARD_MAJOR_IDS = range(2, 6)
RPM_MOTOR_MAJOR_ID = 6


class MotorControl(enum.Enum):
    """How the host starts, stops and speeds a device's motor (the SDK's three ways)."""

    DTR = 'DTR line'            # on/off only: DTR cleared runs the motor (A1; A2/A3 bare)
    PWM = 'PWM (SET_MOTOR_PWM)'    # an A2/A3 accessory board's motor driver
    RPM = 'rpm (MOTOR_SPEED)'      # the S-series' own speed control


def native_baudrate(model: int, hardware: int) -> int:
    """
    Return a model's serial rate, as SLAMTEC's SDK reckons it (``_getNativeBaudRate``).

    :param model: the model byte of GET_INFO
    :param hardware: the hardware revision of GET_INFO
    :return: bits per second; 0 for a model it does not know
    """
    major = model >> 4
    if major in (1, 2, 3):
        return 256000 if hardware >= 6 else 115200
    if major == 8 and model == 0x82:
        return 460800
    return {4: 460800, 6: 256000, 7: 1000000, 8: 1000000}.get(major, 0)


def model_name(model: int) -> str:
    """
    Name a device by its model byte, as SLAMTEC does.

    :param model: the model byte of GET_INFO
    :return: e.g. ``'S1M1'`` for 0x61, ``'A2M8'`` for 0x28; ``'unknown (0xNN)'`` for a major
        id outside :data:`MODEL_FAMILIES`
    """
    family = MODEL_FAMILIES.get(model >> 4)
    return f'{family}M{model & 0x0F}' if family else f'unknown (0x{model:02X})'


@dataclass(frozen=True)
class DeviceInfo(_StructAnswer):
    """
    GET_INFO answer (type 0x04, 20 bytes).

    :ivar model: model id (0x61 = S1M1)
    :ivar firmware_minor: firmware minor version
    :ivar firmware_major: firmware major version
    :ivar hardware: hardware revision
    :ivar serial_number: 16 serial number bytes
    """

    _FORMAT = '<BBBB16s'
    ANSWER_TYPE = AnswerType.DEVICE_INFO

    model: int
    firmware_minor: int
    firmware_major: int
    hardware: int
    serial_number: bytes

    @property
    def firmware(self) -> tuple:
        """Firmware version as ``(major, minor)``."""
        return self.firmware_major, self.firmware_minor

    @property
    def model_name(self) -> str:
        """Return the model's name, e.g. ``'S1M1'`` (see :func:`model_name`)."""
        return model_name(self.model)

    @property
    def supports_conf(self) -> bool:
        """Tell whether it answers GET_LIDAR_CONF: a new design or firmware 1.24 on (the SDK's)."""
        return self.model >> 4 >= NEW_DESIGN_MAJOR_ID or self.firmware >= CONF_COMMANDS_FIRMWARE

    @property
    def firmware_version(self) -> str:
        """Return the firmware version as SLAMTEC writes it, e.g. ``'1.28'``."""
        return f'{self.firmware_major}.{self.firmware_minor:02d}'

    def describe(self) -> str:
        """
        Describe the device in one line.

        :return: model name and id, firmware, hardware and serial number
        """
        return (f'RPLIDAR {self.model_name} (model 0x{self.model:02X}), firmware '
                f'{self.firmware_version}, hardware {self.hardware}, serial '
                f'{self.serial_number.hex().upper()}')


@dataclass(frozen=True)
class DeviceHealth(_StructAnswer):
    """
    GET_HEALTH answer (type 0x06, 3 bytes).

    :ivar status: :class:`HealthStatus`
    :ivar error_code: device error code
    """

    _FORMAT = '<BH'
    ANSWER_TYPE = AnswerType.DEVICE_HEALTH

    status: int
    error_code: int


@dataclass(frozen=True)
class SampleRate(_StructAnswer):
    """
    GET_SAMPLERATE answer (type 0x15, 4 bytes).

    :ivar standard_us: microseconds per sample of the standard scan
    :ivar express_us: microseconds per sample of the express scan
    """

    _FORMAT = '<HH'
    ANSWER_TYPE = AnswerType.SAMPLE_RATE

    standard_us: int
    express_us: int


@dataclass(frozen=True)
class AccBoardFlag(_StructAnswer):
    """
    GET_ACC_BOARD_FLAG answer (type 0xFF, 4 bytes).

    :ivar support_flag: bit 0 set: an accessory board drives the motor (SET_MOTOR_PWM)
    """

    _FORMAT = '<I'
    ANSWER_TYPE = AnswerType.ACC_BOARD_FLAG

    support_flag: int

    @property
    def motor_pwm(self) -> bool:
        """Tell whether the motor takes SET_MOTOR_PWM."""
        return bool(self.support_flag & 1)


@dataclass(frozen=True)
class ScanMode:
    """
    One scan mode as GET_LIDAR_CONF describes it.

    :ivar mode_id: id used in EXPRESS_SCAN
    :ivar name: e.g. ``'DenseBoost'``
    :ivar us_per_sample: microseconds per sample
    :ivar max_distance_m: farthest measurable range, m
    :ivar answer_type: stream answer type (0x81 nodes, 0x85 dense capsules, ...)
    """

    mode_id: int
    name: str
    us_per_sample: float
    max_distance_m: float
    answer_type: int

    def describe(self) -> str:
        """
        Describe the mode in one line.

        :return: name, sample rate and range
        """
        return (f'{self.name} (id {self.mode_id}, {self.us_per_sample:g} us/sample = '
                f'{1000.0 / self.us_per_sample:.2f} kHz, {self.max_distance_m:g} m, '
                f'answer 0x{self.answer_type:02X})')


def encode_conf_request(conf_type: int, mode: Optional[int] = None) -> bytes:
    """
    Encode GET_LIDAR_CONF: u32 type, plus u16 mode for mode entries.

    :param conf_type: :class:`ConfType`
    :param mode: scan mode id for the entries in :data:`MODE_CONF_TYPES`
    :return: the request bytes
    """
    payload = struct.pack('<I', conf_type)
    if mode is not None:
        payload += struct.pack('<H', mode)
    return encode_request(Command.GET_LIDAR_CONF, payload)


def decode_conf_request(payload: bytes) -> tuple:
    """
    Decode a GET_LIDAR_CONF request payload.

    :param payload: request payload
    :return: ``(conf_type, mode)``; mode is None when absent
    :raises ProtocolError: on a payload shorter than 4 bytes
    """
    if len(payload) < 4:
        raise ProtocolError(f'GET_LIDAR_CONF payload of {len(payload)} bytes is too short')
    conf_type = struct.unpack_from('<I', payload)[0]
    mode = struct.unpack_from('<H', payload, 4)[0] if len(payload) >= 6 else None
    return conf_type, mode


def encode_conf_value(conf_type: int, value) -> bytes:
    """
    Encode a GET_LIDAR_CONF answer payload: u32 type echo and the value.

    :param conf_type: :class:`ConfType`
    :param value: int, float for the Q8 entries, str for the mode name, (rpm, pwm) for the
        desired rotation, None for an entry the device does not know (echo only)
    :return: the answer payload
    """
    echo = struct.pack('<I', conf_type)
    if value is None:
        return echo
    if conf_type == ConfType.MODE_NAME:
        return echo + value.encode('ascii') + b'\0'
    if conf_type in _CONF_Q8:
        value = round(value * 256)
    values = value if isinstance(value, tuple) else (value,)
    return echo + struct.pack(_CONF_FORMATS[conf_type], *values)


def decode_conf_value(conf_type: int, payload: bytes):
    """
    Decode a GET_LIDAR_CONF answer payload.

    :param conf_type: the requested :class:`ConfType`
    :param payload: the answer payload (type echo and value)
    :return: int, float (Q8 entries), str (mode name) or (rpm, pwm) tuple
    :raises ProtocolError: on a wrong echo or a short value
    """
    if len(payload) < 4 or struct.unpack_from('<I', payload)[0] != conf_type:
        raise ProtocolError(f'GET_LIDAR_CONF 0x{conf_type:02X} answered with '
                            f'{bytes(payload).hex(" ")}')
    value = payload[4:]
    if conf_type == ConfType.MODE_NAME:
        return value.split(b'\0', 1)[0].decode('ascii', errors='replace')
    fmt = _CONF_FORMATS[conf_type]
    if len(value) < struct.calcsize(fmt):
        raise ProtocolError(f'GET_LIDAR_CONF 0x{conf_type:02X} value is {len(value)} bytes')
    values = struct.unpack_from(fmt, value)
    if conf_type in _CONF_Q8:
        return values[0] / 256.0
    return values if len(values) > 1 else values[0]


@dataclass(frozen=True)
class Samples:
    """
    Decoded measurements in stream order (arrays of equal length).

    :ivar angle_deg: raw angle, degrees clockwise from the device front, in [0, 360)
    :ivar distance_mm: distance, mm; 0 = no return
    :ivar quality: 6-bit quality (0-63); 47 for a dense-capsule return, 0 without
    :ivar start: True at the first sample of a new turn (the node's S bit; for capsules the
        first sample whose angle is below its predecessor's)
    :ivar frame_end: stream offset just past the frame that carried the sample's distance
    :ivar samples_after: samples measured after this one within the same frame
    :ivar slot: the sample's position in the stream, counting the frames sent before it by their
        bytes (so corrupted or lost frames still count): frame index x samples per frame + k
    :ivar device_time_us: the timestamp of the sample's frame on the device's clock,
        microseconds, for formats that carry one (ultra-dense capsules); -1 where the format
        carries none or the frame's was unreadable (the default)
    """

    angle_deg: np.ndarray
    distance_mm: np.ndarray
    quality: np.ndarray
    start: np.ndarray
    frame_end: np.ndarray
    samples_after: np.ndarray
    slot: np.ndarray
    device_time_us: Optional[np.ndarray] = None

    def __post_init__(self):
        if self.device_time_us is None:
            object.__setattr__(self, 'device_time_us', np.full(len(self.angle_deg), -1, np.int64))

    def __len__(self):
        return len(self.angle_deg)

    @classmethod
    def concat(cls, parts: Sequence['Samples']) -> 'Samples':
        """
        Concatenate in order.

        :param parts: samples to join
        :return: one :class:`Samples`
        """
        if len(parts) == 1:
            return parts[0]
        fields = ('angle_deg', 'distance_mm', 'quality', 'start', 'frame_end', 'samples_after',
                  'slot', 'device_time_us')
        if not parts:
            dtypes = (np.float64, np.float64, np.uint8, bool, np.int64, np.int64, np.int64)
            return cls(*(np.empty(0, dtype) for dtype in dtypes))
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in fields))


_NODE_DTYPE = np.dtype([('sync_quality', 'u1'), ('angle_check', '<u2'), ('distance_q2', '<u2')])
_CAPSULE_DTYPE = np.dtype([('sync1', 'u1'), ('sync2', 'u1'), ('start_angle', '<u2'),
                           ('distance_mm', '<u2', (SAMPLES_PER_CAPSULE,))])
NODE_SIZE = _NODE_DTYPE.itemsize
CAPSULE_SIZE = _CAPSULE_DTYPE.itemsize


def encode_standard_nodes(angle_q6: np.ndarray, distance_q2: np.ndarray, quality: np.ndarray,
                          start: np.ndarray) -> bytes:
    """
    Encode 5-byte standard nodes (answer type 0x81).

    :param angle_q6: raw angles, 1/64 degree, 0-23039
    :param distance_q2: distances, 1/4 mm, 0 = no return
    :param quality: 6-bit qualities
    :param start: S flags (first node of a turn)
    :return: the node bytes
    """
    start = np.asarray(start, dtype=np.uint8)
    nodes = np.empty(len(start), _NODE_DTYPE)
    nodes['sync_quality'] = (np.asarray(quality, np.uint8) << 2) | start | ((start ^ 1) << 1)
    nodes['angle_check'] = (np.asarray(angle_q6, np.uint16) << 1) | 1
    nodes['distance_q2'] = distance_q2
    return nodes.tobytes()


def encode_dense_capsules(start_q6: np.ndarray, distance_mm: np.ndarray,
                          start_flag: np.ndarray) -> bytes:
    """
    Encode 84-byte dense capsules (answer type 0x85) with their checksums.

    :param start_q6: start angle of each capsule, 1/64 degree, 0-23039
    :param distance_mm: distances, shape (n, 40), mm, 0 = no return
    :param start_flag: S flag of each capsule (set on the first capsule after the start command)
    :return: the capsule bytes
    """
    flags = np.asarray(start_flag, dtype=np.uint16) << 15
    capsules = np.empty(len(flags), _CAPSULE_DTYPE)
    capsules['start_angle'] = np.asarray(start_q6, np.uint16) | flags
    capsules['distance_mm'] = distance_mm
    raw = capsules.view(np.uint8).reshape(len(flags), CAPSULE_SIZE)
    sums = np.bitwise_xor.reduce(raw[:, 2:], axis=1)
    capsules['sync1'] = 0xA0 | (sums & 0x0F)
    capsules['sync2'] = 0x50 | (sums >> 4)
    return capsules.tobytes()


def _byte_table(predicate) -> np.ndarray:
    """Tabulate a vectorised predicate over all 256 byte values."""
    return predicate(np.arange(256, dtype=np.uint8))


@dataclass(frozen=True)
class StreamCounts:
    """
    What a scan stream decoder has met so far.

    :ivar frames: frames (nodes or capsules) received, decoded or not
    :ivar damaged_frames: capsules that failed their checksum or lost or gained bytes
    :ivar realigned_frames: capsules whose samples were found again after lost or gained bytes
    :ivar lost_frames: frames that yielded no samples
    :ivar resyncs: times sync was lost and searched for byte by byte
    :ivar discarded_bytes: bytes skipped while searching
    :ivar samples: samples decoded
    :ivar rejected_samples: decoded samples published as no return: implausible distances and
        those a lost byte made unreadable
    :ivar replaced_angles: capsules whose start angle was out of sequence (the predicted one
        was used)
    """

    frames: int = 0
    damaged_frames: int = 0
    realigned_frames: int = 0
    lost_frames: int = 0
    resyncs: int = 0
    discarded_bytes: int = 0
    samples: int = 0
    rejected_samples: int = 0
    replaced_angles: int = 0

    def __add__(self, other: 'StreamCounts') -> 'StreamCounts':
        return StreamCounts(*(getattr(self, f) + getattr(other, f) for f in _COUNT_FIELDS))

    def __sub__(self, other: 'StreamCounts') -> 'StreamCounts':
        return StreamCounts(*(getattr(self, f) - getattr(other, f) for f in _COUNT_FIELDS))


_COUNT_FIELDS = tuple(f.name for f in fields(StreamCounts))


class StandardNodeDecoder:
    """
    Incremental decoder of 5-byte standard nodes (answer type 0x81), resynchronising as the SDK.

    byte 0: bit 0 S, bit 1 must equal not S, bits 2-7 quality; byte 1 bit 0 check bit = 1;
    u16 at 1-2 >> 1 = angle in 1/64 degree; u16 at 3-4 = distance in 1/4 mm. The SDK checks
    byte 0 of a node (skips it when wrong), then byte 1 (skips both when wrong), then takes the
    rest. Aligned nodes are checked and decoded vectorised; only garbage takes the byte loop.
    """

    FRAME_SIZE = NODE_SIZE
    SAMPLES_PER_FRAME = 1
    _FIRST_OK = _byte_table(lambda b: ((b >> 1) ^ b) & 1 == 1)
    _SECOND_OK = _byte_table(lambda b: b & 1 == 1)

    def __init__(self):
        self._pending = b''
        self._offset = 0
        self._frames = self._resyncs = self._discarded = 0

    @property
    def counts(self) -> StreamCounts:
        """Return what the decoder has met so far."""
        return StreamCounts(frames=self._frames, samples=self._frames, resyncs=self._resyncs,
                            discarded_bytes=self._discarded)

    def feed(self, data: bytes) -> Samples:
        """
        Decode what the next received chunk completes.

        :param data: the next received bytes, any length
        :return: the samples decoded, in stream order
        """
        buffer = self._pending + bytes(data)
        parts = []
        pos = 0
        while len(buffer) - pos >= NODE_SIZE:
            count = (len(buffer) - pos) // NODE_SIZE
            raw = np.frombuffer(buffer, np.uint8, count * NODE_SIZE, pos).reshape(count, NODE_SIZE)
            bad = np.flatnonzero(~(self._FIRST_OK[raw[:, 0]] & self._SECOND_OK[raw[:, 1]]))
            good = count if bad.size == 0 else int(bad[0])
            if good:
                ends = self._offset + pos + NODE_SIZE * np.arange(1, good + 1, dtype=np.int64)
                parts.append(self._decode(raw[:good], ends))
                self._frames += good
                pos += good * NODE_SIZE
            if good == count:
                break
            resynced = self._resync(buffer, pos)
            self._resyncs += 1
            self._discarded += resynced - pos
            pos = resynced
        self._pending = buffer[pos:]
        self._offset += pos
        return Samples.concat(parts)

    def _resync(self, buffer: bytes, pos: int) -> int:
        """Skip bytes as the SDK does until a node may start; return that position."""
        while pos < len(buffer):
            if not self._FIRST_OK[buffer[pos]]:
                pos += 1
            elif pos + 1 == len(buffer) or self._SECOND_OK[buffer[pos + 1]]:
                return pos
            else:
                pos += 2
        return pos

    @staticmethod
    def _decode(raw: np.ndarray, ends: np.ndarray) -> Samples:
        nodes = raw.reshape(-1).view(_NODE_DTYPE)
        sync_quality = nodes['sync_quality']
        return Samples(angle_deg=(nodes['angle_check'] >> 1) / 64.0,
                       distance_mm=nodes['distance_q2'] / 4.0,
                       quality=sync_quality >> 2,
                       start=(sync_quality & 1).astype(bool),
                       frame_end=ends,
                       samples_after=np.zeros(len(ends), np.int64),
                       slot=ends // NODE_SIZE - 1)
