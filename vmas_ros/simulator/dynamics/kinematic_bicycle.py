"""Kinematic bicycle dynamics for car-like robots (front-wheel steering).

Action: (speed [m/s], steering angle [rad]). The model is the one commonly
used for planning car trajectories (Polack et al., IV 2017, eq. 2): the
centre of gravity moves at slip angle ``beta`` relative to the heading, with
``tan(beta) = l_r / (l_f + l_r) * tan(delta)``, and the heading turns at
``v * cos(beta) * tan(delta) / (l_f + l_r)``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.dynamics._kinematic import KinematicDynamics

if TYPE_CHECKING:
    from vmas_ros.simulator.world import World


class KinematicBicycle(KinematicDynamics):
    """Bicycle kinematics turned into force and torque (see ``_kinematic``).

    Args:
        world: the world the agent lives in (its ``dt`` is the step horizon).
        width: vehicle width; kept for scenarios and rendering, unused here.
        l_f: distance from the centre of gravity to the front axle.
        l_r: distance from the centre of gravity to the rear axle.
        max_steering_angle: steering commands are clipped to +/- this [rad],
            since real steering racks saturate.
        integration: ``"rk4"`` (default, as VMAS 1.5) or ``"euler"``.
    """

    def __init__(
        self,
        world: "World",
        width: float,
        l_f: float,
        l_r: float,
        max_steering_angle: float,
        integration: str = "rk4",
    ) -> None:
        super().__init__(world, integration)
        if not l_f + l_r > 0:
            raise ValueError(f"wheelbase l_f + l_r must be > 0, got l_f={l_f}, l_r={l_r}")
        self.width = width
        self.l_f = l_f
        self.l_r = l_r
        self.max_steering_angle = max_steering_angle

    @property
    def needed_action_size(self) -> int:
        return 2

    def commands(self) -> Tuple[Tensor, Tensor]:
        """(steering, speed), the argument order of ``f``; steering is clipped."""
        u = self.agent.action.u
        steering = u[:, 1].clamp(-self.max_steering_angle, self.max_steering_angle)
        return steering, u[:, 0]

    def f(self, state: Tensor, steering_command: Tensor, v_command: Tensor) -> Tensor:
        """d(x, y, theta)/dt of the centre of gravity for speed and steering angle."""
        wheelbase = self.l_f + self.l_r
        tan_steer = torch.tan(steering_command)
        # atan2(y, 1) == atan(y) mathematically; it is used (and the products below
        # are ordered) to round exactly like VMAS, so float32 trajectories stay
        # comparable through contacts, which amplify last-bit differences
        beta = torch.atan2(tan_steer * self.l_r / wheelbase, torch.ones_like(tan_steer))
        heading = state[:, 2] + beta
        return torch.stack(
            (
                v_command * torch.cos(heading),
                v_command * torch.sin(heading),
                v_command / wheelbase * torch.cos(beta) * tan_steer,
            ),
            dim=-1,
        )
