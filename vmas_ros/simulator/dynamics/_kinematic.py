"""Shared machinery for kinematic models (differential drive, bicycle).

A kinematic model says how the pose (x, y, theta) *should* change under a
command; the engine, however, only integrates forces. Each step we therefore
integrate the model over one ``world.dt`` to get the desired pose change and
pick the force and torque that make the engine's semi-implicit Euler step land
exactly there (absent drag, friction, contacts and with one substep):

    v_next = v + a * dt,   p_next = p + v_next * dt   =>   a = (dp / dt - v) / dt

so the agent follows the model while still colliding like any other body.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.dynamics.common import Dynamics

if TYPE_CHECKING:
    from vmas_ros.simulator.world import World

_INTEGRATIONS = ("euler", "rk4")


class KinematicDynamics(Dynamics):
    """Base of kinematic models; subclasses give ``f`` and ``commands``.

    ``f(state, *commands)`` returns d(x, y, theta)/dt as a [batch, 3] tensor for
    a [batch, 3] pose; ``commands()`` reads the agent's action into the
    arguments ``f`` expects. Commands are held constant over the step.
    """

    def __init__(self, world: "World", integration: str) -> None:
        super().__init__()
        if integration not in _INTEGRATIONS:
            raise ValueError(f"integration must be one of {_INTEGRATIONS}, got {integration!r}")
        self.world = world
        self.dt = world.dt
        self.integration = integration

    # -- to implement --------------------------------------------------------
    def f(self, state: Tensor, *commands: Tensor) -> Tensor:  # pragma: no cover - abstract
        raise NotImplementedError

    def commands(self) -> Tuple[Tensor, ...]:  # pragma: no cover - abstract
        raise NotImplementedError

    # -- integrators ---------------------------------------------------------
    def euler(self, state: Tensor, *commands: Tensor) -> Tensor:
        """Pose change over one dt using the derivative at the start."""
        return self.f(state, *commands) * self.dt

    def runge_kutta(self, state: Tensor, *commands: Tensor) -> Tensor:
        """Pose change over one dt with classic 4th-order Runge-Kutta.

        More accurate on curves: with Euler a turning robot drifts outwards
        because it moves along the tangent of the start heading for a whole dt.
        """
        dt = self.dt
        k1 = self.f(state, *commands)
        k2 = self.f(state + k1 * (dt / 2), *commands)
        k3 = self.f(state + k2 * (dt / 2), *commands)
        k4 = self.f(state + k3 * dt, *commands)
        return (k1 + 2 * k2 + 2 * k3 + k4) * (dt / 6)

    # -- force computation ---------------------------------------------------
    def process_action(self) -> None:
        agent = self.agent
        s = agent.state
        pose = torch.cat((s.pos, s.rot), dim=-1)  # [batch, 3]
        commands = self.commands()
        step = self.euler if self.integration == "euler" else self.runge_kutta
        delta = step(pose, *commands)
        dt = self.dt
        velocity = torch.cat((s.vel, s.ang_vel), dim=-1)
        accel = (delta - velocity * dt) / (dt * dt)
        s.force = accel[:, :2] * agent.mass
        s.torque = accel[:, 2:3] * agent.moment_of_inertia
