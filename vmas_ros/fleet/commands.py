"""Velocity commands on their way to the robots: latency, timeout, and the values refused.

A command takes effect ``latency`` seconds after it arrived, and is the
robot's target until ``timeout`` seconds after that; then the target is zero
velocity, as diff_drive_controller does with ``cmd_vel_timeout``. Ages count
from when a command takes effect, so latency shifts a command without
shortening its life.

The latency is one value for the whole fleet, so commands fall due in the
order they arrived: one FIFO of ``(due, robot, command)`` holds every robot's
queue interleaved, and each step pops what is due, whatever the robot (work
per message, none per robot). Times are the caller's monotonic seconds.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Deque, Optional, Sequence, Tuple

import numpy as np

__all__ = ["CommandBuffer", "command_problem", "ABSURD_VELOCITY", "FIELDS"]

#: a velocity component beyond this (m/s or rad/s) is a unit or encoding mistake, not a command
ABSURD_VELOCITY = 1e6
#: the six components of a Twist, in the order :func:`command_problem` takes them
FIELDS = ("linear.x", "linear.y", "linear.z", "angular.x", "angular.y", "angular.z")


def command_problem(values: Sequence[float]) -> Optional[str]:
    """Why a Twist's six ``values`` (see :data:`FIELDS`) cannot be a command, or None."""
    for field, value in zip(FIELDS, values):
        if not math.isfinite(value):
            return f"{field}={value}: expected finite numbers"
        if abs(value) > ABSURD_VELOCITY:
            return f"{field}={value:g}: expected |value| <= {ABSURD_VELOCITY:g}"
    return None


class CommandBuffer:
    """The fleet's commands in flight and in force.

    ``target(now)`` gives ``[n, 3]`` body-frame targets (vx, vy, wz): each
    robot's latest command that is due, or zeros where there is none or it
    timed out.
    """

    def __init__(self, n_robots: int, latency: float, timeout: float) -> None:
        self.latency, self.timeout = latency, timeout
        self.pending: Deque[Tuple[float, int, np.ndarray]] = deque()
        self.current = np.zeros((n_robots, 3))  # [n, 3] the command in force
        self.since = np.full(n_robots, -math.inf)  # [n] when it took effect

    def push(self, robot: int, command: Sequence[float], now: float) -> None:
        """A command ``(vx, vy, wz)`` for robot ``robot`` arrived at ``now``."""
        self.pending.append((now + self.latency, robot, np.asarray(command, dtype=np.float64)))

    def target(self, now: float) -> np.ndarray:
        """``[n, 3]``: what every robot is told to do at ``now``."""
        while self.pending and self.pending[0][0] <= now:
            due, robot, command = self.pending.popleft()
            self.current[robot] = command
            self.since[robot] = due
        fresh = (now - self.since) <= self.timeout  # [n]
        return np.where(fresh[:, None], self.current, 0.0)

    def clear(self) -> None:
        """Forget every command, pending or in force (a new episode)."""
        self.pending.clear()
        self.current[:] = 0.0
        self.since[:] = -math.inf
