# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Reading LaserScans from bags and writing bags, with the ``rosbags`` library (no ROS install).

Reads ROS 2 bags (sqlite3 and mcap) and ROS 1 bags. Writes ROS 2 bags (mcap by default) of
rosbags messages (serialised by rosbags: no ROS install needed) or of rclpy messages (serialised
by rclpy, imported only then); the message definitions come from a rosbags typestore with
wctls_msgs registered from its .msg files. rosbags is imported when a bag is first opened, so a
tool without it starts and says so in one line (:func:`wctls_ros.extras.explains_missing_extras`).
A bag is written to a staging folder beside it and
renamed into place when complete: an error or a signal never leaves half a bag behind, and the
staging folder of a killed writer (SIGKILL) is removed by the next writer in the same folder.
"""

import contextlib
from dataclasses import dataclass
import fcntl
import os
import pathlib
import re
import shutil
import tempfile
from typing import Iterator, Optional, TYPE_CHECKING

from ..conversions import typestore

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader

LASER_SCAN = 'sensor_msgs/msg/LaserScan'
# Files that hold a ROS 2 bag's messages when its metadata.yaml is missing (recorder killed).
_STORAGE_SUFFIXES = ('.mcap', '.db3')
# The storages a bag is written in: name -> rosbags' StoragePlugin member.
_STORAGES = {'mcap': 'MCAP', 'sqlite3': 'SQLITE3'}
# A bag is written in a staging folder beside it, named after the writing process and locked
# (flock) by it: one whose process is gone and whose lock is free was left by a killed run.
_STAGING_PREFIX = '.partial-'
_STAGING_NAME = re.compile(r'\.partial-(\d+)-[a-z0-9_]+')


class BagError(RuntimeError):
    """A bag that cannot be read or written, with the reason."""


@dataclass(frozen=True)
class ScanRecord:
    """
    One LaserScan read from a bag.

    :ivar timestamp_ns: the bag's log time of the message, ns
    :ivar topic: topic it was recorded on
    :ivar scan: the message as rosbags read it (ROS 1 or ROS 2 fields of sensor_msgs/LaserScan;
        :func:`wctls_ros.conversions.laser_scan` copies it into an rclpy or rosbags ROS 2 one)
    """

    timestamp_ns: int
    topic: str
    scan: object


@dataclass(frozen=True)
class BagInfo:
    """
    What a bag holds.

    :ivar path: the bag that was opened (a storage file when the folder had no metadata.yaml)
    :ivar topics: topic -> (message type, message count), for every topic
    :ivar start_ns: log time of the first message, ns (0 for an empty bag)
    :ivar end_ns: log time of the last message, ns (0 for an empty bag)
    """

    path: pathlib.Path
    topics: dict
    start_ns: int
    end_ns: int

    def scan_topics(self) -> dict:
        """
        Return the LaserScan topics with their message counts.

        :return: topic -> count
        """
        return {topic: count for topic, (kind, count) in self.topics.items()
                if kind == LASER_SCAN}


def _resolve(path) -> pathlib.Path:
    """
    Return the path to open: a ROS 2 folder without metadata.yaml opens its one storage file.

    Only regular files are opened: reading a FIFO (or a device) would wait forever.
    """
    path = pathlib.Path(path)
    if not path.exists():
        raise BagError(f'no bag at {path}')
    if not path.is_dir():
        if not path.is_file():
            raise BagError(f'{path} is not a regular file or a folder (a FIFO, device or '
                           'socket): not a bag')
        return path
    parts = sorted(p for p in path.iterdir()
                   if p.suffix in _STORAGE_SUFFIXES or p.name == 'metadata.yaml')
    for part in parts:
        if not part.is_file():
            raise BagError(f'{part} is not a regular file (a FIFO, device, socket or folder): '
                           f'{path} is not a readable bag')
    if not (path / 'metadata.yaml').exists():
        files = [p for p in parts if p.suffix in _STORAGE_SUFFIXES]
        if len(files) != 1:
            raise BagError(f'{path} is a folder without metadata.yaml and with '
                           f'{len(files)} .mcap/.db3 files: not a ROS 2 bag')
        return files[0]
    return path


def _open(path) -> 'AnyReader':
    from rosbags.highlevel import AnyReader
    path = _resolve(path)
    try:
        reader = AnyReader([path], default_typestore=typestore())
        reader.open()
    except Exception as error:  # noqa: B902 - rosbags raises many types for a damaged bag
        raise BagError(f'cannot read {path} as a ROS 1 or ROS 2 bag (corrupt, truncated or '
                       f'another format): {error}') from error
    return reader


def _summary(reader: 'AnyReader') -> BagInfo:
    """Summarise an open bag."""
    topics = {}
    for connection in reader.connections:
        kind, count = topics.get(connection.topic, (connection.msgtype, 0))
        topics[connection.topic] = (kind, count + connection.msgcount)
    empty = not reader.message_count
    return BagInfo(pathlib.Path(reader.paths[0]), topics,
                   0 if empty else reader.start_time, 0 if empty else reader.end_time - 1)


def bag_info(path) -> BagInfo:
    """
    Summarise a bag: its topics with types and counts, and its time span.

    :param path: a ROS 2 bag folder (or its .mcap/.db3 file) or a ROS 1 .bag file
    :return: the summary
    :raises BagError: when the path is missing or not a readable bag
    """
    reader = _open(path)
    try:
        return _summary(reader)
    finally:
        reader.close()


def scan_topics(path) -> dict:
    """
    List the LaserScan topics of a bag with their message counts.

    :param path: a ROS 2 bag folder (or its .mcap/.db3 file) or a ROS 1 .bag file
    :return: topic -> message count
    :raises BagError: when the path is missing or not a readable bag
    """
    return bag_info(path).scan_topics()


def choose_scan_topic(path, topic: Optional[str] = None, info: Optional[BagInfo] = None) -> str:
    """
    Pick the LaserScan topic to read: the given one, or the only one in the bag.

    :param path: the bag
    :param topic: the requested topic, or None (or '') to find it
    :param info: the bag's summary when already read (saves opening the bag again)
    :return: the topic
    :raises BagError: when the bag has no LaserScan, several without a choice, not ``topic``, or
        a LaserScan topic without messages
    """
    info = info or bag_info(path)
    topics = info.scan_topics()
    if topic:
        if topic not in topics:
            if topic in info.topics:
                raise BagError(f'{path}: topic {topic} carries {info.topics[topic][0]}, not '
                               f'{LASER_SCAN}; LaserScan topics: {sorted(topics)}')
            raise BagError(f'{path} has no LaserScan topic {topic!r}; it has {sorted(topics)}')
    elif not topics:
        found = ', '.join(f'{name} ({kind})' for name, (kind, _) in sorted(info.topics.items()))
        raise BagError(f'{path} holds no {LASER_SCAN} messages (topics: {found or "none"})')
    elif len(topics) > 1:
        raise BagError(f'{path} has several LaserScan topics {sorted(topics)}: choose one')
    else:
        topic = next(iter(topics))
    if topics[topic] == 0:
        raise BagError(f'{path}: its LaserScan topic {topic} holds no messages')
    return topic


def read_scans(path, topic: Optional[str] = None,
               start_ns: Optional[int] = None) -> Iterator[ScanRecord]:
    """
    Yield the LaserScans of one topic in log-time order, one at a time (constant memory).

    :param path: a ROS 2 bag (sqlite3 or mcap) or a ROS 1 bag
    :param topic: the LaserScan topic, or None for the bag's only one
    :param start_ns: skip messages logged before this time, ns (None: from the start)
    :return: iterator of records
    :raises BagError: on a missing, corrupt or truncated bag, or no LaserScan topic
    """
    reader = _open(path)
    count = 0
    try:
        topic = choose_scan_topic(path, topic, _summary(reader))
        connections = [c for c in reader.connections if c.topic == topic]
        try:
            for connection, timestamp, raw in reader.messages(connections=connections,
                                                              start=start_ns):
                record = ScanRecord(timestamp, topic, reader.deserialize(raw, connection.msgtype))
                count += 1
                yield record
        except BagError:
            raise
        except Exception as error:  # noqa: B902 - a truncated bag fails deep inside rosbags
            raise BagError(f'{path} is damaged after {count} messages of {topic}: '
                           f'{error}') from error
    finally:
        reader.close()


def _lock_folder(path: pathlib.Path) -> Optional[int]:
    """Take the exclusive lock of a folder without waiting; return its descriptor, or None."""
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return None
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(descriptor)
        return None
    return descriptor


def _process_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:     # another user's process
        return True
    return True


def remove_stale_staging(folder) -> list:
    """
    Remove what killed writers (SIGKILL, a crash, a power cut) left in a folder.

    A staging folder is stale when the process named in it is gone and nothing holds its lock;
    the folder of a live writer is never touched.

    :param folder: the folder where bags are written
    :return: the staging folders removed
    """
    removed = []
    try:
        candidates = [p for p in pathlib.Path(folder).iterdir()
                      if p.name.startswith(_STAGING_PREFIX)]
    except OSError:             # not listable: nothing we could clean
        return removed
    for path in candidates:
        match = _STAGING_NAME.fullmatch(path.name)
        if match is None or _process_exists(int(match[1])):
            continue
        lock = _lock_folder(path)
        if lock is not None:
            try:
                shutil.rmtree(path, ignore_errors=True)
                removed.append(path)
            finally:
                os.close(lock)
    return removed


class BagWriter:
    """
    Write a ROS 2 bag of rosbags or rclpy messages; the bag appears only when closed without error.

    An OSError while the bag is open (a write to the bag or to a side file that meets a full
    disk or a file-size limit) or while it is closed leaves nothing and becomes a BagError that
    names the bag. Use as a context manager::

        with BagWriter('out/run') as bag:
            bag.write('/scan', timestamp_ns, scan_msg)
            bag.sidecar('corners.csv').write_text(...)   # a file shipped inside the bag folder
    """

    def __init__(self, path, storage: str = 'mcap', overwrite: bool = False):
        """
        Prepare the bag (nothing appears at ``path`` until it is closed without error).

        :param path: the bag folder to create
        :param storage: 'mcap' (default; Foxglove opens it directly) or 'sqlite3'
        :param overwrite: replace an existing ``path`` (only once the new bag is complete)
        :raises BagError: when ``path`` exists and ``overwrite`` is false, or a bad storage
        """
        self.path = pathlib.Path(path)
        if storage not in _STORAGES:
            raise BagError(f'storage must be one of {list(_STORAGES)}, got {storage!r}')
        if self.path.exists() and not overwrite:
            raise BagError(f'{self.path} exists: refusing to overwrite it')
        self._storage = storage
        self._staging = None
        self._lock = None
        self._writer = None
        self._connections = {}

    def __enter__(self) -> 'BagWriter':
        from rosbags.rosbag2 import StoragePlugin, Writer
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            remove_stale_staging(self.path.parent)
            self._staging = pathlib.Path(tempfile.mkdtemp(
                prefix=f'{_STAGING_PREFIX}{os.getpid()}-', dir=self.path.parent))
            self._lock = _lock_folder(self._staging)
            self._writer = Writer(self._staging / self.path.name, version=9,
                                  storage_plugin=StoragePlugin[_STORAGES[self._storage]])
            self._writer.open()
        except Exception as error:  # noqa: B902 - rosbags and the file system raise many types
            self._remove_staging()
            raise BagError(f'cannot write {self.path}: {error}') from error
        return self

    def _remove_staging(self) -> None:
        """Remove the staging folder, then release its lock."""
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
        if self._lock is not None:
            os.close(self._lock)
        self._staging = self._lock = None

    def write(self, topic: str, timestamp_ns: int, message) -> None:
        """
        Append one message on a topic: a rosbags message or an rclpy one.

        :param topic: the topic; its type is taken from the first message written on it
        :param timestamp_ns: log time, ns
        :param message: a rosbags message (serialised by rosbags) or an rclpy message
            (serialised by rclpy)
        """
        msgtype = getattr(message, '__msgtype__', None)
        if msgtype is None:         # rclpy: the module is <package>.msg._<name>
            from rclpy.serialization import serialize_message
            msgtype = f'{type(message).__module__.split(".")[0]}/msg/{type(message).__name__}'
            data = serialize_message(message)
        else:
            data = typestore().serialize_cdr(message, msgtype)
        self.write_serialized(topic, msgtype, timestamp_ns, data)

    def write_serialized(self, topic: str, msgtype: str, timestamp_ns: int, data) -> None:
        """
        Append one message already serialised (CDR) on a topic.

        :param topic: the topic; its type is taken from the first message written on it
        :param msgtype: the message type, e.g. 'wctls_msgs/msg/CornerArray'
        :param timestamp_ns: log time, ns
        :param data: the serialised message
        """
        connection = self._connections.get(topic)
        if connection is None:
            connection = self._writer.add_connection(topic, msgtype, typestore=typestore())
            self._connections[topic] = connection
        self._writer.write(connection, int(timestamp_ns), data)

    def sidecar(self, name: str) -> pathlib.Path:
        """
        Return where to write an extra file that is shipped inside the bag folder.

        The file appears together with the bag (or not at all); ROS bag readers ignore it.

        :param name: a file name (no folders)
        :return: its path in the staging folder, valid until the writer is closed
        :raises BagError: for a name with folders in it or the bag's own metadata.yaml
        """
        if pathlib.Path(name).name != name or name in ('metadata.yaml', ''):
            raise BagError(f'not a usable side file name: {name!r}')
        return self._staging / self.path.name / name

    def __exit__(self, kind, value, traceback):
        try:
            if kind is None:
                self._writer.close()
                if self.path.exists():  # overwrite: the old bag goes with the staging folder
                    self.path.rename(self._staging / '.replaced')
                (self._staging / self.path.name).rename(self.path)
            else:
                with contextlib.suppress(OSError):   # flushing what is thrown away may fail too
                    self._writer.abort()
        except OSError as error:
            value = error
        finally:
            self._remove_staging()
        if isinstance(value, OSError):
            raise BagError(f'cannot write {self.path}: {value.strerror or value}') from value
        return False
