"""
Reading LaserScans from bags and writing bags, with the ``rosbags`` library (no ROS install).

Reads ROS 2 bags (sqlite3 and mcap) and ROS 1 bags. Writes ROS 2 mcap bags whose messages are
serialised by rclpy itself, so every type rclpy knows (including wctls_msgs) can be stored; the
message definitions come from a rosbags typestore with wctls_msgs registered from its .msg files.
A bag is written to a temporary folder and renamed into place when complete: an error never
leaves half a bag behind.
"""

from dataclasses import dataclass
import functools
import pathlib
import shutil
import tempfile
from typing import Iterator, Optional

from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_types_from_msg, get_typestore, Stores

LASER_SCAN = 'sensor_msgs/msg/LaserScan'
MESSAGE_PACKAGE = 'wctls_msgs'


class BagError(RuntimeError):
    """A bag that cannot be read or written, with the reason."""


@functools.lru_cache(maxsize=1)
def typestore():
    """
    Return the ROS 2 Jazzy typestore with the wctls_msgs types registered.

    :return: a rosbags Typestore
    :raises BagError: when the wctls_msgs .msg files cannot be found
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for path in sorted(_message_directory().glob('*.msg')):
        types.update(get_types_from_msg(path.read_text(), f'{MESSAGE_PACKAGE}/msg/{path.stem}'))
    store.register(types)
    return store


def _message_directory() -> pathlib.Path:
    """Find wctls_msgs/msg: in the install space, else beside this package's source."""
    try:
        from ament_index_python.packages import get_package_share_directory
        return pathlib.Path(get_package_share_directory(MESSAGE_PACKAGE)) / 'msg'
    except (ImportError, LookupError, ValueError):
        source = pathlib.Path(__file__).resolve().parents[3] / MESSAGE_PACKAGE / 'msg'
        if source.is_dir():
            return source
    raise BagError(f'cannot find the {MESSAGE_PACKAGE} message definitions: source the '
                   'workspace (install/setup.bash) first')


@dataclass(frozen=True)
class ScanRecord:
    """
    One LaserScan read from a bag.

    :ivar timestamp_ns: the bag's log time of the message, ns
    :ivar topic: topic it was recorded on
    :ivar scan: the message (fields of sensor_msgs/LaserScan: header, angle_min, ranges, ...)
    """

    timestamp_ns: int
    topic: str
    scan: object


def _open(path) -> AnyReader:
    path = pathlib.Path(path)
    if not path.exists():
        raise BagError(f'no bag at {path}')
    try:
        reader = AnyReader([path], default_typestore=typestore())
        reader.open()
    except Exception as error:  # noqa: B902 - rosbags raises many types for a damaged bag
        raise BagError(f'cannot open {path} as a ROS 1 or ROS 2 bag: {error}') from error
    return reader


def scan_topics(path) -> dict:
    """
    List the LaserScan topics of a bag with their message counts.

    :param path: a ROS 2 bag folder (or its .mcap/.db3 file) or a ROS 1 .bag file
    :return: topic -> message count
    :raises BagError: when the path is missing or not a readable bag
    """
    reader = _open(path)
    try:
        return {c.topic: c.msgcount for c in reader.connections if c.msgtype == LASER_SCAN}
    finally:
        reader.close()


def choose_scan_topic(path, topic: Optional[str] = None) -> str:
    """
    Pick the LaserScan topic to read: the given one, or the only one in the bag.

    :param path: the bag
    :param topic: the requested topic, or None to find it
    :return: the topic
    :raises BagError: when the bag has no LaserScan, several without a choice, or not ``topic``
    """
    topics = scan_topics(path)
    if topic is not None:
        if topic not in topics:
            raise BagError(f'{path} has no LaserScan topic {topic!r}; it has {sorted(topics)}')
        return topic
    if not topics:
        raise BagError(f'{path} holds no sensor_msgs/msg/LaserScan messages')
    if len(topics) > 1:
        raise BagError(f'{path} has several LaserScan topics {sorted(topics)}: choose one')
    return next(iter(topics))


def read_scans(path, topic: Optional[str] = None) -> Iterator[ScanRecord]:
    """
    Yield the LaserScans of one topic in log-time order, one at a time (constant memory).

    :param path: a ROS 2 bag (sqlite3 or mcap) or a ROS 1 bag
    :param topic: the LaserScan topic, or None for the bag's only one
    :return: iterator of records
    :raises BagError: on a missing, corrupt or truncated bag, or no LaserScan topic
    """
    topic = choose_scan_topic(path, topic)
    reader = _open(path)
    try:
        connections = [c for c in reader.connections if c.topic == topic]
        try:
            for connection, timestamp, raw in reader.messages(connections=connections):
                yield ScanRecord(timestamp, topic, reader.deserialize(raw, connection.msgtype))
        except BagError:
            raise
        except Exception as error:  # noqa: B902 - a truncated bag fails deep inside rosbags
            raise BagError(f'{path} is damaged after some messages of {topic}: {error}') from error
    finally:
        reader.close()


class BagWriter:
    """
    Write an mcap ROS 2 bag of rclpy messages; the bag appears only when closed without error.

    Use as a context manager::

        with BagWriter('out/run') as bag:
            bag.write('/scan', timestamp_ns, scan_msg)
    """

    def __init__(self, path):
        self.path = pathlib.Path(path)
        if self.path.exists():
            raise BagError(f'{self.path} exists: refusing to overwrite it')
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._staging = pathlib.Path(tempfile.mkdtemp(prefix='.partial-', dir=self.path.parent))
        self._writer = Writer(self._staging / self.path.name, version=9,
                              storage_plugin=StoragePlugin.MCAP)
        self._connections = {}
        self._serialize = None

    def __enter__(self) -> 'BagWriter':
        self._writer.open()
        from rclpy.serialization import serialize_message
        self._serialize = serialize_message
        return self

    def write(self, topic: str, timestamp_ns: int, message) -> None:
        """
        Append one message (serialised by rclpy) on a topic.

        :param topic: the topic; its type is taken from the first message written on it
        :param timestamp_ns: log time, ns
        :param message: an rclpy message instance
        """
        connection = self._connections.get(topic)
        if connection is None:
            module = type(message).__module__.split('.')[0]
            msgtype = f'{module}/msg/{type(message).__name__}'
            connection = self._writer.add_connection(topic, msgtype, typestore=typestore())
            self._connections[topic] = connection
        self._writer.write(connection, int(timestamp_ns), self._serialize(message))

    def __exit__(self, kind, value, traceback):
        try:
            self._writer.close()
            if kind is None:
                (self._staging / self.path.name).rename(self.path)
        finally:
            shutil.rmtree(self._staging, ignore_errors=True)
        return False
