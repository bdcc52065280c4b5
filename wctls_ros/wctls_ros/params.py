# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The one parameter schema of wctls_ros: every node's parameters, and the checks of their files.

Each parameter is a :class:`Parameter` row (name, type by its default, default, range,
description, read-only or not). The nodes declare theirs from here (with ranges as ROS
descriptors, :func:`wctls_ros.node_main.declare_parameters`), the offline tools read and check
parameter files with :func:`load_parameters` exactly as the node would accept them, and the
documented parameter tables are printed by ``python -m wctls_ros.params`` (``--write
docs/user_guide.md`` regenerates them there). feature_node's pipeline parameters are derived
from :class:`~wctls_ros.core.FeatureConfig` itself (its fields' descriptions and limits), so a
limit is stated once. Pure Python: no rclpy import.
"""

import argparse
from dataclasses import dataclass, fields, replace
import math
import pathlib
import re
import sys
from typing import Any, Callable, Dict, NamedTuple, Optional, Tuple, Union

import yaml

from .core import FeatureConfig, METHODS
from .core.config import field_description, field_limits, Limits
from .frontend.dock import DockShape, TrackSettings
from .frontend.odometry import OdometryConfig
from .frontend.wheel import WheelModel
from .plain_yaml import load_without_aliases
from .sensors import DEFAULT_SENSOR, PRESET_PARAMETERS, sensor_presets

Value = Union[bool, int, float, str]
# Parameters every node has (or that rclpy adds) which a parameter file may set for any node.
_COMMON = ('use_sim_time',)
_COMMON_PREFIXES = ('qos_overrides.',)


class ConfigError(ValueError):
    """A parameter file or value that the node would refuse, with the reason."""


def _same(value):
    return value


@dataclass(frozen=True)
class Parameter:
    """
    One ROS parameter: its type (that of the default), default, range and meaning.

    :ivar name: the ROS parameter name
    :ivar default: the default value; its Python type is the parameter's type
    :ivar description: what it means, with its unit
    :ivar limits: the allowed interval for numbers (the ROS descriptor range is its closure),
        None for strings and booleans
    :ivar choices: the allowed values of a string (empty: any)
    :ivar read_only: fixed at start-up (restart the node to change it)
    :ivar setting: the settings field it fills (a FeatureConfig or MarkerStyle field), if any
    :ivar to_setting: converts the parameter's value to that field's unit (e.g. deg to rad)
    """

    name: str
    default: Value
    description: str
    limits: Optional[Limits] = None
    choices: Tuple[str, ...] = ()
    read_only: bool = False
    setting: Optional[str] = None
    to_setting: Callable = _same

    @property
    def type_name(self) -> str:
        """
        Return the ROS type of the parameter.

        :return: 'bool', 'integer', 'double' or 'string'
        """
        kinds = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
        return kinds[type(self.default)]

    def check(self, value) -> Value:
        """
        Return a value as this parameter's type, refusing what rclpy would refuse.

        :param value: a value from a parameter file or a command line
        :return: the value (an integer given for a double becomes a float)
        :raises ConfigError: on a wrong type, a value outside the range, an unknown choice
        """
        default = self.default
        if isinstance(default, bool):
            ok = isinstance(value, bool)
        elif isinstance(default, int):
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif isinstance(default, float):
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
            value = float(value) if ok else value
        else:
            ok = isinstance(value, str)
        if not ok:
            raise ConfigError(f'{self.name} must be of type {self.type_name}, got {value!r}')
        if self.limits is not None and not self.limits.holds(value):
            raise ConfigError(f'{self.name} = {value!r} is outside its range '
                              f'{self.limits.describe()}')
        if self.choices and value not in self.choices:
            raise ConfigError(f'{self.name} must be one of {self.choices}, got {value!r}')
        return value


def _feature_parameter(name: str) -> Parameter:
    """
    Return the ROS parameter of a FeatureConfig field: angles in deg (``*_rad`` -> ``*_deg``).

    :param name: the field name
    :return: the parameter
    """
    default, limits = getattr(FeatureConfig(), name), field_limits(name)
    if name.endswith('_rad') and limits is not None:
        description = field_description(name, angle_unit='deg')
        degrees = math.degrees
        return Parameter(name[:-len('_rad')] + '_deg', round(degrees(default), 6),
                         description[0].upper() + description[1:],
                         limits._replace(low=degrees(limits.low), high=degrees(limits.high)),
                         setting=name, to_setting=math.radians)
    description = field_description(name)
    return Parameter(name, default, description[0].upper() + description[1:], limits,
                     METHODS if name == 'method' else (), setting=name)


@dataclass(frozen=True)
class MarkerStyle:
    """
    How features are drawn in RViz / Foxglove.

    :ivar ellipse_sigma: draw the k-sigma ellipse of each corner's position (1 = one sigma)
    :ivar ellipse_scale: extra magnification of the ellipses for visibility (the paper uses 10)
    :ivar line_width_m: width of the segment lines, m
    :ivar corner_size_m: diameter of the corner spheres and height of their id labels, m
    :ivar text_ids: label each corner with its index (a text marker per corner)
    """

    ellipse_sigma: float = 1.0
    ellipse_scale: float = 10.0
    line_width_m: float = 0.02
    corner_size_m: float = 0.06
    text_ids: bool = False


def _preset_parameter(parameter: Parameter) -> Parameter:
    """Return a parameter a sensor preset sets, with the default preset's value as default."""
    if parameter.name not in PRESET_PARAMETERS:
        return parameter
    return replace(parameter, default=sensor_presets()[DEFAULT_SENSOR].parameters[parameter.name],
                   description=f"{parameter.description} (default: the sensor preset's)")


SENSOR = 'sensor'
_STYLE = MarkerStyle()
FEATURE_NODE = (
    Parameter(SENSOR, DEFAULT_SENSOR, 'Sensor preset (config/sensors/<name>.yaml): its noise '
              f'model is the default of {", ".join(PRESET_PARAMETERS)}, which a parameter file '
              'or a command line may still set', choices=tuple(sensor_presets()),
              read_only=True),
) + tuple(_preset_parameter(_feature_parameter(f.name)) for f in fields(FeatureConfig)) + (
    Parameter('publish_markers', True, 'Publish visualization_msgs/MarkerArray on markers'),
    Parameter('marker_ellipse_sigma', _STYLE.ellipse_sigma,
              'Draw the k-sigma covariance ellipse of each corner', Limits(0.1, 10.0),
              setting='ellipse_sigma'),
    Parameter('marker_ellipse_scale', _STYLE.ellipse_scale,
              'Extra magnification of the drawn ellipses (the paper draws them x10)',
              Limits(0.1, 1000.0), setting='ellipse_scale'),
    Parameter('marker_line_width_m', _STYLE.line_width_m, 'Width of the segment lines, m',
              Limits(1e-4, 1.0), setting='line_width_m'),
    Parameter('marker_text_ids', _STYLE.text_ids,
              'Label each corner with its index (one text marker per corner: serialising it '
              "doubles the markers' cost, about 0.6x the core per scan, so off by default)",
              setting='text_ids'),
    Parameter('publish_landmarks', False,
              "Track the corners and line landmarks and publish every scan's, with their "
              'persistent ids, on landmarks (wctls_msgs/LandmarkArray; empty ones too)'),
    Parameter('landmark_step_sigma_m', 0.0,
              'With publish_landmarks: the sensor counts as still between scans, its unknown '
              'step this sigma in x and y (0: a sensor on a tripod), m', Limits(0.0, 10.0)),
    Parameter('landmark_step_sigma_deg', 0.0,
              'With publish_landmarks: the sigma of its unknown turn between scans, deg',
              Limits(0.0, 180.0)),
    Parameter('landmark_bridges', '',
              'With publish_landmarks: comma-separated bridges among rtabmap '
              '(rtabmap_msgs/LandmarkDetections on landmark_detections), cartographer '
              '(cartographer_ros_msgs/LandmarkList on landmark) and pose_array '
              '(geometry_msgs/PoseArray on landmark_poses); one whose package is not installed '
              'is left out with a warning', read_only=True),
)

# feature_node is a lifecycle node: whether it drives itself to active.
AUTOSTART = 'autostart'
FEATURE_NODE += (
    Parameter(AUTOSTART, True, 'Configure and activate at start (a plain ros2 run extracts at '
              'once); false waits for a lifecycle manager or launch file to drive the '
              'transitions', read_only=True),
)

# feature_node's dock detection (wctls_ros.frontend.dock; docs/docking.md).
DOCK_ENABLED = 'dock_enabled'
_DOCK, _TRACK = DockShape(), TrackSettings()
DOCK_PARAMETERS = (
    Parameter(DOCK_ENABLED, False, 'Look for a dock in every scan and offer the services that '
              'start and stop it; publish its pose on detected_dock_pose and '
              'detected_dock_pose_with_covariance', read_only=True),
    Parameter('dock_detect_at_start', True, 'Detection on from activation; false: off until '
              'the start_dock_detection or toggle_dock_detection service turns it on',
              read_only=True),
    Parameter('dock_right_face_m', _DOCK.right_face_m, "Length of the dock's face on the "
              "robot's right, apex to outer end, m", Limits(0.02, 5.0)),
    Parameter('dock_left_face_m', _DOCK.left_face_m, "Length of the dock's face on the robot's "
              'left, m', Limits(0.02, 5.0)),
    Parameter('dock_opening_angle_deg', math.degrees(_DOCK.opening_angle_rad), 'Angle between '
              "the dock's faces through the robot's side, deg: below 180 a V, above 180 a "
              'wedge, 90 an L', Limits(1.0, 359.0)),
    Parameter('dock_face_tolerance_m', _DOCK.face_tolerance_m, 'How much longer than its '
              'length a seen face may be, m', Limits(0.0, 1.0)),
    Parameter('dock_face_shortfall_m', _DOCK.face_shortfall_m, 'How much shorter a seen face '
              'may be, beyond the spacing of its returns, m', Limits(0.0, 1.0)),
    Parameter('dock_angle_tolerance_deg', math.degrees(_DOCK.angle_tolerance_rad), 'How much '
              'the seen opening angle may differ, deg', Limits(0.0, 45.0)),
    Parameter('dock_reference_x_m', 0.0, "The dock frame's origin in the apex frame (x along "
              'the axis, away from the robot), m', Limits(-5.0, 5.0)),
    Parameter('dock_reference_y_m', 0.0, "The dock frame's origin in the apex frame, y (left), "
              'm', Limits(-5.0, 5.0)),
    Parameter('dock_reference_yaw_deg', 0.0, "The dock frame's yaw in the apex frame, deg",
              Limits(-180.0, 180.0)),
    Parameter('dock_max_speed_m_s', _TRACK.max_speed_m_s, 'The fastest the dock may move in '
              "the scan's frame between detections (the tracker's gate), m/s",
              Limits(0.0, 10.0)),
    Parameter('dock_max_turn_rate_deg_s', math.degrees(_TRACK.max_turn_rate_rad_s), 'The '
              "fastest the dock's yaw may change between detections, deg/s",
              Limits(0.0, 720.0)),
    Parameter('dock_confirm_detections', _TRACK.confirm_detections, 'Agreeing detections in a '
              'row before a dock is published', Limits(1, 100)),
    Parameter('dock_timeout_s', _TRACK.timeout_s, 'A dock not seen for this long must be '
              'confirmed again, s', Limits(0.01, 60.0)),
)
FEATURE_NODE += DOCK_PARAMETERS


BAG_REPLAY = (
    Parameter('bag', '', 'ROS 2 bag folder (or its .mcap / .db3 file) or ROS 1 .bag file to '
              'play (required)', read_only=True),
    Parameter('topic', '', "LaserScan topic in the bag; empty: the bag's only LaserScan topic",
              read_only=True),
    Parameter('rate', 1.0, 'Playback speed: bag seconds per wall-clock second (changeable '
              'while playing)', Limits(0.01, 100.0)),
    Parameter('start_offset_s', 0.0, 'Start playing this far after the start of the bag, s',
              Limits(0.0, 1e7), read_only=True),
    Parameter('loop', False, 'Start again at the end of the bag (changeable while playing)'),
    Parameter('publish_clock', False, 'Publish the bag time on /clock (rosgraph_msgs/Clock) '
              'for nodes with use_sim_time', read_only=True),
    Parameter('clock_rate_hz', 40.0, 'How often /clock is published, Hz', Limits(1.0, 1000.0),
              read_only=True),
    Parameter('wait_for_subscribers', 0, 'Start playing once this many subscribers match scan '
              '(0: start at once)', Limits(0, 1000), read_only=True),
)


def _read_only(name: str, default: Value, description: str, limits: Optional[Limits] = None,
               choices: Tuple[str, ...] = ()) -> Parameter:
    """Return a parameter fixed at start-up."""
    return Parameter(name, default, description, limits, choices, read_only=True)


_ODOMETRY = OdometryConfig()
ODOMETRY_NODE = FEATURE_NODE[:1 + len(fields(FeatureConfig))] + (
    _read_only('odom_frame', 'odom', 'Frame of the published pose (REP-105)'),
    _read_only('base_frame', 'base_link', "The robot's frame: the child frame of the pose"),
    _read_only('publish_tf', False, 'Also publish the transform odom -> base_frame on /tf '
               '(off where another source, such as an EKF, publishes it)'),
    _read_only('laser_x_m', 0.0, "The laser's position on the robot (base_frame -> the scan's "
               'frame), x, m', Limits(-100.0, 100.0)),
    _read_only('laser_y_m', 0.0, "The laser's position on the robot, y, m",
               Limits(-100.0, 100.0)),
    _read_only('laser_yaw_deg', 0.0, "The laser's heading on the robot, deg",
               Limits(-180.0, 180.0)),
    _read_only('mount_from_tf', False, "Take the laser's pose on the robot from /tf_static "
               "(base_frame -> the scan's frame, through any static chain) instead of laser_x_m, "
               'laser_y_m and laser_yaw_deg; scans before it is known are left out'),
    Parameter('max_hypotheses', _ODOMETRY.max_hypotheses, 'Motion hypotheses scored per scan '
              'at most', Limits(1, 100000), setting='max_hypotheses'),
    Parameter('max_step_m', _ODOMETRY.max_step_m, 'Largest motion between two scans, m',
              Limits(0.01, 100.0), setting='max_step_m'),
    Parameter('keyframe_m', _ODOMETRY.keyframe_m, 'Match the scans against a keyframe until '
              'they lie this far from it, m (0 and keyframe_deg 0: scan to scan)',
              Limits(0.0, 100.0), setting='keyframe_m'),
    Parameter('keyframe_deg', round(math.degrees(_ODOMETRY.keyframe_rad), 6), '... or turned '
              'this far from it, deg', Limits(0.0, 180.0), setting='keyframe_rad',
              to_setting=math.radians),
    Parameter('degenerate_sigma_m', _ODOMETRY.degenerate_sigma_m, 'A step the landmarks know '
              'worse than this along some direction, m, is degenerate (the prior fills in)',
              Limits(1e-4, 10.0), setting='degenerate_sigma_m'),
    Parameter('degenerate_sigma_deg', round(math.degrees(_ODOMETRY.degenerate_sigma_rad), 6),
              'The same in rotation, deg', Limits(1e-3, 90.0), setting='degenerate_sigma_rad',
              to_setting=math.radians),
    Parameter('prior_sigma_m', _ODOMETRY.prior_sigma_m, "The constant-velocity prior's growth "
              'per scan, each axis, m', Limits(1e-4, 10.0), setting='prior_sigma_m'),
    Parameter('prior_sigma_deg', round(math.degrees(_ODOMETRY.prior_sigma_rad), 6),
              "The prior's growth per scan in yaw, deg", Limits(1e-3, 180.0),
              setting='prior_sigma_rad', to_setting=math.radians),
)

# The wheel odometry as the prior (docs/odometry.md#wheel-odometry-as-the-prior).
_WHEEL = WheelModel()
WHEEL_PARAMETERS = (
    _read_only('wheel_odometry_topic', '', "The robot's wheel odometry, nav_msgs/Odometry (the "
               'pose of base_frame in its own odom frame): its step between two scans, '
               'interpolated at their stamps, is the prior; empty: none (the constant '
               'velocity)'),
    _read_only('wheel_odometry_tf_frame', '', 'Take the wheel odometry from /tf instead: the '
               "transform from this frame (the wheel odometry's, e.g. odom) to base_frame; "
               'needs publish_tf false; empty: none'),
    _read_only('wheel_timeout_s', 0.5, 'A scan later than the newest wheel pose by more than '
               'this, or between two wheel poses further apart, has no wheel prior (the '
               'constant velocity fills in, counted on /diagnostics), s', Limits(0.001, 60.0)),
    _read_only('wheel_use_message_covariance', True, "The wheel step's covariance from the "
               "Odometry's twist covariance times the time between the scans squared (plus "
               'the floors below) where its x, y, yaw block is not zero; false: always the '
               'model below'),
    _read_only('wheel_sigma_per_m', _WHEEL.sigma_per_m, "The wheel step's std in x and y per "
               'metre travelled, m per m (sigma = this x distance + wheel_sigma_floor_m)',
               Limits(0.0, 10.0)),
    _read_only('wheel_sigma_floor_m', _WHEEL.floor_m, "The wheel step's std in x and y of "
               'every step, m', Limits(1e-6, 10.0)),
    _read_only('wheel_sigma_per_rad', _WHEEL.sigma_per_rad, "The wheel step's yaw std per "
               'radian turned, rad per rad (sigma = this x turn + wheel_sigma_floor_deg)',
               Limits(0.0, 10.0)),
    _read_only('wheel_sigma_floor_deg', round(math.degrees(_WHEEL.floor_rad), 6),
               "The wheel step's yaw std of every step, deg", Limits(1e-4, 90.0)),
)
ODOMETRY_NODE += WHEEL_PARAMETERS

SCHEMAS = {'feature_node': FEATURE_NODE, 'bag_replay': BAG_REPLAY,
           'odometry_node': ODOMETRY_NODE}


class WheelSettings(NamedTuple):
    """
    Where odometry_node takes the wheel odometry from, and its step's covariance.

    :ivar topic: the nav_msgs/Odometry topic ('' : not a topic)
    :ivar tf_frame: the frame whose transform to base_frame on /tf is the wheel's pose ('':
        not from TF)
    :ivar timeout_s: the longest gap the wheel's poses may leave, s
    :ivar use_message_covariance: take the covariance from the message where it states one
    :ivar model: the covariance otherwise
    """

    topic: str
    tf_frame: str
    timeout_s: float
    use_message_covariance: bool
    model: WheelModel

    @property
    def enabled(self) -> bool:
        """
        Return whether a wheel odometry is read.

        :return: True with a topic or a TF frame
        """
        return bool(self.topic or self.tf_frame)


class OdometrySettings(NamedTuple):
    """
    What odometry_node's parameters configure.

    :ivar config: the pipeline configuration
    :ivar odometry: the odometry's settings
    :ivar mount: the laser's pose on the robot (x m, y m, yaw rad)
    :ivar odom_frame: the pose's frame
    :ivar base_frame: the robot's frame
    :ivar publish_tf: whether the transform odom -> base_frame is published
    :ivar mount_from_tf: whether the mount comes from /tf_static instead of ``mount``
    :ivar wheel: the wheel odometry as the prior
    """

    config: FeatureConfig
    odometry: OdometryConfig
    mount: Tuple[float, float, float]
    odom_frame: str
    base_frame: str
    publish_tf: bool
    mount_from_tf: bool
    wheel: WheelSettings


def odometry_settings(values: Dict[str, Value]) -> OdometrySettings:
    """
    Build odometry_node's validated settings from its parameter values.

    :param values: name -> value for every parameter of ODOMETRY_NODE
    :return: the settings
    :raises ValueError: with every reason when the values make no valid configuration
    """
    settings = _settings(ODOMETRY_NODE, values)
    feature = {k: v for k, v in settings.items() if k in FeatureConfig.__dataclass_fields__}
    odometry = {k: v for k, v in settings.items() if k in OdometryConfig.__dataclass_fields__}
    wheel = WheelSettings(
        str(values['wheel_odometry_topic']), str(values['wheel_odometry_tf_frame']),
        float(values['wheel_timeout_s']), bool(values['wheel_use_message_covariance']),
        WheelModel(float(values['wheel_sigma_per_m']), float(values['wheel_sigma_floor_m']),
                   float(values['wheel_sigma_per_rad']),
                   math.radians(float(values['wheel_sigma_floor_deg']))))
    problems = []
    if wheel.topic and wheel.tf_frame:
        problems.append('give the wheel odometry as wheel_odometry_topic or as '
                        'wheel_odometry_tf_frame, not both')
    if wheel.tf_frame and values['publish_tf']:
        problems.append(f'wheel_odometry_tf_frame {wheel.tf_frame!r} reads the wheel '
                        f"odometry's transform to {values['base_frame']!r} from /tf: publish_tf "
                        'must be false (base_frame would have two parents)')
    if problems:
        raise ConfigError('; '.join(problems))
    return OdometrySettings(FeatureConfig(**feature), OdometryConfig(**odometry),
                            (float(values['laser_x_m']), float(values['laser_y_m']),
                             math.radians(float(values['laser_yaw_deg']))),
                            str(values['odom_frame']), str(values['base_frame']),
                            bool(values['publish_tf']), bool(values['mount_from_tf']), wheel)


class FeatureSettings(NamedTuple):
    """
    What feature_node's parameters configure.

    :ivar config: the pipeline configuration
    :ivar style: how the markers are drawn
    :ivar publish_markers: whether markers are published
    """

    config: FeatureConfig
    style: MarkerStyle
    publish_markers: bool


def defaults(schema, sensor: Optional[str] = None) -> Dict[str, Value]:
    """
    Return the default value of every parameter of a schema.

    :param schema: e.g. FEATURE_NODE
    :param sensor: a sensor preset whose values are the defaults of the parameters it sets
        (feature_node's); None: the schema's own defaults (those of DEFAULT_SENSOR)
    :return: name -> default
    :raises ConfigError: on an unknown sensor
    """
    values = {parameter.name: parameter.default for parameter in schema}
    if sensor is not None:
        presets = sensor_presets()
        if sensor not in presets:
            raise ConfigError(f'{SENSOR} must be one of {tuple(presets)}, got {sensor!r}')
        values.update({name: value for name, value in presets[sensor].parameters.items()
                       if name in values})
    return values


def feature_settings(values: Dict[str, Value]) -> FeatureSettings:
    """
    Build feature_node's validated settings from its parameter values.

    :param values: name -> value for every parameter of FEATURE_NODE
    :return: the settings
    :raises ValueError: with every reason when the values make no valid configuration
    """
    settings = _settings(FEATURE_NODE, values)
    config = {k: v for k, v in settings.items() if k in FeatureConfig.__dataclass_fields__}
    style = {k: v for k, v in settings.items() if k not in config}
    return FeatureSettings(FeatureConfig(**config), MarkerStyle(**style),
                           bool(values['publish_markers']))


def _settings(schema, values: Dict[str, Value]) -> dict:
    """
    Return the settings fields a schema's parameter values fill, in the fields' units.

    :param schema: e.g. FEATURE_NODE
    :param values: name -> value for every parameter of the schema
    :return: setting field -> value
    :raises ConfigError: with every value the schema refuses
    """
    settings: dict = {}
    problems: list = []
    for parameter in schema:
        try:
            value = parameter.check(values[parameter.name])
        except ConfigError as error:           # stated in the parameter's own name and unit
            problems.append(str(error))
            continue
        if parameter.setting is not None:
            settings[parameter.setting] = parameter.to_setting(value)
    if problems:
        raise ConfigError('; '.join(problems))
    return settings


def landmark_settings(values: Dict[str, Value]) -> Tuple[bool, float, float]:
    """
    Return whether feature_node tracks its landmarks, and the sigmas of a step between scans.

    :param values: parameter name -> value (FEATURE_NODE)
    :return: (publish_landmarks, step sigma m, step sigma rad)
    """
    return (bool(values['publish_landmarks']), float(values['landmark_step_sigma_m']),
            math.radians(float(values['landmark_step_sigma_deg'])))


class DockSettings(NamedTuple):
    """
    What feature_node's dock parameters configure.

    :ivar shape: the dock
    :ivar tracking: how detections are checked against the last ones
    :ivar detect_at_start: detection on from activation
    """

    shape: DockShape
    tracking: TrackSettings
    detect_at_start: bool


def dock_settings(values: Dict[str, Value]) -> Optional[DockSettings]:
    """
    Build feature_node's dock settings from its parameter values.

    :param values: name -> value for every parameter of FEATURE_NODE
    :return: the settings; None when ``dock_enabled`` is false
    :raises ConfigError: with every reason when the values describe no usable dock
    """
    if not values[DOCK_ENABLED]:
        return None
    # Each value is of its parameter's type once checked (bool, int or float here).
    checked: Dict[str, Any] = {p.name: p.check(values[p.name]) for p in DOCK_PARAMETERS}
    try:
        dock = DockShape(
            right_face_m=checked['dock_right_face_m'], left_face_m=checked['dock_left_face_m'],
            opening_angle_rad=math.radians(checked['dock_opening_angle_deg']),
            face_tolerance_m=checked['dock_face_tolerance_m'],
            face_shortfall_m=checked['dock_face_shortfall_m'],
            angle_tolerance_rad=math.radians(checked['dock_angle_tolerance_deg']),
            reference_xy_m=(checked['dock_reference_x_m'], checked['dock_reference_y_m']),
            reference_yaw_rad=math.radians(checked['dock_reference_yaw_deg']))
    except ValueError as error:          # the dock's own checks (shape_errors)
        raise ConfigError(f'the dock parameters describe no usable dock: {error}') from error
    tracking = TrackSettings(
        max_speed_m_s=checked['dock_max_speed_m_s'],
        max_turn_rate_rad_s=math.radians(checked['dock_max_turn_rate_deg_s']),
        confirm_detections=checked['dock_confirm_detections'],
        timeout_s=checked['dock_timeout_s'])
    return DockSettings(dock, tracking, checked['dock_detect_at_start'])


def _flatten(parameters: dict, prefix: str = '') -> dict:
    """Turn nested parameter mappings into dotted names, as rcl does for parameter files."""
    flat = {}
    for name, value in parameters.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f'{prefix}{name}.'))
        else:
            flat[f'{prefix}{name}'] = value
    return flat


