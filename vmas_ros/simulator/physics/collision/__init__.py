"""Collisions: one kernel per pair of shape kinds, found through one table.

The world's pair tables (:mod:`vmas_ros.simulator.tables`) group every
colliding entity pair by the kinds of their shapes, sorted by name, once per
layout; a large group of spheres (a swarm) has no pair list but a grid that
finds its contacts each step (:mod:`.sphere_grid`). A step runs each group's kernel on all its pairs and envs at once and
adds the result onto the entities' forces (:mod:`..scatter`). Every kernel has
the same signature and returns :class:`PairForces`.
"""
from __future__ import annotations

from typing import Callable, Dict, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.layout import split_xy_stacked
from vmas_ros.simulator.physics.collision import box_box, box_line, box_sphere, line_line, line_sphere, sphere_sphere
from vmas_ros.simulator.physics.collision.contact import PairForces
from vmas_ros.simulator.physics.collision.sphere_grid import add_group_contact_forces
from vmas_ros.simulator.physics.scatter import add_pairs, add_pairs_opposite
from vmas_ros.simulator.physics.types import BodyState, StepParams
from vmas_ros.simulator.tables import PairTable, WorldTables

__all__ = ["KERNELS", "PairForces", "add_contact_forces", "pair_forces"]

#: (shape kind, shape kind), sorted -> kernel(pair table, q [3, N, B], params, exact) -> PairForces
KERNELS: Dict[Tuple[str, str], Callable[[PairTable, Tensor, StepParams, bool], PairForces]] = {
    ("sphere", "sphere"): sphere_sphere.forces,
    ("line", "sphere"): line_sphere.forces,
    ("box", "sphere"): box_sphere.forces,
    ("line", "line"): line_line.forces,
    ("box", "line"): box_line.forces,
    ("box", "box"): box_box.forces,
}


def add_contact_forces(force: Tensor, tables: WorldTables, q: Tensor, params: StepParams) -> None:
    """Add every pair's contact forces (and torques) onto ``force`` ``[3, N, B]``, in place.

    Worlds with joints compute and sum their contacts exactly as VMAS does
    (``exact``): stiff joints amplify a last-bit difference within a few steps.
    """
    exact = tables.joints is not None
    for pair in tables.pairs:
        pushed = KERNELS[pair.kind](pair, q, params, exact)
        target = force if pushed.on_a.shape[0] == 3 else force[:2]
        if pushed.on_b is None:
            add_pairs_opposite(target, pair, pushed.on_a)
        else:
            add_pairs(target, pair, pushed.on_a, pushed.on_b)
    for group in tables.sphere_groups:
        add_group_contact_forces(force, group, q, params)


def pair_forces(pair: PairTable, state: BodyState, params: StepParams) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """Contact forces ``[P, B, 2]`` and torques ``[P, B, 1]`` on both members of one kernel's pairs,
    computed exactly (VMAS's arithmetic); the vector-layout face of :data:`KERNELS` for tests and tools."""
    q = torch.cat([split_xy_stacked(state.pos.contiguous()), state.rot[..., 0].unsqueeze(0)])
    pushed = KERNELS[pair.kind](pair, q, params, True)
    on_b = -pushed.on_a if pushed.on_b is None else pushed.on_b
    if pushed.on_a.shape[0] == 2:
        zero = torch.zeros_like(pushed.on_a[0])
        on_a, on_b = torch.cat([pushed.on_a, zero[None]]), torch.cat([on_b, zero[None]])
    else:
        on_a = pushed.on_a
    return (on_a[:2].permute(1, 2, 0), on_b[:2].permute(1, 2, 0), on_a[2].unsqueeze(-1), on_b[2].unsqueeze(-1))
