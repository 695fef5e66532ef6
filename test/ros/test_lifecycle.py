"""lifecycle: the last shutdown tolerates rclpy's own signal handling finishing it first."""
from __future__ import annotations

import pytest
import rclpy
from rclpy._rclpy_pybind11 import RCLError

from vmas_ros.ros import lifecycle

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
