"""How a ros2_control mobile base turns a velocity command into motion, for a whole fleet at once.

State is struct-of-arrays over the ``n`` robots (:class:`MotionState`):

* ``pose [n, 3]``: x, y (m) and yaw (rad, in [-pi, pi)) in the shared odom frame;
* ``command [n, 3]``: the controller's last output, body frame (vx forward, vy
  left, wz counter-clockwise; REP 103);
* ``velocity [n, 3]``: what the robot actually does, body frame.

One step (:func:`step`) applies, in the order a real base does:

1. the drive: a ``diff_drive`` base cannot move sideways, so the target's vy is dropped;
2. the controller's limiter: acceleration against the controller's *previous
   output*, then speed (diff_drive_controller limits the command it sends,
   not what the wheels achieve, so a sluggish robot is not driven harder);
3. the robot's response: a first-order lag of the velocity towards the command
   (motor and inertia), ``v += (command - v) * (1 - exp(-dt / tau))``: the
   exact response to a constant command over ``dt``, whatever the step;
4. the pose integrated with that velocity, rotated into the odom frame at the
   heading of mid-step (second order in ``dt`` for turning robots).

For a holonomic base the linear limits bound the norm of (vx, vy), which keeps
the direction of a clipped command; for a diff-drive base that norm is |vx|.
Every function here is pure: arrays in, new arrays out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DriveModel", "MotionState", "limit_command", "respond", "integrate", "step", "wrap_angle"]


@dataclass(frozen=True)
class DriveModel:
    """A base's drive and limits; accelerations and ``velocity_lag`` of 0 mean "none"."""

    holonomic: bool = True
    max_linear_speed: float = 1.0
    max_angular_speed: float = 2.0
    max_linear_accel: float = 0.0
    max_angular_accel: float = 0.0
    velocity_lag: float = 0.0

    @classmethod
    def from_params(cls, params) -> "DriveModel":
        """The model that robot_fleet's parameter values describe."""
        return cls(holonomic=params.drive == "holonomic", max_linear_speed=params.max_linear_speed,
                   max_angular_speed=params.max_angular_speed, max_linear_accel=params.max_linear_accel,
                   max_angular_accel=params.max_angular_accel, velocity_lag=params.velocity_lag)


@dataclass
class MotionState:
    """The fleet's motion: ``pose [n, 3]``, ``command [n, 3]`` and ``velocity [n, 3]`` (see the module)."""

    pose: np.ndarray
    command: np.ndarray
    velocity: np.ndarray

    @classmethod
    def at_rest(cls, pose: np.ndarray) -> "MotionState":
        """Robots standing at ``pose [n, 3]``."""
        pose = np.array(pose, dtype=np.float64).reshape(-1, 3)
        pose[:, 2] = wrap_angle(pose[:, 2])
        return cls(pose=pose, command=np.zeros_like(pose), velocity=np.zeros_like(pose))


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """``angle`` (any shape) mapped into [-pi, pi)."""
    return (np.asarray(angle) + math.pi) % (2 * math.pi) - math.pi


def _clamp_norm(vectors: np.ndarray, limit: float) -> np.ndarray:
    """``vectors [n, k]`` scaled down where their norm exceeds ``limit`` (direction kept)."""
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    scale = np.minimum(1.0, limit / np.maximum(norm, 1e-300))
    return vectors * scale


def limit_command(target: np.ndarray, previous: np.ndarray, dt: float, model: DriveModel) -> np.ndarray:
    """The controller's output ``[n, 3]`` for ``target [n, 3]`` after ``previous [n, 3]``, ``dt`` s later.

    The drive drops a diff-drive target's vy; the change from ``previous`` is
    bounded by the acceleration limits times ``dt``, then the result by the
    speed limits.
    """
    out = np.array(target, dtype=np.float64)
    if not model.holonomic:
        out[:, 1] = 0.0
    change = out - previous
    if model.max_linear_accel > 0:
        change[:, :2] = _clamp_norm(change[:, :2], model.max_linear_accel * dt)
    if model.max_angular_accel > 0:
        bound = model.max_angular_accel * dt
        change[:, 2] = np.clip(change[:, 2], -bound, bound)
    out = previous + change
    out[:, :2] = _clamp_norm(out[:, :2], model.max_linear_speed)
    out[:, 2] = np.clip(out[:, 2], -model.max_angular_speed, model.max_angular_speed)
    return out


def respond(velocity: np.ndarray, command: np.ndarray, dt: float, lag: float) -> np.ndarray:
    """The velocity ``[n, 3]`` after ``dt`` s of tracking ``command [n, 3]`` with time constant ``lag``."""
    if lag <= 0:
        return np.array(command, dtype=np.float64)
    return velocity + (command - velocity) * -math.expm1(-dt / lag)


def integrate(pose: np.ndarray, velocity: np.ndarray, dt: float) -> np.ndarray:
    """The pose ``[n, 3]`` after ``dt`` s at body-frame ``velocity [n, 3]`` (mid-step heading)."""
    heading = pose[:, 2] + 0.5 * velocity[:, 2] * dt
    cos, sin = np.cos(heading), np.sin(heading)
    out = np.empty_like(pose)
    out[:, 0] = pose[:, 0] + (cos * velocity[:, 0] - sin * velocity[:, 1]) * dt
    out[:, 1] = pose[:, 1] + (sin * velocity[:, 0] + cos * velocity[:, 1]) * dt
    out[:, 2] = wrap_angle(pose[:, 2] + velocity[:, 2] * dt)
    return out


def step(state: MotionState, target: np.ndarray, dt: float, model: DriveModel) -> MotionState:
    """The fleet ``dt`` s later, each robot's controller given ``target [n, 3]`` (body frame)."""
    command = limit_command(target, state.command, dt, model)
    velocity = respond(state.velocity, command, dt, model.velocity_lag)
    return MotionState(pose=integrate(state.pose, velocity, dt), command=command, velocity=velocity)
