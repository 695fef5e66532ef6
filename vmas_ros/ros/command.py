"""Velocity commands (``cmd_vel``) to agent actions, for every dynamics model.

ROS drives robots with body-frame velocities (REP 103: x forward, y left, yaw
counter-clockwise). Agents take whatever their dynamics model expects, so each
agent gets a small translation:

- Holonomic (force) agents: a one-step (dead-beat) velocity controller. With
  drag ``z`` the world updates ``v' = (1 - z) v + F / m * dt`` (summed over
  substeps), so ``F = m (v_cmd - (1 - z) v) / dt`` reaches the command in one
  step when nothing else pushes; it is clamped to the action range, which is
  how force limits show.
- HolonomicWithRotation: the same for yaw rate with the moment of inertia.
- Agents with a VMAS ``VelocityController`` (``agent.controller``): the action
  already is a velocity in the world frame.
- DiffDrive: (forward speed, yaw rate) is its action; both get a dead-beat
  drag compensation, because these models aim at the commanded motion and
  drag then removes ``drag * v`` each step.
- KinematicBicycle: (speed, steering) with the steering angle that gives the
  commanded yaw rate under the bicycle model, compensated the same way.

Everything is batched over envs; a command applies to one env (``env_index``)
and the other envs keep the fallback action.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.dynamics.diff_drive import DiffDrive
from vmas_ros.simulator.dynamics.holonomic import Holonomic
from vmas_ros.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation
from vmas_ros.simulator.dynamics.kinematic_bicycle import KinematicBicycle


#: largest accepted |component| of a command (m/s, rad/s). Far above any simulated agent's speed,
#: so no real command is refused; a bigger value is a sender's bug (units, uninitialised memory),
#: and values past float32's range (3.4e38) would turn into inf and then NaN in the controller.
MAX_COMMAND = 1e6
COMMAND_FIELDS = ("linear.x", "linear.y", "angular.z")


def check_command(values: Sequence[float], fields: Sequence[str] = COMMAND_FIELDS) -> Optional[Tuple[str, str]]:
    """Why a velocity command cannot be used, as (kind, details); None when it can.

    ``kind`` is "with NaN or inf" or "with huge values"; ``details`` names each
    bad component with its value and what was expected. Such a command is
    dropped, not clamped: clamping would turn garbage into full speed, while
    dropping keeps the last good command (until ``cmd_vel_timeout``) or the
    fallback control, and the simulation state stays finite.
    """
    bad = [f"{field}={value!r}" for field, value in zip(fields, values)
           if not isinstance(value, (int, float)) or not math.isfinite(value) or abs(value) > MAX_COMMAND]
    if not bad:
        return None
    non_finite = any(isinstance(v, (int, float)) and not math.isfinite(v) for v in values)
    kind = "with NaN or inf" if non_finite else "with huge values"
    return kind, f"{', '.join(bad)}; expected finite values with |value| <= {MAX_COMMAND:g}"


def body_to_world(vx: Tensor, vy: Tensor, yaw: Tensor) -> Tuple[Tensor, Tensor]:
    """Rotate a body-frame velocity into the world frame."""
    c, s = torch.cos(yaw), torch.sin(yaw)
    return vx * c - vy * s, vx * s + vy * c


def world_to_body(vx: Tensor, vy: Tensor, yaw: Tensor) -> Tuple[Tensor, Tensor]:
    """Rotate a world-frame velocity into the body frame."""
    c, s = torch.cos(yaw), torch.sin(yaw)
    return vx * c + vy * s, -vx * s + vy * c


def command_to_action(agent, world, env_index: int, linear: Tuple[float, float], angular_z: float) -> Tensor:
    """The action row [action_size] that makes ``agent`` in ``env_index`` follow the command."""
    device = world.device
    vx_b = torch.tensor(float(linear[0]), device=device)
    vy_b = torch.tensor(float(linear[1]), device=device)
    wz = torch.tensor(float(angular_z), device=device)
    yaw = agent.state.rot[env_index, 0]
    dynamics = agent.dynamics
    multiplier = agent.action.u_multiplier_tensor
    u_range = agent.action.u_range_tensor
    action = torch.zeros(agent.action_size, device=device)
    if isinstance(dynamics, (DiffDrive, KinematicBicycle)):
        # kinematic models aim at the commanded motion, then drag takes its share:
        # v' = v_target - drag * v, so the target carries drag * v on top (dead-beat)
        drag = world.drag if agent.drag is None else agent.drag
        heading = torch.stack([torch.cos(yaw), torch.sin(yaw)])
        speed = vx_b + drag * torch.dot(agent.state.vel[env_index], heading)
        turn = wz + drag * agent.state.ang_vel[env_index, 0]
        action[0] = speed
        action[1] = turn if isinstance(dynamics, DiffDrive) else _bicycle_steering(dynamics, speed, turn)
    elif hasattr(agent, "controller"):
        action[0], action[1] = body_to_world(vx_b, vy_b, yaw)
        if agent.action_size > 2 and isinstance(dynamics, HolonomicWithRotation):
            action[2] = _deadbeat(agent, world, wz, agent.state.ang_vel[env_index, 0], agent.moment_of_inertia)
    elif isinstance(dynamics, (Holonomic, HolonomicWithRotation)):
        wx, wy = body_to_world(vx_b, vy_b, yaw)
        vel = agent.state.vel[env_index]
        action[0] = _deadbeat(agent, world, wx, vel[0], agent.mass)
        action[1] = _deadbeat(agent, world, wy, vel[1], agent.mass)
        if isinstance(dynamics, HolonomicWithRotation):
            action[2] = _deadbeat(agent, world, wz, agent.state.ang_vel[env_index, 0], agent.moment_of_inertia)
    else:
        raise ValueError(
            f"agent {agent.name!r} uses {type(dynamics).__name__}, which cmd_vel cannot drive "
            f"(supported: Holonomic, HolonomicWithRotation, DiffDrive, KinematicBicycle, VelocityController)"
        )
    action = action / multiplier
    return torch.maximum(torch.minimum(action, u_range), -u_range)


def _deadbeat(agent, world, target: Tensor, current: Tensor, inertia: float) -> Tensor:
    drag = world.drag if agent.drag is None else agent.drag
    return inertia * (target - (1 - drag) * current) / world.dt


def _bicycle_steering(dynamics: KinematicBicycle, speed: Tensor, yaw_rate: Tensor) -> Tensor:
    """Steering angle whose bicycle-model yaw rate ``v sin(beta) / l_r`` equals ``yaw_rate``."""
    if float(speed) == 0.0:
        return torch.zeros((), device=speed.device)
    sin_beta = (yaw_rate * dynamics.l_r / speed).clamp(-1.0, 1.0)
    beta = torch.asin(sin_beta)
    steering = torch.atan(torch.tan(beta) * (dynamics.l_f + dynamics.l_r) / dynamics.l_r)
    limit = float(dynamics.max_steering_angle)
    return steering.clamp(-limit, limit) if math.isfinite(limit) else steering


class CommandGate:
    """Checks every incoming velocity command (ROS or Foxglove) and names the bad ones.

    One warning per agent at most every ``period`` seconds: a broken teleop
    publishes at tens of Hz, and one line per agent says enough.
    """

    def __init__(self, logger, agent_names: Sequence[str], period: float = 2.0) -> None:
        self.logger, self.names, self.period = logger, list(agent_names), period
        self._warned: dict = {}  # agent index -> monotonic time of its last warning

    def refuse(self, agent_index: int, values: Sequence[float], source: str) -> bool:
        """True, after a throttled warning naming the agent, source and values, when the command is unusable."""
        import time

        problem = check_command(values)
        if problem is None:
            return False
        now = time.monotonic()
        if now - self._warned.get(agent_index, -math.inf) > self.period:
            self._warned[agent_index] = now
            kind, details = problem
            self.logger.warning(f"dropped a cmd_vel {kind} for {self.names[agent_index]} ({source}): {details}")
        return True
