"""The forces on each entity before contacts: actions, friction and gravity (paper, "The VMAS platform").

    f_i = f_action + f_friction + f_gravity   (then + contacts + joints)

Friction is Coulomb-like: it opposes the velocity with at most ``mu * m`` and
never reverses a velocity within one substep. The limit of an agent's action
force (``utils.clamp_norm``) is applied when the actions are assembled.
"""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator.geometry import norm_xy
from vmas_ros.simulator.masks import mask_ne
from vmas_ros.simulator.physics.constants import StepConstants
from vmas_ros.simulator.tables import WorldTables

__all__ = ["applied_forces", "friction"]


def applied_forces(actions: Tensor, v: Tensor, tables: WorldTables, c: StepConstants, may_write_actions: bool) -> Tensor:
    """``[3, N, B]`` action + friction + gravity, a tensor contacts and joints may be added into in place.

    ``may_write_actions``: the caller hands ``actions`` over, so it can be that
    tensor itself when nothing else is added (no copy).
    """
    force = actions
    if tables.has_friction:
        force = force + friction(v, c)
    if tables.has_gravity:
        force = force + c.gravity
    if force is actions and not may_write_actions and (tables.joints is not None or tables.pairs):
        force = force.clone()  # written in place by the contacts and joints
    return force


def friction(v: Tensor, c: StepConstants) -> Tensor:
    """Friction ``[3, N, B]`` opposing the velocity ``v``, never reversing it within one substep."""
    speed = norm_xy(v[0], v[1])
    speed = torch.stack([speed, speed, v[2].abs()])
    moving = mask_ne(speed, 0.0)
    inv = moving / (speed + (1 - moving))  # 1 / speed where moving, 0 elsewhere (exact)
    return -(v * inv) * torch.minimum(c.friction_cap, v.abs() * c.mass_over_dt)
