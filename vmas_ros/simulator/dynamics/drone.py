"""Quadrotor (drone) dynamics projected onto the plane, as VMAS 1.5 models it.

Action: (thrust, torque_x, torque_y, torque_z), body frame. A rigid-body
model with a 12-value state per env is integrated over one ``world.dt``:

    index  0..2   roll phi, pitch theta, yaw psi            [rad]
    index  3..5   body rates p, q, r                         [rad/s]
    index  6..8   velocity x_dot, y_dot, z_dot               [m/s]
    index  9..11  position x, y, z                           [m]

with the thrust along the body z axis and Euler's equations for the rates
(diagonal inertia ``I_xx, I_yy, I_zz``). A hover thrust ``mass * g`` is
always added to the commanded thrust, so a zero action keeps the drone level.

The engine integrates forces on a planar body, so, as for the kinematic
models (see ``_kinematic``), each step the model's change is turned into the
force and yaw torque the engine's semi-implicit Euler step needs. Faithful to
VMAS 1.5 (and needed for parity with it), the planar force is the one that
makes the agent's velocity equal to the model's *velocity change* over the
step divided by dt (``delta x_dot / dt``, about the model's acceleration),
and the yaw torque makes the agent's angular velocity equal to
``delta r / dt``. Before each step the model's x, y and yaw are overwritten
with the agent's position and rotation, so contacts and the engine's drag
feed back into the model through them.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Optional, Tuple, Union

import torch
from torch import Tensor

from vmas_ros.simulator.dynamics._kinematic import KinematicDynamics
from vmas_ros.simulator.utils import TorchUtils

if TYPE_CHECKING:
    from vmas_ros.simulator.world import World

#: size of the model's state (see the module docstring for the layout)
STATE_SIZE = 12
#: roll or pitch beyond this [rad] counts as a crash (``needs_reset``)
MAX_TILT = 30 * (math.pi / 180)


class Drone(KinematicDynamics):
    """Rigid-body quadrotor turned into planar force and yaw torque.

    Reuses the Euler / RK4 integrators of ``KinematicDynamics`` (they work on
    any state size); the commands are held constant over the step.

    Args:
        world: the world the agent lives in (its ``dt`` and ``batch_dim``).
        I_xx, I_yy, I_zz: principal moments of inertia [kg m^2] (defaults:
            a ~1 kg quadrotor, as in VMAS).
        integration: ``"rk4"`` (default) or ``"euler"``.

    Attributes:
        drone_state: [batch, 12] model state, zero (level, at rest) after reset.
        g: gravity [m/s^2] the hover thrust compensates.
    """

    def __init__(
        self,
        world: "World",
        I_xx: float = 8.1e-3,
        I_yy: float = 8.1e-3,
        I_zz: float = 14.2e-3,
        integration: str = "rk4",
    ) -> None:
        super().__init__(world, integration)
        for name, value in (("I_xx", I_xx), ("I_yy", I_yy), ("I_zz", I_zz)):
            if not value > 0:
                raise ValueError(f"{name} must be > 0 (a moment of inertia), got {value!r}")
        self.I_xx, self.I_yy, self.I_zz = I_xx, I_yy, I_zz
        self.g = 9.81
        self.drone_state = torch.zeros(world.batch_dim, STATE_SIZE, device=world.device)

    def reset(self, index: Optional[Union[Tensor, int]] = None) -> None:
        """Level and at rest again in the selected envs (all when ``index`` is None)."""
        if index is None:
            self.drone_state = torch.zeros_like(self.drone_state)
        else:
            self.drone_state = TorchUtils.where_from_index(index, 0.0, self.drone_state)

    def zero_grad(self) -> None:
        self.drone_state = self.drone_state.detach()

    @property
    def needed_action_size(self) -> int:
        return 4

    def needs_reset(self) -> Tensor:
        """[batch] bool: roll or pitch beyond +-30 degrees (the model is only trusted near level)."""
        return (self.drone_state[:, :2].abs() > MAX_TILT).any(dim=-1)

    def commands(self) -> Tuple[Tensor, Tensor]:
        """(total thrust [batch], body torques [batch, 3]); the hover thrust is added here."""
        u = self.agent.action.u
        return u[:, 0] + self.agent.mass * self.g, u[:, 1:4]

    def f(self, state: Tensor, thrust: Tensor, torque: Tensor) -> Tensor:
        """d(state)/dt, [batch, 12], for thrust [batch] and body torques [batch, 3]."""
        roll, pitch, yaw = state[:, 0], state[:, 1], state[:, 2]
        p, q, r = state[:, 3], state[:, 4], state[:, 5]
        cos_r, sin_r = torch.cos(roll), torch.sin(roll)
        cos_p, sin_p = torch.cos(pitch), torch.sin(pitch)
        cos_y, sin_y = torch.cos(yaw), torch.sin(yaw)
        mass = self.agent.mass
        # the body z axis in the world frame, scaled by the thrust
        accel_x = (cos_r * sin_p * cos_y + sin_r * sin_y) * thrust / mass
        accel_y = (cos_r * sin_p * sin_y - sin_r * cos_y) * thrust / mass
        accel_z = (cos_r * cos_p) * thrust / mass - self.g
        # Euler's rotation equations for a diagonal inertia tensor
        p_dot = (torque[:, 0] - (self.I_yy - self.I_zz) * q * r) / self.I_xx
        q_dot = (torque[:, 1] - (self.I_zz - self.I_xx) * p * r) / self.I_yy
        r_dot = (torque[:, 2] - (self.I_xx - self.I_yy) * p * q) / self.I_zz
        # attitude rates are taken equal to the body rates (small-angle kinematics, as in VMAS)
        return torch.stack(
            (p, q, r, p_dot, q_dot, r_dot, accel_x, accel_y, accel_z, state[:, 6], state[:, 7], state[:, 8]),
            dim=-1,
        )

    def process_action(self) -> None:
        agent = self.agent
        s = agent.state
        old = self.drone_state
        # the engine owns the planar position and the yaw: contacts may have moved them
        state = torch.cat((old[:, :2], s.rot, old[:, 3:9], s.pos, old[:, 11:]), dim=-1)
        step = self.euler if self.integration == "euler" else self.runge_kutta
        delta = step(state, *self.commands())
        self.drone_state = state + delta
        dt = self.dt
        accel = (delta[:, 6:8] - s.vel * dt) / dt**2
        ang_accel = (delta[:, 5:6] - s.ang_vel * dt) / dt**2
        s.force = agent.mass * accel
        s.torque = agent.moment_of_inertia * ang_accel
