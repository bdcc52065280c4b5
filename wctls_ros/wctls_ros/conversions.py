# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The codec between the core and ROS messages: LaserScan checks, Features to wctls_msgs and markers.

Pure: it builds message objects and never publishes or writes. One code path serves the live
node, which builds rclpy messages, and the offline bag tools, which build rosbags messages (from
a typestore, serialised by rosbags): every builder takes the :class:`MessageTypes` to build
with (rclpy's by default). Importing this module imports neither rclpy nor any message package.
"""

import array
import functools
import importlib
import math
import pathlib
from typing import Any, Callable, Dict, Optional

import numpy as np

from .core import CornerSet, ellipse, extract_features, FeatureConfig, Features, SegmentSet
from .frontend.dock import DockPose
from .params import MarkerStyle

# The message types the codec reads and builds.
MESSAGE_TYPES = (
    'builtin_interfaces/msg/Duration', 'builtin_interfaces/msg/Time',
    'geometry_msgs/msg/Point', 'geometry_msgs/msg/Pose', 'geometry_msgs/msg/PoseWithCovariance',
    'geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/PoseWithCovarianceStamped',
    'geometry_msgs/msg/Quaternion', 'geometry_msgs/msg/Vector3',
    'sensor_msgs/msg/CompressedImage', 'sensor_msgs/msg/LaserScan',
    'std_msgs/msg/ColorRGBA', 'std_msgs/msg/Header',
    'visualization_msgs/msg/Marker', 'visualization_msgs/msg/MarkerArray',
    'visualization_msgs/msg/MeshFile',
    'wctls_msgs/msg/Corner', 'wctls_msgs/msg/CornerArray', 'wctls_msgs/msg/LineSegment',
    'wctls_msgs/msg/LineSegmentArray',
    'wctls_msgs/msg/Landmark', 'wctls_msgs/msg/LandmarkArray',
)
MESSAGE_PACKAGE = 'wctls_msgs'
# Rows/columns of (x, y, yaw) in a geometry_msgs 6x6 pose covariance (x, y, z, roll, pitch, yaw).
_POSE_INDEX = np.array([0, 1, 5])
# Height of the flat cylinders that draw covariance ellipses, m.
_ELLIPSE_THICKNESS_M = 0.005
# Opacity of the segments that are not line landmarks among the markers (the landmarks: 1).
_OTHER_SEGMENT_ALPHA = 0.35


def _float32_array_for_rclpy(values) -> array.array:
    """Return float32 values as the array.array that rclpy messages take without copying."""
    out = array.array('f')
    out.frombytes(np.ascontiguousarray(values, dtype=np.float32).tobytes())
    return out


def _float32_array_for_rosbags(values) -> np.ndarray:
    """Return float32 values as the numpy array that rosbags serialises."""
    return np.asarray(values, dtype=np.float32)


class MessageTypes:
    """
    The message classes the codec builds with, by type name (``types.Corner``, ...).

    Made from rclpy's message packages (:meth:`from_rclpy`) or from a rosbags typestore
    (:meth:`from_typestore`); both take the same field values, except that a float32 sequence
    is held as :attr:`float32_array` makes it. Either serialises its messages to CDR bytes,
    which an rclpy publisher publishes as they are and a bag stores: rosbags' classes build
    and serialise in a fraction of the time rclpy's take (see docs/results/message_path.md),
    so the node and the bag tools both build with them.

    :ivar float32_array: turns a float32 sequence into what the message classes hold
    :ivar serialize: turns a message of these classes into its CDR bytes (with the
        encapsulation header, as ``rclpy.serialization.serialize_message`` gives)
    :ivar deserialize: turns CDR bytes and a ROS type name into a message of these classes
    """

    def __init__(self, classes: Dict[str, type], float32_array: Callable,
                 serialize: Callable[[object], bytes],
                 deserialize: Callable[[bytes, str], object]):
        """
        Name the classes.

        :param classes: ROS type name (one of MESSAGE_TYPES) -> class
        :param float32_array: turns a float32 sequence into what the classes hold
        :param serialize: turns a message of these classes into its CDR bytes
        :param deserialize: turns CDR bytes and a type name into a message of these classes
        """
        for name, kind in classes.items():
            setattr(self, name.rsplit('/', 1)[1], kind)
        self.float32_array = float32_array
        self.serialize = serialize
        self.deserialize = deserialize

    def __getattr__(self, name: str) -> Any:
        """
        Refuse a type that is not one of MESSAGE_TYPES (the others are attributes already).

        Also tells a type checker that ``types.Corner`` and the like exist.

        :param name: the short type name asked for
        :raises AttributeError: always: the type is not one the codec builds
        """
        raise AttributeError(f'{name} is not one of the message types the codec builds')

    @classmethod
    def from_rclpy(cls) -> 'MessageTypes':
        """
        Return the classes of rclpy's message packages (imported now).

        :return: the types
        """
        from rclpy.serialization import deserialize_message, serialize_message
        classes = {}
        for name in MESSAGE_TYPES:
            package, _, kind = name.split('/')
            classes[name] = getattr(importlib.import_module(f'{package}.msg'), kind)

        def deserialize(data: bytes, name: str):
            return deserialize_message(data, classes[name])
        return cls(classes, _float32_array_for_rclpy, serialize_message, deserialize)

    @classmethod
    def from_typestore(cls, store) -> 'MessageTypes':
        """
        Return the classes of a rosbags typestore (which must know wctls_msgs).

        rosbags makes a type's (de)serialiser at its first use: they are all made now, so
        that the first message is not slow and worker processes forked later inherit them.

        :param store: a rosbags Typestore
        :return: the types
        """
        for name in MESSAGE_TYPES:
            store.get_msgdef(name)

        def serialize(message) -> bytes:
            return bytes(store.serialize_cdr(message, message.__msgtype__))
        return cls({name: store.types[name] for name in MESSAGE_TYPES},
                   _float32_array_for_rosbags, serialize, store.deserialize_cdr)


def mismatched_types(store, published: Dict[str, str]) -> list:
    """
    Name the types whose definition in a rosbags typestore is not the one a ROS install uses.

    Messages serialised with the typestore's definitions are read correctly only where the
    definitions agree, which their RIHS01 type hashes tell (rclpy reports a publisher's in
    ``get_publishers_info_by_topic``).

    :param store: a rosbags Typestore
    :param published: ROS type name -> its type hash in the ROS install (``RIHS01_...``)
    :return: the names (sorted) whose definition differs or that the typestore lacks
    """
    mismatched = []
    for name, type_hash in published.items():
        try:
            known = store.hash_rihs01(name)
        except KeyError:
            known = None
        if known != type_hash:
            mismatched.append(name)
    return sorted(mismatched)


@functools.lru_cache(maxsize=1)
def typestore():
    """
    Return rosbags' ROS 2 Jazzy typestore with the wctls_msgs types registered.

    rosbags is imported now: the bag tools need it, the node only uses it when it is installed.

    :return: a rosbags Typestore
    :raises ImportError: when rosbags is not installed
    :raises LookupError: when the wctls_msgs .msg files cannot be found
    """
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores
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
        source = pathlib.Path(__file__).resolve().parents[2] / MESSAGE_PACKAGE / 'msg'
        if source.is_dir():
            return source
    raise LookupError(f'cannot find the {MESSAGE_PACKAGE} message definitions: source the '
                      'workspace (install/setup.bash) first')


@functools.lru_cache(maxsize=1)
def rclpy_types() -> MessageTypes:
    """
    Return the rclpy message classes (imported at the first call).

    :return: the types
    """
    return MessageTypes.from_rclpy()


def scan_problems(scan) -> list:
    """
    List what makes a LaserScan unusable (empty when it is fine).

    NaN and +-inf ranges are not problems: REP-117 uses them for invalid returns.

    :param scan: a sensor_msgs/LaserScan (rclpy or rosbags)
    :return: human-readable problems
    """
    problems = []
    count = len(scan.ranges)
    if count == 0:
        problems.append('it has no beams')
    if len(scan.intensities) not in (0, count):
        problems.append(f'{len(scan.intensities)} intensities for {count} ranges')
    fields = ('angle_min', 'angle_max', 'angle_increment', 'range_min', 'range_max')
    bad = [f for f in fields if not math.isfinite(getattr(scan, f))]
    if bad:
        problems.append('non-finite ' + ', '.join(bad))
        return problems
    if scan.angle_increment == 0.0 and count > 1:
        problems.append('angle_increment is 0')
    elif count > 1:
        last = scan.angle_min + (count - 1) * scan.angle_increment
        if abs(last - scan.angle_max) > 0.5 * abs(scan.angle_increment) + 1e-6:
            problems.append(f'angle_max {scan.angle_max:.6f} disagrees with angle_min + '
                            f'(N - 1) * angle_increment = {last:.6f}')
    if not 0.0 <= scan.range_min < scan.range_max:
        problems.append(f'range limits [{scan.range_min}, {scan.range_max}] are not ordered')
    return problems


def scan_features(scan, config: FeatureConfig):
    """
    Extract the features of a LaserScan, or explain why it cannot be used.

    :param scan: a sensor_msgs/LaserScan (rclpy or rosbags)
    :param config: the pipeline configuration
    :return: (Features, problems): empty features and the reasons when the scan is unusable
    """
    problems = scan_problems(scan)
    if not problems:
        try:
            return extract_features(np.asarray(scan.ranges, dtype=float), scan.angle_min,
                                    scan.angle_increment, config, scan.range_min,
                                    scan.range_max), problems
        except ValueError as error:
            problems = [str(error)]
    return Features(config.method, SegmentSet.empty(), CornerSet.empty()), problems


def copy_header(source, types: Optional[MessageTypes] = None):
    """
    Copy a header (rclpy, rosbags, ROS 1 or ROS 2) into a ``types.Header``.

    :param source: the header to copy (a ROS 1 header's seq is dropped)
    :param types: the message classes to build with (None: rclpy's)
    :return: the header
    """
    types = types or rclpy_types()
    stamp = source.stamp
    return types.Header(stamp=types.Time(sec=int(stamp.sec), nanosec=int(stamp.nanosec)),
                        frame_id=str(source.frame_id))


def laser_scan(scan, types: Optional[MessageTypes] = None):
    """
    Copy a LaserScan (rclpy, rosbags, ROS 1 or ROS 2) into a ``types.LaserScan``.

    :param scan: the scan to copy
    :param types: the message classes to build with (None: rclpy's)
    :return: the scan, with the same header (a ROS 1 header's seq is dropped)
    """
    types = types or rclpy_types()
    return types.LaserScan(
        header=copy_header(scan.header, types), angle_min=float(scan.angle_min),
        angle_max=float(scan.angle_max), angle_increment=float(scan.angle_increment),
        time_increment=float(scan.time_increment), scan_time=float(scan.scan_time),
        range_min=float(scan.range_min), range_max=float(scan.range_max),
        ranges=types.float32_array(scan.ranges),
        intensities=types.float32_array(scan.intensities))


def pose_covariances(covariance_xy_yaw: np.ndarray) -> np.ndarray:
    """
    Lay out (x, y, yaw) covariances as row-major 6x6 pose covariances.

    :param covariance_xy_yaw: shape (C, 3, 3)
    :return: shape (C, 36); the z, roll and pitch rows and columns are 0
    """
    full = np.zeros((len(covariance_xy_yaw), 6, 6))
    full[:, _POSE_INDEX[:, None], _POSE_INDEX[None, :]] = covariance_xy_yaw
    return full.reshape(-1, 36)


def corner_array(features: Features, header, types: Optional[MessageTypes] = None):
    """
    Convert the corners of one scan to a CornerArray.

    Every field is computed for all corners at once, in numpy, and read out as Python numbers
    (``tolist``), so that the one Python step per corner is building its messages.

    :param features: output of ``extract_features``
    :param header: the scan's header, a ``types.Header`` (shared, not copied)
    :param types: the message classes to build with (None: rclpy's)
    :return: the message
    """
    types = types or rclpy_types()
    Corner, Point, Quaternion = types.Corner, types.Point, types.Quaternion
    PoseWithCovariance, Pose = types.PoseWithCovariance, types.Pose
    corners, segments = features.corners, features.segments
    walls = np.stack([corners.first_segment, corners.second_segment], axis=1)
    half_yaw = 0.5 * corners.yaw_rad      # a turn about z: (0, 0, sin(yaw / 2), cos(yaw / 2))
    messages = [
        Corner(pose=PoseWithCovariance(
            pose=Pose(position=Point(x=x, y=y, z=0.0),
                      orientation=Quaternion(x=0.0, y=0.0, z=qz, w=qw)),
            covariance=covariance),
            first_line=first, second_line=second, opening_angle=opening,
            first_line_points=first_points, second_line_points=second_points,
            first_line_chi2_dof=first_chi2, second_line_chi2_dof=second_chi2,
            first_end_seen=first_seen, second_end_seen=second_seen)
        for (x, y), qz, qw, covariance, opening, (first, second), (first_points, second_points),
        (first_chi2, second_chi2), (first_seen, second_seen) in zip(
            corners.xy_m.tolist(), np.sin(half_yaw).tolist(), np.cos(half_yaw).tolist(),
            pose_covariances(corners.covariance), corners.opening_angle_rad.tolist(),
            walls.tolist(), segments.num_points[walls].tolist(),
            segments.residual_chi2_dof[walls].tolist(), corners.end_seen.tolist())]
    return types.CornerArray(header=header, method=features.method, corners=messages)


def _one_flag_per_segment(is_landmark: np.ndarray, segments: SegmentSet) -> np.ndarray:
    """
    Return the line landmark flags as one bool per segment.

    :param is_landmark: the flags, shape (S,)
    :param segments: the scan's segments (S of them)
    :return: the flags, shape (S,), bool
    :raises ValueError: when is_landmark does not give one flag per segment (a wrong length
        would index the wrong segments, a scalar would select all or none)
    """
    flags = np.asarray(is_landmark, dtype=bool)
    if flags.shape != (len(segments),):
        raise ValueError(f'{flags.shape} landmark flags for {len(segments)} segments')
    return flags


def line_segment_array(features: Features, header, types: Optional[MessageTypes] = None, *,
                       is_landmark: np.ndarray):
    """
    Convert the segments of one scan to a LineSegmentArray (built as :func:`corner_array`).

    Every segment goes in, in scan order, so that the corners' wall indices index it; each
    carries its line landmark flag.

    :param features: output of ``extract_features``
    :param header: the scan's header, a ``types.Header`` (shared, not copied)
    :param types: the message classes to build with (None: rclpy's)
    :param is_landmark: which segments are line landmarks, shape (S,), bool
        (:func:`~wctls_ros.core.line_landmarks`)
    :return: the message
    :raises ValueError: when is_landmark does not give one flag per segment
    """
    types = types or rclpy_types()
    LineSegment, Point = types.LineSegment, types.Point
    s = features.segments
    is_landmark = _one_flag_per_segment(is_landmark, s)
    messages = [
        LineSegment(angle=angle, radius=radius, covariance=covariance,
                    start=Point(x=start_x, y=start_y, z=0.0), end=Point(x=end_x, y=end_y, z=0.0),
                    first_index=first, last_index=last, num_points=count,
                    residual_chi2_dof=chi2_dof, landmark=landmark)
        for angle, radius, covariance, (start_x, start_y), (end_x, end_y), first, last, count,
        chi2_dof, landmark in zip(
            s.angle_rad.tolist(), s.radius_m.tolist(),
            np.ascontiguousarray(s.covariance, dtype=float).reshape(-1, 4),
            s.start_xy_m.tolist(), s.end_xy_m.tolist(), s.first_index.tolist(),
            s.last_index.tolist(), s.num_points.tolist(), s.residual_chi2_dof.tolist(),
            is_landmark.tolist())]
    return types.LineSegmentArray(header=header, method=features.method, segments=messages)


def unused_marker_fields(types: MessageTypes) -> dict:
    """
    Return the Marker fields we never use, at their defaults (rosbags needs every field).

    :param types: the message classes
    :return: field name -> default value
    """
    no_bytes = np.zeros(0, np.uint8)
    no_header = types.Header(stamp=types.Time(sec=0, nanosec=0), frame_id='')
    return {'lifetime': types.Duration(sec=0, nanosec=0), 'frame_locked': False, 'colors': [],
            'texture_resource': '',
            'texture': types.CompressedImage(header=no_header, format='', data=no_bytes),
            'uv_coordinates': [], 'mesh_resource': '',
            'mesh_file': types.MeshFile(filename='', data=no_bytes),
            'mesh_use_embedded_materials': False}


def marker_array(features: Features, header, style: MarkerStyle = MarkerStyle(),
                 types: Optional[MessageTypes] = None, *, is_landmark: np.ndarray):
    """
    Draw one scan's features: segments, corners with ids, and covariance ellipses.

    The array starts with a DELETEALL marker, so features of earlier scans never linger. The
    line landmarks are one LINE_LIST (namespace ``segments``, id 0, opaque), the other segments
    another (id 1, the same colour at :data:`_OTHER_SEGMENT_ALPHA`), all corners one
    SPHERE_LIST; each corner's k-sigma covariance
    ellipse is one flat CYLINDER scaled to its axes and turned to its orientation (as RViz draws
    covariances) and, with ``style.text_ids``, its index one TEXT_VIEW_FACING marker. Markers
    of one array share sub-messages (header, colours, scales): change a copy, not them.

    :param features: output of ``extract_features``
    :param header: the scan's header, a ``types.Header`` (shared, not copied)
    :param style: sizes, the ellipse scale, whether corners get id labels
    :param types: the message classes to build with (None: rclpy's)
    :param is_landmark: which segments are line landmarks, shape (S,), bool
        (:func:`~wctls_ros.core.line_landmarks`)
    :return: the markers
    :raises ValueError: when is_landmark does not give one flag per segment
    """
    types = types or rclpy_types()
    Marker, Point, Pose, Quaternion = types.Marker, types.Point, types.Pose, types.Quaternion
    Vector3, ColorRGBA = types.Vector3, types.ColorRGBA
    # What the markers of each kind have alike; each marker adds its id, pose and what varies.
    alike = dict(unused_marker_fields(types), header=header, action=Marker.ADD)
    upright = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    at_origin = Pose(position=Point(x=0.0, y=0.0, z=0.0), orientation=upright)
    no_scale = Vector3(x=0.0, y=0.0, z=0.0)
    markers = [Marker(**dict(alike, action=Marker.DELETEALL), ns='', id=0, type=Marker.ARROW,
                      pose=at_origin, scale=no_scale, color=ColorRGBA(r=0.0, g=0.0, b=0.0, a=0.0),
                      points=[], text='')]
    segments, corners = features.segments, features.corners
    is_landmark = _one_flag_per_segment(is_landmark, segments)
    line_width = Vector3(x=style.line_width_m, y=0.0, z=0.0)
    for marker_id, (drawn, alpha) in enumerate(((is_landmark, 1.0),
                                                (~is_landmark, _OTHER_SEGMENT_ALPHA))):
        if not drawn.any():
            continue
        ends = np.stack([segments.start_xy_m[drawn], segments.end_xy_m[drawn]],
                        1).reshape(-1, 2).tolist()
        markers.append(Marker(
            **alike, ns='segments', id=marker_id, type=Marker.LINE_LIST, pose=at_origin,
            scale=line_width, color=ColorRGBA(r=0.1, g=0.5, b=1.0, a=alpha),
            points=[Point(x=x, y=y, z=0.0) for x, y in ends], text=''))
    if not len(corners):
        return types.MarkerArray(markers=markers)
    size = style.corner_size_m
    markers.append(Marker(
        **alike, ns='corners', id=0, type=Marker.SPHERE_LIST, pose=at_origin,
        scale=Vector3(x=size, y=size, z=size), color=ColorRGBA(r=1.0, g=0.2, b=0.2, a=1.0),
        points=[Point(x=x, y=y, z=0.0) for x, y in corners.xy_m.tolist()], text=''))
    label_fields = dict(alike, ns='corner_ids', type=Marker.TEXT_VIEW_FACING, points=[],
                        scale=Vector3(x=0.0, y=0.0, z=2.0 * size),
                        color=ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0))
    ellipse_fields = dict(alike, ns='ellipses', type=Marker.CYLINDER, points=[], text='',
                          color=ColorRGBA(r=1.0, g=0.6, b=0.0, a=0.5))
    shape = ellipse(corners.covariance[:, :2, :2])
    diameter = 2.0 * style.ellipse_sigma * style.ellipse_scale
    half_turn = 0.5 * shape.orientation_rad
    rows = np.column_stack([corners.xy_m, diameter * shape.semi_major,
                            diameter * shape.semi_minor, np.sin(half_turn),
                            np.cos(half_turn)]).tolist()
    for i, (x, y, major_axis, minor_axis, qz, qw) in enumerate(rows):
        if style.text_ids:
            markers.append(Marker(**label_fields, id=i, text=str(i), pose=Pose(
                position=Point(x=x, y=y, z=2.0 * size), orientation=upright)))
        # A flat elliptic cylinder: one marker per ellipse, no outline points to send.
        markers.append(Marker(
            **ellipse_fields, id=i,
            pose=Pose(position=Point(x=x, y=y, z=0.0),
                      orientation=Quaternion(x=0.0, y=0.0, z=qz, w=qw)),
            scale=Vector3(x=major_axis, y=minor_axis, z=_ELLIPSE_THICKNESS_M)))
    return types.MarkerArray(markers=markers)


def dock_pose_messages(dock: DockPose, header, types: Optional[MessageTypes] = None) -> tuple:
    """
    Convert a dock detection to the PoseStamped Nav2's docking server takes, and its covariance.

    :param dock: the detection, in the scan's frame
    :param header: the scan's header, a ``types.Header`` (shared, not copied)
    :param types: the message classes to build with (None: rclpy's)
    :return: (PoseStamped, PoseWithCovarianceStamped), both with ``header``
    """
    types = types or rclpy_types()
    half_yaw = 0.5 * dock.yaw_rad          # a turn about z: (0, 0, sin(yaw / 2), cos(yaw / 2))
    pose = types.Pose(position=types.Point(x=dock.x_m, y=dock.y_m, z=0.0),
                      orientation=types.Quaternion(x=0.0, y=0.0, z=math.sin(half_yaw),
                                                   w=math.cos(half_yaw)))
    covariance = pose_covariances(dock.covariance[None])[0]
    return (types.PoseStamped(header=header, pose=pose),
            types.PoseWithCovarianceStamped(header=header, pose=types.PoseWithCovariance(
                pose=pose, covariance=covariance)))


def dock_marker(dock: DockPose, header, types: Optional[MessageTypes] = None):
    """
    Draw a dock detection as an arrow along its x axis, in a MarkerArray of its own.

    Published after the scan's features, whose array starts with DELETEALL: the arrow shows
    until the next scan's features, so only while the dock is seen (namespace ``dock``).

    :param dock: the detection, in the scan's frame
    :param header: the scan's header, a ``types.Header`` (shared, not copied)
    :param types: the message classes to build with (None: rclpy's)
    :return: the markers
    """
    types = types or rclpy_types()
    pose = dock_pose_messages(dock, header, types)[0].pose
    return types.MarkerArray(markers=[types.Marker(
        **unused_marker_fields(types), header=header, action=types.Marker.ADD, ns='dock', id=0,
        type=types.Marker.ARROW, pose=pose, scale=types.Vector3(x=0.3, y=0.03, z=0.03),
        color=types.ColorRGBA(r=0.6, g=0.2, b=0.8, a=1.0), points=[], text='')])
