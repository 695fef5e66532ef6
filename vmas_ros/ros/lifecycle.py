"""How our nodes start and stop: refused parameters exit 2, signals exit 0, nothing half torn down.

sim_node and policy_node share this so that both behave the same for users
and launch files: a ``ConfigError`` raised while the node is built prints the
reason and exits with code 2; SIGINT/SIGTERM (KeyboardInterrupt or an
external shutdown) exit with 0 after the node is destroyed.
"""
from __future__ import annotations

import signal
import sys
from typing import Callable, List, Optional

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


class ConfigError(ValueError):
    """Start-up parameters were refused; the message says which and why."""


def run_node(name: str, make_node: Callable[[], Node], argv: Optional[List[str]] = None) -> int:
    """Init rclpy, build the node with ``make_node`` and spin it until shutdown; returns the exit code."""
    rclpy.init(args=argv if argv is not None else sys.argv)
    node = None
    code = 0
    try:
        node = make_node()
        rclpy.spin(node)
    except ConfigError as error:
        print(f"{name}: refused parameters: {error}", file=sys.stderr)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        code = 0
    except Exception:
        if rclpy.ok():
            raise
        code = 0  # a callback raced the shutdown a signal started: still a clean exit
    finally:
        # a second Ctrl-C (or a SIGINT sent to the whole process group) must not break the clean-up
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