def _sections(document: dict, node_name: str) -> list:
    """Return the ros__parameters mappings that apply to the node, wildcards first."""
    wildcards: list = []
    own: list = []
    for key, section in document.items():
        key = str(key)
        name = key.rstrip('/').rsplit('/', 1)[-1]
        if key in ('/**', '**'):
            target = wildcards
        elif name == node_name:
            target = own
        else:
            continue
        if not isinstance(section, dict) or not isinstance(section.get('ros__parameters'), dict):
            raise ConfigError(f'section {key!r} has no ros__parameters mapping')
        target.append(section['ros__parameters'])
    return wildcards + own


def load_parameters(path, node_name: str = 'feature_node',
                    overrides: Optional[dict] = None) -> Dict[str, Value]:
    """
    Read a node's parameter values from a ROS 2 parameter file, over the defaults.

    The file is the one ``--ros-args --params-file`` takes: the node's section (or ``/**``)
    and its ``ros__parameters``. A file is accepted exactly when the node would accept it
    (names, types, ranges); feature_node's rules between values are checked by
    :func:`feature_settings`. A ``sensor`` preset sets the defaults of the parameters it
    covers; the file and the overrides still set any of them.

    :param path: the parameter file (None: defaults only)
    :param node_name: the node whose section and schema apply (a key of SCHEMAS)
    :param overrides: values applied after the file (e.g. from a command line)
    :return: name -> value for every parameter of the node
    :raises ConfigError: for an unreadable file, an unknown name, a wrong type or range
    """
    schema = {parameter.name: parameter for parameter in SCHEMAS[node_name]}
    given = {}
    if path is not None:
        path = pathlib.Path(path)
        if path.exists() and not path.is_file():     # opening a FIFO would wait for a writer
            raise ConfigError(f'cannot read the parameter file {path}: not a regular file (a '
                              'folder, FIFO, device or socket)')
        try:
            document = load_without_aliases(path.read_text())
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
            raise ConfigError(f'cannot read the parameter file {path}: '
                              f'{str(error).splitlines()[0]}') from error
        if not isinstance(document, dict):
            raise ConfigError(f'{path} is not a ROS 2 parameter file (a mapping of node names)')
        sections = _sections(document, node_name)
        if not sections:
            raise ConfigError(f'{path} has no parameters for {node_name} (expected a '
                              f"'{node_name}:' or '/**:' section with ros__parameters)")
        for section in sections:
            given.update(_flatten(section))
    given.update(overrides or {})
    unknown = sorted(name for name in given if name not in schema and name not in _COMMON
                     and not name.startswith(_COMMON_PREFIXES))
    if unknown:
        raise ConfigError(f'unknown {node_name} parameters {unknown}; known: {sorted(schema)}')
    checked = {name: schema[name].check(value) for name, value in given.items()
               if name in schema}
    sensor = checked.get(SENSOR)
    values = defaults(schema.values(), sensor if isinstance(sensor, str) else None)
    values.update(checked)
    return values


