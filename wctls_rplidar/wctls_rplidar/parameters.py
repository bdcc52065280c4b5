# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
rplidar_node's parameters: one row each, declared with its ROS descriptor, shown in the docs.

Every parameter is read-only (fixed at configure; reconfigure to change one), named as
sllidar_ros2 names it where it has the same meaning. ``python -m wctls_rplidar.parameters``
prints the Markdown table the documentation shows. Pure Python apart from :func:`declare_all`.
"""

from dataclasses import dataclass
import sys
from typing import Optional, Tuple, Union

Value = Union[bool, int, float, str]


@dataclass(frozen=True)
class Parameter:
    """
    One read-only ROS parameter: its type (that of the default), default, range and meaning.

    :ivar name: the ROS parameter name
    :ivar default: the default value; its Python type is the parameter's type
    :ivar description: what it means, with its unit
    :ivar limits: the closed interval (low, high) allowed for a number, None otherwise
    :ivar choices: the allowed values of a string (empty: any)
    """

    name: str
    default: Value
    description: str
    limits: Optional[Tuple[float, float]] = None
    choices: Tuple[str, ...] = ()


PARAMETERS = tuple(Parameter(*row) for row in (
    ('channel_type', 'serial', "Link to the device: 'serial' or 'tcp'", None,
     ('serial', 'tcp')),
    ('serial_port', '/dev/ttyUSB0', 'Serial device of the S1 (a udev symlink such as '
     '/dev/rplidar is steadier)'),
    ('serial_baudrate', 0, 'Serial bits per second (A1, A2M8 115200; A3, S1 256000; C1 '
     '460800; S2, S3 1000000); 0 probes these rates and keeps the one that answers',
     (0, 4000000)),
    ('tcp_ip', '192.168.0.7', "Device address when channel_type is 'tcp'"),
    ('tcp_port', 20108, "Device TCP port when channel_type is 'tcp'", (1, 65535)),
    ('frame_id', 'laser', 'Frame of the scans (x toward the raw 180 deg side, as '
     'sllidar_ros2)'),
    ('inverted', False, 'The sensor is mounted upside down (mirror the beam order)'),
    ('angle_compensate', True, 'Bin each turn into 360*k fixed beams (k from the sample '
     'rate), each at its bin centre, NaN where no sample fell; false publishes the turn on its '
     'own angle grid, each sample within half a step of its bearing, with a varying beam '
     'count'),
    ('scan_mode', '', "Scan mode name, e.g. 'DenseBoost' or 'Standard'; '' = the device's "
     'typical mode'),
    ('scan_frequency', 10.0, 'Rotation frequency requested from the motor, Hz (sets the '
     'angle_compensate bin count as in sllidar_ros2)', (5.0, 20.0)),
    ('data_timeout', 1.0, 'Seconds without scan data (or with only garbage) before the '
     'session is restarted', (0.1, 10.0)),
    ('health_reset_attempts', 3, 'RESETs tried on a device health error before giving up',
     (0, 10)),
    ('autostart', True, 'Configure and activate at start (a plain ros2 run scans at once); '
     'false waits for a lifecycle manager or launch file to drive the transitions'),
    ('configure_timeout', 5.0, 'Seconds configure waits for the device info and health before '
     'it fails naming the likely cause (without autostart; autostart keeps retrying)',
     (0.5, 60.0)),
    ('orientation', 'sllidar', "Laser frame of both scans: 'sllidar' (x toward the raw 180 deg "
     "side, as sllidar_ros2) or 'rep103' (x toward the device's front, raw 0 deg); both "
     'counter-clockwise', None, ('sllidar', 'rep103')),
    ('fixed_beams', 0, 'Also publish scan_fixed: every turn in this many fixed angular bins '
     'from -pi (the sample nearest each bin centre; NaN for a bin no sample fell in), for '
     'slam_toolbox and AMCL; 0 = off', (0, 8192)),
))


def declare_all(node) -> dict:
    """
    Declare every parameter on a node, with its description, range and choices.

    :param node: the rclpy node
    :return: name -> value (the default, a parameter file's or a command line's)
    :raises rclpy.exceptions.ParameterException: on a value of the wrong type or range
    """
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    values = {}
    for parameter in PARAMETERS:
        descriptor = ParameterDescriptor(name=parameter.name, read_only=True,
                                         description=parameter.description)
        if parameter.choices:
            descriptor.additional_constraints = 'one of: ' + ', '.join(parameter.choices)
        if parameter.limits is not None and isinstance(parameter.default, int):
            low, high = parameter.limits
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high),
                                                     step=1)]
        elif parameter.limits is not None:
            low, high = parameter.limits
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(low), to_value=float(high), step=0.0)]
        values[parameter.name] = node.declare_parameter(parameter.name, parameter.default,
                                                        descriptor).value
    return values


def markdown_table() -> str:
    """
    Return the parameters as the Markdown table the documentation shows.

    :return: the table, one row per parameter
    """
    kinds = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
    rows = ['| parameter | type | default | range | meaning |', '|---|---|---|---|---|']
    for parameter in PARAMETERS:
        default = parameter.default
        shown = (repr(default) if isinstance(default, str) else str(default).lower()
                 if isinstance(default, bool) else f'{default:g}')
        allowed = (f'[{parameter.limits[0]:g}, {parameter.limits[1]:g}]'
                   if parameter.limits is not None else ' \\| '.join(parameter.choices))
        meaning = parameter.description.replace('|', '\\|')
        rows.append(f'| `{parameter.name}` | {kinds[type(default)]} | {shown} | {allowed} | '
                    f'{meaning} (read-only) |')
    return '\n'.join(rows)


if __name__ == '__main__':
    print(markdown_table())
    sys.exit(0)
