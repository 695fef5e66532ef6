"""lifecycle: the last shutdown tolerates rclpy's own signal handling finishing it first."""
from __future__ import annotations

import gc
import signal
import sys

import pytest
import rclpy
import rclpy.node
from rclpy._rclpy_pybind11 import RCLError

from vmas_ros.ros import lifecycle, signal_guard

pytestmark = pytest.mark.ros


def test_a_shutdown_that_a_signal_completed_meanwhile_is_no_error(monkeypatch):
    """try_shutdown checks the context and then shuts it down; when a SIGINT's deferred shutdown lands
    between the two, rcl says it was shut down already: the node has still stopped cleanly."""
    rclpy.init()
    try_shutdown = rclpy.try_shutdown

    def raced():
        rclpy.shutdown()  # what rclpy's signal handling does in between
        raise RCLError("failed to shutdown: rcl_shutdown already called on the given context")

    monkeypatch.setattr(rclpy, "try_shutdown", raced)
    lifecycle._shut_down()
    assert not rclpy.ok()
    monkeypatch.setattr(rclpy, "try_shutdown", try_shutdown)


def test_other_shutdown_errors_still_raise(monkeypatch):
    rclpy.init()
    try:
        monkeypatch.setattr(rclpy, "try_shutdown", lambda: (_ for _ in ()).throw(RCLError("something else")))
        with pytest.raises(RCLError, match="something else"):
            lifecycle._shut_down()
    finally:
        monkeypatch.undo()
        rclpy.try_shutdown()


class _FailingNode(rclpy.node.Node):
    """A node whose first timer callback raises what rclpy's C++ code raised when a SIGINT landed inside
    take_message; ``signalled`` first marks the signal as received, as the entry point's handler does."""

    def __init__(self, signalled: bool) -> None:
        super().__init__("lifecycle_failing_node")
        self.create_timer(0.01, lambda: self._fail(signalled))

    @staticmethod
    def _fail(signalled: bool) -> None:
        if signalled:
            signal_guard._guard.stopping = True
        raise RuntimeError("Unable to convert call argument '0' to Python object")


@pytest.mark.parametrize("signalled", [True, False])
def test_an_error_out_of_a_stop_signal_is_a_clean_stop(monkeypatch, signalled):
    """A SIGINT's KeyboardInterrupt raised inside rclpy's C++ code can come out as another error: after a
    stop signal that is a clean exit (0); without one the error is the node's and propagates."""
    monkeypatch.setattr(signal_guard, "_guard", signal_guard._Guard("lifecycle_test"))
    signal_guard._guard.handed_over = True  # what run_node's hand_over() does; the handler is not installed
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        if signalled:
            assert lifecycle.run_node("lifecycle_test", lambda: _FailingNode(True), argv=["lifecycle_test"]) == 0
        else:
            with pytest.raises(RuntimeError, match="Unable to convert call argument"):
                lifecycle.run_node("lifecycle_test", lambda: _FailingNode(False), argv=["lifecycle_test"])
    finally:
        for sig, handler in handlers.items():  # run_node ignores both signals while it cleans up
            signal.signal(sig, handler)
    assert not rclpy.ok()


class _Broken:
    def __del__(self):
        raise AttributeError("not rclpy's")


@pytest.mark.parametrize("stopping", [True, False])
def test_a_task_half_built_by_a_stop_signal_prints_no_traceback(monkeypatch, capsys, stopping):
    """A stop signal's KeyboardInterrupt inside rclpy's Task constructor leaves a task without its
    attributes, and its __del__ fails. After a stop the running node's hook drops that message, and
    only that one; before a stop it is printed as usual."""
    from rclpy.task import Task

    monkeypatch.setattr(signal_guard, "_guard", signal_guard._Guard("lifecycle_test"))
    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)  # put back after the test
    signal_guard.hand_over()
    signal_guard._guard.stopping = stopping
    half_built = Task.__new__(Task)  # what an interrupted __init__ leaves behind
    del half_built
    other = _Broken()
    del other
    gc.collect()
    printed = capsys.readouterr().err
    assert ("Future.__del__" in printed) is not stopping, printed
    assert "not rclpy's" in printed