def markdown_table(schema) -> str:
    """
    Return a schema as the Markdown table the documentation shows.

    :param schema: e.g. FEATURE_NODE
    :return: the table, one row per parameter
    """
    rows = ['| parameter | type | default | range | meaning |', '|---|---|---|---|---|']
    for parameter in schema:
        default = repr(parameter.default) if isinstance(parameter.default, str) else (
            str(parameter.default).lower() if isinstance(parameter.default, bool)
            else f'{parameter.default:g}')
        allowed = (parameter.limits.describe() if parameter.limits is not None
                   else ' \\| '.join(parameter.choices))
        read_only = ' (read-only)' if parameter.read_only else ''
        meaning = parameter.description.replace('|', '\\|')
        rows.append(f'| `{parameter.name}` | {parameter.type_name} | {default} | {allowed} | '
                    f'{meaning}{read_only} |')
    return '\n'.join(rows)


def _table_block(name: str) -> re.Pattern:
    """Return the pattern of a node's table block in a document, markers included."""
    return re.compile(rf'^(<!-- params:{name} -->\n).*?^(<!-- /params:{name} -->)$',
                      re.DOTALL | re.MULTILINE)


def with_tables(document: str) -> str:
    """
    Return a document with every node's parameter table regenerated from the schema.

    Each node's table stands between the lines ``<!-- params:NODE -->`` and
    ``<!-- /params:NODE -->``; whatever is between them is replaced by :func:`markdown_table`.

    :param document: the Markdown text (e.g. docs/user_guide.md)
    :return: the text with the tables of today's schema
    :raises ConfigError: when a node of SCHEMAS has no such block, or more than one
    """
    for name, schema in SCHEMAS.items():
        document, count = _table_block(name).subn(
            lambda block: f'{block[1]}\n{markdown_table(schema)}\n\n{block[2]}', document)
        if count != 1:
            raise ConfigError(f'{count} blocks for {name}; expected one, between the lines '
                              f"'<!-- params:{name} -->' and '<!-- /params:{name} -->'")
    return document


