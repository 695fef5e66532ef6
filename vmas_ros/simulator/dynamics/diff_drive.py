"""Differential-drive (unicycle) dynamics for wheeled robots such as TurtleBots.

Action: (forward speed [m/s], turn rate [rad/s]). The agent cannot slide
sideways by itself; this is the model ROS ``cmd_vel`` (linear.x, angular.z)
describes, which is why it is the usual choice for real ground robots.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.dynamics._kinematic import KinematicDynamics

if TYPE_CHECKING:
    from vmas_ros.simulator.world import World


class DiffDrive(KinematicDynamics):
    """Unicycle kinematics turned into force and torque (see ``_kinematic``).

    Args:
        world: the world the agent lives in; its ``dt`` is the horizon over
            which the command is integrated.
        integration: ``"rk4"`` (default, accurate on arcs) or ``"euler"``.
    """

    def __init__(self, world: "World", integration: str = "rk4") -> None:
        super().__init__(world, integration)

    @property
    def needed_action_size(self) -> int:
        return 2

    def commands(self) -> Tuple[Tensor, Tensor]:
        u = self.agent.action.u
        return u[:, 0], u[:, 1]

    def f(self, state: Tensor, u_command: Tensor, ang_vel_command: Tensor) -> Tensor:
        """d(x, y, theta)/dt of a unicycle moving at ``u_command`` along its heading."""
        theta = state[:, 2]
        return torch.stack(
            (u_command * torch.cos(theta), u_command * torch.sin(theta), ang_vel_command), dim=-1
        )
