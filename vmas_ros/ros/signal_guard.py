"""Signals during a node's start-up: a clean exit 0 from the first milliseconds on.

Why: ``sim_node`` spends its start-up importing torch, rclpy and the engine.
Python's default handlers make a SIGINT there a KeyboardInterrupt
traceback raised from inside some import (exit 1, or death by SIGINT; seen
once leaving the process hung on an import lock) and a SIGTERM plain death by
signal (-15). A launch file or supervisor that stops a node right after
starting it should see what it sees later on: exit code 0 and one line.

So the entry points (:mod:`vmas_ros.ros.startup`, :mod:`vmas_ros.fleet.startup`)
install :func:`guard` before any heavy import. It only uses the standard
library, and lives in a module that imports nothing else of vmas_ros. Its handler has two phases:

* **starting** (until :func:`hand_over`): nothing of the node exists yet, no
  bag, no ROS endpoint. The handler prints one line and ends the process with
  ``os._exit(0)`` at once, without unwinding half-finished imports.
* **running** (after ``lifecycle.run_node`` has called ``rclpy.init``, which
  chains its own handlers to this one): SIGINT and SIGTERM both raise
  KeyboardInterrupt in the main thread, as Python's SIGINT handler does, so
  ``run_node`` stops the node, closes its bag and exits 0. During a recorder
  write the handler only notes the signal (the recorder calls its ``hold`` and
  ``release``) and raises once the write is complete, so a bag never ends in
  half a step. A KeyboardInterrupt that lands inside the constructor of one
  of rclpy's tasks leaves that task half built, and its ``__del__`` would
  print a traceback; once a stop was asked for, that one message is dropped.

A library user who imports the nodes gets none of this: only the entry
points call :func:`guard`.
"""
from __future__ import annotations

import os
import signal
import sys
from typing import Optional

__all__ = ["guard", "hand_over", "stop_requested"]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _Guard:
    """The handler of both signals. Callable, as ``signal.signal`` wants, and able to hold signals
    during a recorder write itself (``hold``/``release``): McapRecorder then leaves it installed
    instead of swapping it, and so leaves rclpy's C-level handler, chained in front of it, in place
    (that one wakes the executor at once; without it a stop waits for the node's next timer)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.handed_over = False
        self._holding = 0  # nesting depth of hold(); main thread only, like the handler itself
        self._held = False
        self.stopping = False  # a signal asked the running node to stop

    def __call__(self, signum: int, frame) -> None:
        if not self.handed_over:
            sys.stdout.flush()
            sys.stderr.write(f"{self.name}: stopped by {signal.Signals(signum).name} during start-up, before "
                             "the node existed (nothing was recorded)\n")
            sys.stderr.flush()
            os._exit(0)
        self.stopping = True
        if self._holding:
            self._held = True  # raised by release(), once the write is complete
            return
        raise KeyboardInterrupt

    def hold(self) -> None:
        """Note signals instead of acting on them until the matching ``release``."""
        self._holding += 1

    def release(self) -> None:
        """End a ``hold``; a signal noted meanwhile raises KeyboardInterrupt now."""
        self._holding -= 1
        if not self._holding and self._held:
            self._held = False
            raise KeyboardInterrupt


_guard: Optional[_Guard] = None


def guard(name: str) -> None:
    """Make SIGINT and SIGTERM end the process cleanly (exit 0) from now on; ``name`` starts the message."""
    global _guard
    _guard = _Guard(name)
    for sig in _SIGNALS:
        signal.signal(sig, _guard)


def hand_over() -> None:
    """The node is about to be built (rclpy is initialised): signals now stop it through KeyboardInterrupt."""
    if _guard is not None:
        _guard.handed_over = True
        sys.unraisablehook = _unraisable


def _half_built_future(unraisable) -> bool:
    """Whether ``unraisable`` is an rclpy Future's ``__del__`` failing on an attribute its constructor
    never set: what a KeyboardInterrupt raised inside that constructor leaves behind."""
    where = unraisable.object
    return (isinstance(unraisable.exc_value, AttributeError) and getattr(where, "__name__", None) == "__del__"
            and getattr(where, "__module__", None) == "rclpy.task")


def _unraisable(unraisable) -> None:
    """``sys.unraisablehook`` of a running node. A stop signal raises KeyboardInterrupt wherever the
    main thread is, sometimes inside the constructor of an executor's task; that half-built task's
    ``__del__`` then prints a traceback to a user who only pressed Ctrl-C. Once a stop was asked for,
    that one message is dropped; every other goes to Python's default hook."""
    if not (stop_requested() and _half_built_future(unraisable)):
        sys.__unraisablehook__(unraisable)


def stop_requested() -> bool:
    """Whether SIGINT or SIGTERM asked the running node to stop: an error raised while the signal was
    being turned into KeyboardInterrupt (inside rclpy's C++ code it can come out as another exception)
    is then part of a clean stop."""
    return _guard is not None and _guard.stopping
