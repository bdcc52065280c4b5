# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""The Jazzy ``main()`` every wctls_ros node shares: start, spin, and end cleanly."""

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor


def spin_forever(executor, node) -> int:
    """
    Spin until shutdown (Ctrl-C, SIGTERM).

    :param executor: the executor holding the node
    :param node: the node
    :return: exit status 0
    """
    executor.spin()
    return 0


def run_node(name: str, make_node, spin=spin_forever, config_errors=(ValueError,),
             args=None) -> int:
    """
    Run a node the way ros2/demos do on Jazzy, and turn its ending into an exit status.

    A bad configuration (``config_errors``, or a parameter of the wrong type or out of range)
    is one fatal log line and status 1, never a traceback. Ctrl-C and SIGTERM are a clean
    end: they shut the context down from a signal handler, so whatever runs at that moment (the
    executor's wait set, a publish) may fail with an RCLError instead of raising
    ExternalShutdownException; with the context gone, that is a shutdown, not an error.

    :param name: the logger name for start-up errors
    :param make_node: callable returning the node
    :param spin: callable(executor, node) -> exit status
    :param config_errors: exception types that mean a bad configuration
    :param args: command-line arguments for rclpy.init (default: sys.argv)
    :return: exit status: 0 on a clean end, 1 on a bad configuration
    """
    rclpy.init(args=args)
    node = None
    try:
        # Made before the (slower) node, so a signal during start-up rarely meets it half-built.
        executor = SingleThreadedExecutor()
        node = make_node()
        executor.add_node(node)
        return spin(executor, node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ParameterException, *config_errors) as error:
        rclpy.logging.get_logger(name).fatal(str(error))
        return 1
    except Exception:  # noqa: B902 - a failure caused by the shutdown itself is no error
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
