"""A policy's actions as velocity commands a robot base takes (numpy only: no ROS, no torch).

A trained policy's action means what the training agents' dynamics made of it:

- ``world_velocity``: the first two components are a velocity (or a force a
  velocity controller tracks) along the world's x and y. Holonomic agents that
  never rotate, such as simple_spread's and holonomic navigation's, learn this.
- ``body_velocity``: the same, in the robot's own frame (x forward, y left).
- ``speed_turn``: (forward speed, turn rate), a unicycle's command: what agents
  with ``DiffDrive`` dynamics learn (navigation with ``dynamics: diff_drive``).

A ROS base takes a body-frame twist (REP 103). A holonomic base tracks
(linear.x, linear.y, angular.z); a differential-drive base only linear.x and
angular.z. :func:`body_commands` turns actions into that twist:

- a world-frame velocity is rotated into the body frame by the heading from the
  robot's odometry (so a robot that does not face +x still drives the right way);
- on a differential-drive base, a velocity (world or body) is tracked with a
  point ahead of the wheel axis: a point at ``lookahead`` metres in front of the
  axis moves with velocity ``(v, lookahead * w)`` in the body frame, so asking it
  to move with the wanted velocity ``(ux, uy)`` gives ``v = ux`` and
  ``w = uy / lookahead``. The robot turns towards the wanted direction while it
  drives, instead of stopping to turn on the spot;
- ``cmd_vel_scale`` multiplies the whole twist: for a velocity it converts the
  action's units to metres per second, for (speed, turn) it slows the robot
  along the same path.

:class:`CommandLimiter` then applies limits like ros2_control's
diff_drive_controller: a speed limit and an acceleration limit per tick.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Optional, Tuple

import numpy as np

#: what a policy's action can mean (``auto``: read from the policy's metadata)
ACTION_KINDS = ("auto", "world_velocity", "body_velocity", "speed_turn")
#: the robot base policy_node commands
BASES = ("holonomic", "diff_drive")


def resolve_action_kind(kind: str, metadata: Mapping[str, Any]) -> Tuple[str, str]:
    """(kind, why) for ``kind``; ``auto`` reads the training dynamics from the policy's scenario kwargs.

    A policy trained with ``dynamics: diff_drive`` agents outputs (speed, turn
    rate); every other shipped scenario's holonomic agents output a world-frame
    velocity or force.
    """
    if kind != "auto":
        return kind, "set by action_kind"
    kwargs = metadata.get("scenario_kwargs") or {}
    scenario = metadata.get("scenario", "?")
    if kwargs.get("dynamics") == "diff_drive":
        return "speed_turn", f"the policy was trained on {scenario} with dynamics: diff_drive"
    return "world_velocity", f"the policy was trained on {scenario} with holonomic agents"


def needs_heading(kind: str) -> bool:
    """Whether turning this kind of action into a body-frame twist needs the robot's heading."""
    return kind == "world_velocity"


def body_commands(actions: np.ndarray, yaw: Optional[np.ndarray], kind: str, base: str, scale: float,
                  lookahead: float) -> np.ndarray:
    """Body-frame twists ``[n, 3]`` (linear.x, linear.y, angular.z) for ``actions`` ``[n, action_size]``.

    ``yaw`` ``[n]`` is each robot's heading (needed for ``world_velocity``: NaN
    where unknown, which gives NaN rows). ``base`` ``diff_drive`` keeps
    linear.y at 0 (see the module docstring for the point ahead of the axis).
    """
    actions = np.asarray(actions, dtype=np.float64)
    n = actions.shape[0]
    twist = np.zeros((n, 3))
    if kind == "speed_turn":
        twist[:, 0], twist[:, 2] = actions[:, 0], actions[:, 1]
        return twist * scale
    ux, uy = actions[:, 0] * scale, actions[:, 1] * scale
    if kind == "world_velocity":
        if yaw is None:
            raise ValueError("world_velocity actions need the robots' headings (yaw), got None")
        c, s = np.cos(yaw), np.sin(yaw)
        ux, uy = c * ux + s * uy, -s * ux + c * uy
    elif kind != "body_velocity":
        raise ValueError(f"action kind must be one of {', '.join(ACTION_KINDS[1:])}, got {kind!r}")
    if base == "diff_drive":
        twist[:, 0], twist[:, 2] = ux, uy / lookahead
    elif base == "holonomic":
        twist[:, 0], twist[:, 1] = ux, uy
    else:
        raise ValueError(f"base must be one of {', '.join(BASES)}, got {base!r}")
    return twist


class CommandLimiter:
    """Speed and acceleration limits on every robot's twist, as a base controller applies them.

    A limit of 0 is off. The linear limits apply to the length of
    (linear.x, linear.y), so a holonomic command keeps its direction; the
    angular ones to angular.z. Acceleration is limited against the robot's
    previous command; a robot that has had no command for ``memory`` seconds
    is taken to stand still (its base's command timeout has stopped it).
    """

    def __init__(self, n_robots: int, max_linear_speed: float = 0.0, max_angular_speed: float = 0.0,
                 max_linear_accel: float = 0.0, max_angular_accel: float = 0.0, memory: float = 0.5,
                 period: float = 0.1) -> None:
        self.period = period
        self.max_linear_speed, self.max_angular_speed = max_linear_speed, max_angular_speed
        self.max_linear_accel, self.max_angular_accel = max_linear_accel, max_angular_accel
        self.memory = memory
        self.last = np.zeros((n_robots, 3))
        self.last_time = np.full(n_robots, -math.inf)

    def limit(self, twist: np.ndarray, sent: np.ndarray, now: float) -> np.ndarray:
        """``twist`` ``[n, 3]`` within the limits; the rows where ``sent`` ``[n]`` is true become the new previous."""
        out = np.array(twist, dtype=np.float64)
        linear, angular = out[:, :2], out[:, 2]
        if self.max_linear_speed > 0:
            _clamp_length(linear, self.max_linear_speed)
        if self.max_angular_speed > 0:
            np.clip(angular, -self.max_angular_speed, self.max_angular_speed, out=angular)
        elapsed = now - self.last_time
        recent = elapsed <= self.memory
        previous = np.where(recent[:, None], self.last, 0.0)
        # from rest, the first command may change by one period's worth (``period``: the node's tick)
        dt = np.where(recent, elapsed, self.period)
        if self.max_linear_accel > 0:
            change = linear - previous[:, :2]
            _clamp_length(change, self.max_linear_accel * dt[:, None])
            linear[:] = previous[:, :2] + change
        if self.max_angular_accel > 0:
            step = self.max_angular_accel * dt
            angular[:] = previous[:, 2] + np.clip(angular - previous[:, 2], -step, step)
        self.last[sent] = out[sent]
        self.last_time[sent] = now
        return out


def _clamp_length(vectors: np.ndarray, limit) -> None:
    """Shorten each row of ``vectors`` ``[n, 2]`` (in place) to at most ``limit`` (a number or ``[n, 1]``)."""
    length = np.linalg.norm(vectors, axis=1, keepdims=True)
    factor = np.minimum(1.0, np.divide(limit, length, out=np.ones_like(length), where=length > 0))
    vectors *= factor
