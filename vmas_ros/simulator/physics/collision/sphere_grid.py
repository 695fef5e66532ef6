"""Contacts in a large group of spheres, found through a hashed grid (the broad phase of a swarm).

Testing every pair of ``M`` spheres costs ``M^2 / 2`` per env. Two spheres
touch only when their centres are at most the sum of their radii apart, so
with square cells at least that wide, each sphere needs testing only against
the spheres in its own cell and the eight around it: the candidates of
:func:`~vmas_ros.simulator.physics.spatial_hash.candidates_near`, with the
group's spheres as both queries and targets. The narrow phase (the same soft
contact as every sphere pair, see :mod:`.sphere_sphere`) runs on that list,
masked where an entry is not a real candidate or holds a pair already counted
from its other member.

Exactness: a list longer than its room would lose contacts. The step records
the candidates per sphere it needed in ``group.needed`` (on the device); the
world reads it after the step and, in the rare step where it exceeds the
capacity, grows the capacity and computes the step again from the same state
(:meth:`vmas_ros.simulator.world.World.step`). No contact is ever dropped.
On the CPU that read is a memory load; on a GPU it would wait for the step,
see docs/swarm.md for the design there.
"""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator.masks import mask_ge, mask_le
from vmas_ros.simulator.physics.collision.contact import MIN_CONTACT_DIST, softplus_of_overlap
from vmas_ros.simulator.physics.spatial_hash import candidates_near
from vmas_ros.simulator.physics.types import StepParams

__all__ = ["add_group_contact_forces", "candidate_pairs"]


def candidate_pairs(x: Tensor, y: Tensor, n_members: int, cell: float, capacity: int):
    """Candidate pairs of spheres that may touch: ``(first, second, valid, needed)``.

    ``x``, ``y``: ``[L]`` centres, env-major (``L = B * M``, member ``m`` of env
    ``b`` at ``b * M + m``). Returns ``first`` and ``second`` ``[L * capacity]``
    flat indices of the two spheres of each candidate, ``valid`` (same shape,
    bool: a real candidate, of one env, with ``first < second``, so each pair
    appears once) and ``needed`` (0-d: the candidates per sphere the list
    needed, rounded up, which must not exceed ``capacity``).
    """
    first, second, valid, needed = candidates_near(x, y, n_members, x, y, n_members, cell, capacity)
    return first, second, valid & (second > first), needed


def add_group_contact_forces(force: Tensor, group, q: Tensor, params: StepParams) -> None:
    """Add the contact forces among ``group``'s spheres onto ``force`` ``[3, N, B]``, in place.

    ``group`` is a :class:`~vmas_ros.simulator.tables.SphereGroup`; its
    ``needed`` is raised to the candidates per sphere this call needed.
    """
    members, radius = group.members, group.radius
    n_members, batch = members.shape[0], q.shape[2]
    # [B * M] env-major copies: each env's members are one contiguous block
    x = torch.index_select(q[0], 0, members).t().reshape(-1)
    y = torch.index_select(q[1], 0, members).t().reshape(-1)
    first, second, valid, needed = candidate_pairs(x, y, n_members, group.cell, group.capacity)
    torch.maximum(group.needed, needed, out=group.needed)
    r = radius.repeat(batch)  # [B * M]
    dx = torch.index_select(x, 0, first).sub_(torch.index_select(x, 0, second))
    dy = torch.index_select(y, 0, first).sub_(torch.index_select(y, 0, second))
    dist_min = torch.index_select(r, 0, first).add_(torch.index_select(r, 0, second))
    dist = torch.addcmul(dx * dx, dy, dy).sqrt_()
    active = mask_ge(dist, MIN_CONTACT_DIST).mul_(mask_le(dist, dist_min)).mul_(valid)
    scale = softplus_of_overlap((dist_min - dist) / params.contact_margin).mul_(active).div_(dist.clamp_min(1e-8))
    scale.mul_(params.collision_force * params.contact_margin)
    fx, fy = dx * scale, dy * scale  # on the first sphere; the second gets the opposite
    on_x = torch.zeros_like(x).index_add_(0, first, fx).index_add_(0, second, fx, alpha=-1)
    on_y = torch.zeros_like(y).index_add_(0, first, fy).index_add_(0, second, fy, alpha=-1)
    force[0].index_add_(0, members, on_x.view(batch, n_members).t())
    force[1].index_add_(0, members, on_y.view(batch, n_members).t())
