"""How our nodes start and stop: refused parameters exit 2, a failed step 3, a failed bag 4, signals 0.

sim_node and policy_node share this so that both behave the same for users,
launch files and supervisors (systemd, a launch ``on_exit`` handler), which
can tell the three apart by the exit code alone:

* a ``ConfigError`` raised while the node is built prints the reason and exits
  with code 2 (:data:`EXIT_CONFIG`): fix the parameters;
* a ``SimulationFault`` raised from a callback (a scenario or policy that
  crashed or produced NaN) prints the cause's traceback, then one line saying
  what failed, and exits with code 3 (:data:`EXIT_FAULT`): the node stops
  rather than publish garbage, and its bag is still finished;
* a ``RecordingStopped`` (sim_node with ``record_on_error: stop`` whose bag
  could not be written: disk full, read-only, vanished) prints one line and
  exits with code 4 (:data:`EXIT_RECORDING`);
* SIGINT/SIGTERM (KeyboardInterrupt or an external shutdown) exit with 0; a
  signal before the node is built (during the imports) too, when the entry
  point installed ``signal_guard.guard`` (the ``sim_node``/``policy_node`` programs do).

In every case the node is destroyed before rclpy shuts down, which is where
sim_node closes its bag: the bag is complete whichever way the node stops
(except SIGKILL; see ``vmas-ros bag-recover``).

Before DDS starts, the node removes the Fast DDS shared-memory segments that a
killed process left half made (:mod:`vmas_ros.rostools.dds_clean`): Fast DDS
would wait for them forever. If start-up still hangs inside DDS, a message
names what to do.
"""
from __future__ import annotations

import signal
import sys
import threading
import traceback
from typing import Callable, List, Optional

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from vmas_ros.ros import signal_guard
from vmas_ros.rostools.dds_clean import remove_stuck_segments, stuck_segments

#: exit code for parameters refused at start
EXIT_CONFIG = 2
#: exit code for a node stopped by a SimulationFault (a crashed scenario or policy)
EXIT_FAULT = 3
#: exit code for a node stopped because its bag could not be written (record_on_error: stop)
EXIT_RECORDING = 4


class ConfigError(ValueError):
    """Start-up parameters were refused; the message says which and why."""


class SimulationFault(RuntimeError):
    """A step cannot go on: the scenario or the policy raised, or produced non-finite values.

    The message is meant for the user and says what failed, at which step and
    what was (not) published; the original exception, if any, is ``__cause__``.
    """


class RecordingStopped(RuntimeError):
    """Writing the bag failed and the node was asked to stop then; the message says what failed."""


def _shut_down() -> None:
    """``rclpy.try_shutdown()``, also when rclpy's own signal handling shuts the context down in between.

    try_shutdown checks the context, then shuts it down; a SIGINT's deferred shutdown landing between
    the two made it raise "rcl_shutdown already called" and the node exit 1 instead of 0 (seen once
    on a fresh clone, test_signal_leaves_a_finished_bag[sigint_startup]).
    """
    try:
        rclpy.try_shutdown()
    except RCLError:
        if rclpy.ok():  # not the race: the context is still up
            raise


#: seconds of start-up after which a node looks again for Fast DDS segments that would hang it
STARTUP_DDS_CHECK_S = 10.0


def _clear_stuck_dds(name: str) -> None:
    for path in remove_stuck_segments():
        print(f"{name}: removed {path}, Fast DDS shared memory that a killed process left half made "
              "(it would have made this node wait forever)", file=sys.stderr, flush=True)


def _warn_if_dds_stuck(name: str) -> None:
    """Runs on a timer thread while the node is being built: the main thread may be inside DDS."""
    stuck = stuck_segments()
    if stuck:
        print(f"{name}: still starting after {STARTUP_DDS_CHECK_S:g} s, and {', '.join(map(str, stuck))} "
              "(Fast DDS shared memory that a killed process left half made) may be what it waits for. "
              "Stop this node, run `vmas-ros dds-clean`, and start it again.", file=sys.stderr, flush=True)


def run_node(name: str, make_node: Callable[[], Node], argv: Optional[List[str]] = None) -> int:
    """Init rclpy, build the node with ``make_node`` and spin it until shutdown; returns the exit code."""
    _clear_stuck_dds(name)
    rclpy.init(args=argv if argv is not None else sys.argv)
    node = None
    code = 0
    try:
        # the executor exists before the node: the node publishes its first state while it is built, so
        # a signal prompted by that message must not land inside the executor's constructor (rclpy then
        # prints a traceback from the half-built executor's __del__)
        executor = SingleThreadedExecutor()
        signal_guard.hand_over()  # a signal from here on stops the node (KeyboardInterrupt), see signal_guard.py
        watch = threading.Timer(STARTUP_DDS_CHECK_S, _warn_if_dds_stuck, args=(name,))
        watch.daemon = True
        watch.start()
        try:
            node = make_node()
        finally:
            watch.cancel()
        rclpy.spin(node, executor=executor)
    except ConfigError as error:
        print(f"{name}: refused parameters: {error}", file=sys.stderr)
        code = EXIT_CONFIG
    except SimulationFault as error:
        if error.__cause__ is not None:  # where the scenario or policy failed, for its author
            traceback.print_exception(error.__cause__, file=sys.stderr)
        print(f"{name}: stopped: {error}", file=sys.stderr)
        code = EXIT_FAULT
    except RecordingStopped as error:
        print(f"{name}: stopped: {error}", file=sys.stderr)
        code = EXIT_RECORDING
    except (KeyboardInterrupt, ExternalShutdownException):
        code = 0
    except Exception:
        if rclpy.ok() and not signal_guard.stop_requested():
            raise
        # a callback raced the shutdown a signal started, or the signal's KeyboardInterrupt came out of
        # rclpy's C++ code as another error: still a clean exit
        code = 0
    finally:
        # a second Ctrl-C or SIGTERM (or one sent to the whole process group) must not break the clean-up
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if node is not None:
            node.destroy_node()
        _shut_down()
    if code == EXIT_FAULT and node is not None and getattr(node, "recorder", None) is not None:
        print(f"{name}: the bag {node.recorder.bag} is closed and readable", file=sys.stderr)
    return code
