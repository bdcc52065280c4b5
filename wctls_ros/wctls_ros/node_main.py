# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The Jazzy ``main()`` every wctls_ros node shares, and its parameter declarations."""

import difflib
import os
import re
import sys

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.utilities import remove_ros_args

from .params import defaults, SENSOR
from .process import stop_requested, stop_signals

# What rclpy.init raises for bad ROS arguments (an unreadable --params-file, a bad remap rule,
# an unknown --ros-args option) or environment (ROS_DOMAIN_ID).
_INIT_ERRORS = (rclpy_implementation.RCLError, rclpy_implementation.UnknownROSArgsError)
# rcl appends where in its C sources an error was found: of no use to the user.
_SOURCE_LOCATION = re.compile(r', at \S+:\d+')
# Parameters rclpy itself declares on every node (a params file may set them).
_ROS_PARAMETERS = ('use_sim_time', 'start_type_description_service')
# How long the executor waits at most before it looks whether the context was shut down, s.
SHUTDOWN_CHECK_S = 0.1


def parameter_descriptor(parameter) -> ParameterDescriptor:
    """
    Return the ROS descriptor of a schema row: description, range, read-only, choices.

    The descriptor's range is the closure of the parameter's limits (ROS ranges include both
    ends); an excluded end is refused by the settings' own validation, with its reason.

    :param parameter: a :class:`wctls_ros.params.Parameter`
    :return: the descriptor
    """
    descriptor = ParameterDescriptor(name=parameter.name, description=parameter.description,
                                     read_only=parameter.read_only)
    if parameter.choices:
        descriptor.additional_constraints = 'one of: ' + ', '.join(parameter.choices)
    limits = parameter.limits
    if limits is not None and isinstance(parameter.default, int):
        descriptor.integer_range = [IntegerRange(from_value=limits.low, to_value=limits.high,
                                                 step=1)]
    elif limits is not None:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(limits.low), to_value=float(limits.high), step=0.0)]
    return descriptor


def declare_parameters(node, schema) -> dict:
    """
    Declare a node's parameters from its schema and return their values.

    A ``sensor`` parameter (feature_node's) is declared first: its preset's values are the
    defaults of the parameters it sets (:func:`wctls_ros.params.defaults`).

    :param node: the rclpy node
    :param schema: its rows (e.g. :data:`wctls_ros.params.FEATURE_NODE`)
    :return: name -> value (the default, a parameter file's or a command line's)
    :raises rclpy.exceptions.ParameterException: on a value of the wrong type or range
    :raises wctls_ros.params.ConfigError: on an unknown sensor preset
    """
    def declare(parameter, default):
        return node.declare_parameter(parameter.name, default,
                                      parameter_descriptor(parameter)).value

    values = {parameter.name: declare(parameter, parameter.default)
              for parameter in schema if parameter.name == SENSOR}
    initial = defaults(schema, values.get(SENSOR))
    values.update({parameter.name: declare(parameter, initial[parameter.name])
                   for parameter in schema if parameter.name != SENSOR})
    _warn_of_unknown_parameters(node, list(values))
    return values


def _warn_of_unknown_parameters(node, declared: list) -> None:
    """
    Warn of each parameter a params file or ``-p`` sets that the node does not have.

    ROS ignores them without a word (a misspelled ``range_sigma`` leaves the preset's value in
    force); the offline tools refuse them, the nodes name them with the closest known name.
    rclpy keeps the values given for a node in ``_parameter_overrides`` (no public accessor).
    """
    given = getattr(node, '_parameter_overrides', {})
    unknown = sorted(name for name in given if name not in declared
                     and name not in _ROS_PARAMETERS and not name.startswith('qos_overrides.'))
    for name in unknown:
        closest = difflib.get_close_matches(name, declared, n=1)
        hint = f' (did you mean {closest[0]}?)' if closest else ''
        node.get_logger().warning(f'ignoring parameter {name}: {node.get_name()} has no such '
                                  f'parameter{hint}')


def spin_until_shutdown(executor, finished=lambda: False) -> None:
    """
    Spin until a stop signal, the context's shutdown, or ``finished()`` is true.

    A stop signal (:mod:`wctls_ros.process`) is only noted: the spin ends at the next callback
    or bounded wait, never inside a callback (a scan in the compiled pipeline). Each wait is
    bounded by :data:`SHUTDOWN_CHECK_S`: rclpy's signal thread wakes the executors before it
    shuts the context down, and an executor that woke in between would sleep until its next
    timer or message.

    :param executor: the executor holding the nodes
    :param finished: asked after each callback or bounded wait; True ends the spin
    """
    while executor.context.ok() and stop_requested() is None and not finished():
        executor.spin_once(timeout_sec=SHUTDOWN_CHECK_S)


def spin_forever(executor, node) -> int:
    """
    Spin until shutdown (Ctrl-C, SIGTERM, SIGHUP).

    :param executor: the executor holding the node
    :param node: the node
    :return: exit status 0
    """
    spin_until_shutdown(executor)
    return 0


def run_node(name: str, make_node, spin=spin_forever, config_errors=(ValueError,),
             args=None) -> int:
    """
    Run a node the way ros2/demos do on Jazzy, and turn its ending into an exit status.

    A bad configuration (bad ROS arguments such as a missing ``--params-file``,
    ``config_errors``, or a parameter of the wrong type or out of range) is one fatal log line
    and status 1, never a traceback. A stop signal (Ctrl-C, SIGTERM, SIGHUP), at any moment
    from start-up to the clean-up, is a clean end with status 0, at the next safe point
    (:func:`wctls_ros.process.stop_signals`); once the context is shut down, what fails for
    that reason is no error. Call it last: the process is ending.

    :param name: the logger name for start-up errors
    :param make_node: callable returning the node
    :param spin: callable(executor, node) -> exit status
    :param config_errors: exception types that mean a bad configuration
    :param args: command-line arguments for rclpy.init (default: sys.argv)
    :return: exit status: 0 on a clean end, 1 on a bad configuration
    """
    logger = rclpy.logging.get_logger(name)
    unreadable = _special_params_files(sys.argv if args is None else args)
    if unreadable:
        # rcl would open it and wait for a writer (a FIFO) before any signal handler exists.
        logger.fatal(f'cannot start: --params-file {unreadable[0]} is not a regular file (a '
                     'folder, FIFO, device or socket)')
        return 1
    node = executor = None
    with stop_signals(ending=True):
        try:
            try:
                # Parsed once before rclpy.init, which would log an extra rcl line before
                # raising.
                remove_ros_args(args)
                rclpy.init(args=args)
            except _INIT_ERRORS as error:
                reason = _SOURCE_LOCATION.sub('', str(error))
                if isinstance(error, rclpy_implementation.UnknownROSArgsError):
                    reason = f'unknown ROS arguments {reason}'
                logger.fatal(f'cannot start: {reason}')
                return 1
            executor = SingleThreadedExecutor()
            node = make_node()
            executor.add_node(node)
            return spin(executor, node)
        except (ParameterException, *config_errors) as error:
            if stop_requested() is None:
                logger.fatal(str(error))
                return 1
        except ExternalShutdownException:
            pass
        except Exception:  # noqa: B902 - a failure caused by the shutdown itself is no error
            if rclpy.ok() and stop_requested() is None:
                raise
        finally:
            if executor is not None:
                executor.shutdown()
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return 0


def _special_params_files(args) -> list:
    """Return the --params-file arguments that exist but are not regular files."""
    given = [path for option, path in zip(args, args[1:]) if option == '--params-file']
    return [path for path in given if os.path.exists(path) and not os.path.isfile(path)]
