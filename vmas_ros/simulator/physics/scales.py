"""Per-env scales of every entity's mass and drag: the same robots, a little heavier or draggier in each env.

A world is built with one mass and one drag per entity, ``[N, 1]`` columns
that broadcast over the batch. Training for robots whose dynamics differ from
the model's draws these per env (``vmas_ros.envs.randomisation``): then mass
(with the moment of inertia) and drag become ``[N, B]`` and the integrator
reads them per env::

    v' = (1 - drag * s_drag) * v + f / (m * s_mass) * dt

Only the step's own constants change (``physics.constants``): the mass the
integrator divides by, friction's cap and the drag. What scenarios and
dynamics models read (``agent.mass``) and gravity's force stay as built.

Without scales (the default) nothing here runs and the constants keep their
``[N, 1]`` shape, so the step is the same as ever, bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import torch
from torch import Tensor

__all__ = ["DynamicsScales", "apply", "dynamics_columns", "moved"]


@dataclass
class DynamicsScales:
    """``mass`` and ``drag`` scales, each ``[N, B]`` in ``world.entities`` order (1: as built)."""

    mass: Tensor
    drag: Tensor


def apply(world, mass: Optional[Tensor], drag: Optional[Tensor]) -> None:
    """``World.scale_dynamics``: check the scales and make them the world's.

    The first time, the world's tables are rebuilt, so that the step's
    constants take the per-env shape (and a compiled step compiles anew).
    From then on the new values are written into the same tensors, the
    constants' included: a compiled step reads those afresh on every call.
    """
    shape = (len(world.entities), world.batch_dim)
    new = DynamicsScales(_checked(mass, "mass", shape, world.device, zero_ok=False),
                         _checked(drag, "drag", shape, world.device, zero_ok=True))
    current, tables = world._dynamics_scales, world._tables
    if current is None or tables is None or tables.scales is not current:
        world._dynamics_scales = new
        world._invalidate_tables()
        return
    current.mass.copy_(new.mass)
    current.drag.copy_(new.drag)
    constants = tables.step_constants
    if constants is not None:  # else built from the scales when the next step needs them
        keep, coord_mass, friction_cap = dynamics_columns(tables)
        constants.keep.copy_(keep)
        constants.mass.copy_(coord_mass)
        constants.friction_cap.copy_(friction_cap)
        torch.div(coord_mass, constants.sub_dt, out=constants.mass_over_dt)


def moved(scales: Optional[DynamicsScales], device: torch.device) -> Optional[DynamicsScales]:
    """``scales`` on ``device`` (None stays None)."""
    return None if scales is None else DynamicsScales(scales.mass.to(device), scales.drag.to(device))


def dynamics_columns(tables) -> Tuple[Tensor, Tensor, Tensor]:
    """``(keep [N, 1], mass [3, N, 1], friction cap [3, N, 1])`` of the step's constants from the world's
    tables (``keep = 1 - drag``; mass, mass and moment of inertia per coordinate; friction times them);
    ``[N, B]`` and ``[3, N, B]`` when the tables carry per-env scales."""
    mass, inertia, drag = tables.mass[..., 0], tables.inertia[..., 0], tables.drag[..., 0]
    scales = tables.scales
    if scales is not None:
        if scales.mass.shape[0] != mass.shape[0]:
            raise ValueError(f"the world has {mass.shape[0]} entities, but its mass and drag scales were set for "
                             f"{scales.mass.shape[0]}: call scale_dynamics again after adding entities")
        mass, inertia, drag = mass * scales.mass, inertia * scales.mass, drag * scales.drag
    coord_mass = torch.stack([mass, mass, inertia])
    linear, angular = tables.linear_friction[..., 0], tables.angular_friction[..., 0]
    friction_cap = torch.stack([linear * mass, linear * mass, angular * inertia])
    return 1 - drag, coord_mass, friction_cap


def _checked(value: Optional[Tensor], name: str, shape: tuple, device: torch.device, zero_ok: bool) -> Tensor:
    """``value`` as a float32 ``shape`` tensor on ``device`` (None: ones); a ValueError names what is wrong.
    Scales are finite and positive; ``zero_ok``: 0 too (no drag at all)."""
    if value is None:
        return torch.ones(shape, device=device)
    if not isinstance(value, Tensor):
        raise ValueError(f"{name} scale must be a tensor of shape {shape} (entities x envs), got {type(value).__name__}")
    if tuple(value.shape) != shape:
        raise ValueError(f"{name} scale has shape {tuple(value.shape)}, expected {shape} (entities x envs)")
    value = value.to(device=device, dtype=torch.float32)
    if not bool(torch.isfinite(value).all()) or not bool((value >= 0 if zero_ok else value > 0).all()):
        raise ValueError(f"{name} scale must be finite and {'>=' if zero_ok else '>'} 0 everywhere, got values in "
                         f"[{float(value.min())}, {float(value.max())}]")
    return value.clone()
