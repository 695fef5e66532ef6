"""The physics step's data: world parameters, and the state of every entity as planar tensors.

Entity-major and planar on purpose: the state is ``q`` = (x, y, angle) and
``v`` = (vx, vy, angular velocity), each ``[3, N, B]`` for ``N`` entities in
``B`` envs, so per-entity constants (mass, limits, masks) broadcast as
``[3, N, 1]`` columns over each entity's contiguous batch, one elementwise op
updates every coordinate, and gathering a pair's members copies whole blocks.
A batch-major ``[B, N, 2]`` layout makes every broadcast op run two floats at
a time, and ops over a trailing dim of 2 do not vectorise.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import torch
from torch import Tensor

from vmas_ros.simulator.layout import join_xy, split_xy_stacked

__all__ = ["BodyState", "PlanarState", "StepParams", "stack_actions"]


@dataclass
class StepParams:
    """World-level constants of the step (VMAS's ``World`` arguments)."""

    dt: float
    substeps: int
    collision_force: float
    joint_force: float
    torque_constraint_force: float
    contact_margin: float
    x_semidim: Optional[float]
    y_semidim: Optional[float]
    #: "batch": a pair near in any env interacts in every env (VMAS 1.5, bit parity);
    #: "env": each env decides for itself (envs independent of each other)
    broad_phase: str = "batch"


@dataclass
class PlanarState:
    """State of all entities as stacked planar components.

    ``q`` is ``[3, N, B]``: x, y and angle; ``v`` is ``[3, N, B]``: vx, vy and
    angular velocity.
    """

    q: Tensor
    v: Tensor

    @classmethod
    def from_vectors(cls, state: "BodyState") -> "PlanarState":
        q = torch.cat([split_xy_stacked(state.pos.contiguous()), state.rot[..., 0].unsqueeze(0)])
        v = torch.cat([split_xy_stacked(state.vel.contiguous()), state.ang_vel[..., 0].unsqueeze(0)])
        return cls(q, v)

    def to_vectors(self) -> "BodyState":
        q, v = self.q, self.v
        return BodyState(join_xy(q[0], q[1]), join_xy(v[0], v[1]), q[2].unsqueeze(-1), v[2].unsqueeze(-1))


@dataclass
class BodyState:
    """State of all entities in VMAS's vector layout, for tools and tests: pos/vel ``[N, B, 2]``,
    rot/ang_vel ``[N, B, 1]``."""

    pos: Tensor
    vel: Tensor
    rot: Tensor
    ang_vel: Tensor


def stack_actions(force: Tensor, torque: Tensor) -> Tensor:
    """Per-entity force ``[N, B, 2]`` and torque ``[N, B, 1]`` as one ``[3, N, B]`` (fx, fy, torque)."""
    return torch.cat([split_xy_stacked(force.contiguous()), torque[..., 0].unsqueeze(0)])