def main(argv=None) -> int:
    """
    Print the parameter tables as Markdown, or write or check them in a document.

    :param argv: arguments (default: sys.argv[1:])
    :return: exit status: 0; 1 when ``--check`` finds a stale table; 2 on a user error
    """
    parser = argparse.ArgumentParser(
        prog='python -m wctls_ros.params',
        description='The parameter tables of the nodes, from the one schema.')
    parser.add_argument('nodes', nargs='*', metavar='NODE',
                        help=f"nodes to print: {', '.join(SCHEMAS)} (default: all)")
    action = parser.add_mutually_exclusive_group()
    action.add_argument('--write', metavar='FILE', help='replace the marked table blocks of '
                        "every node in FILE (e.g. docs/user_guide.md) with today's tables")
    action.add_argument('--check', metavar='FILE', help='exit 1 when a marked table in FILE '
                        'differs from the schema')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    unknown = [name for name in args.nodes if name not in SCHEMAS]
    if unknown:
        parser.error(f"unknown nodes {unknown}; choose among {', '.join(SCHEMAS)}")
    path = args.write or args.check
    if path is None:
        for name in args.nodes or SCHEMAS:
            print(f'### {name}\n\n{markdown_table(SCHEMAS[name])}\n')
        return 0
    try:
        document = pathlib.Path(path).read_text()
        updated = with_tables(document)
        if args.write and updated != document:
            pathlib.Path(path).write_text(updated)
    except (OSError, ConfigError) as error:
        print(f'{parser.prog}: error: {path}: {getattr(error, "strerror", None) or error}',
              file=sys.stderr)
        return 2
    if args.check and updated != document:
        print(f'{path}: the parameter tables differ from the schema; regenerate them with '
              f'python -m wctls_ros.params --write {path}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
