"""Contacts in a large group of spheres, found through a uniform grid (the broad phase of a swarm).

Testing every pair of ``M`` spheres costs ``M^2 / 2`` per env. Two spheres
touch only when their centres are at most the sum of their radii apart, so
with square cells at least that wide, each sphere needs testing only against
the spheres in its own cell and the eight around it. Per step and env:

1. each sphere gets the integer cell ``(floor(x / h), floor(y / h))``, and one
   sort key made of (env, cell row, cell column);
2. the keys are sorted: the three cells ``cx - 1 .. cx + 1`` of one row are
   then one contiguous run, found with two binary searches
   (``torch.searchsorted``), so the neighbourhood is three runs;
3. each run offers ``capacity`` candidate slots; the narrow phase (the same
   soft contact as every sphere pair, see :mod:`.sphere_sphere`) runs on all
   slots at once, masked where a slot is empty or holds a pair already
   counted from its other member.

Nothing leaves the device: the work is a fixed number of batched ops whose
shapes depend only on the group's size, the number of envs and ``capacity``.

Exactness: a run longer than ``capacity`` would lose contacts. The step
records the longest run it saw in ``group.needed`` (on the device); the world
reads it after the step and, in the rare step where it exceeds the capacity,
grows the capacity and computes the step again from the same state
(:meth:`vmas_ros.simulator.world.World.step`). No contact is ever dropped.
On the CPU that read is a memory load; on a GPU it would wait for the step,
see docs/swarm.md for the design there.
"""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator.masks import mask_ge, mask_le
from vmas_ros.simulator.physics.collision.contact import MIN_CONTACT_DIST, softplus_of_overlap
from vmas_ros.simulator.physics.types import StepParams

__all__ = ["add_group_contact_forces", "candidate_slots"]

#: cell coordinates are clamped to +-LIMIT (entities farther out share the edge cells: still exact,
#: only more candidates there); 21 bits per coordinate and the env index above them fit an int64
_BITS = 21
_LIMIT = (1 << (_BITS - 1)) - 2
_OFFSET = 1 << (_BITS - 1)
_ROW = 1 << _BITS


def _cells(x: Tensor, inv_h: float) -> Tensor:
    return torch.floor(x * inv_h).clamp_(-_LIMIT, _LIMIT).to(torch.long).add_(_OFFSET)


def candidate_slots(x: Tensor, y: Tensor, n_members: int, cell: float, capacity: int):
    """Candidate partners of every sphere: ``(other, valid, needed)``.

    ``x``, ``y``: ``[L]`` centres, env-major (``L = B * M``, member ``m`` of env
    ``b`` at ``b * M + m``). Returns ``other`` ``[L, 3 * capacity]`` flat indices
    of candidates, ``valid`` (same shape, bool: a real candidate with a larger
    flat index, so each pair appears once) and ``needed`` (a 0-d tensor: the
    longest neighbourhood run, which must not exceed ``capacity``).
    """
    length = x.shape[0]
    inv_h = 1.0 / cell
    cx, cy = _cells(x, inv_h), _cells(y, inv_h)
    env = torch.arange(length, device=x.device) // n_members
    row = (env * _ROW + cy) * _ROW  # the key of column 0 in this sphere's row
    keys, order = torch.sort(row + cx)
    dy = torch.tensor([-_ROW, 0, _ROW], device=x.device)
    left = (row + cx - 1).unsqueeze(1) + dy  # [L, 3]: first key of each of the three runs
    lo = torch.searchsorted(keys, left)
    hi = torch.searchsorted(keys, left + 2, right=True)
    needed = (hi - lo).max()
    slot = lo.unsqueeze(2) + torch.arange(capacity, device=x.device)  # [L, 3, K]
    valid = slot < hi.unsqueeze(2)
    other = order[slot.clamp_(max=length - 1)].view(length, -1)
    self_index = torch.arange(length, device=x.device).unsqueeze(1)
    valid = valid.view(length, -1) & (other > self_index)
    return other, valid, needed


def add_group_contact_forces(force: Tensor, group, q: Tensor, params: StepParams) -> None:
    """Add the contact forces among ``group``'s spheres onto ``force`` ``[3, N, B]``, in place.

    ``group`` is a :class:`~vmas_ros.simulator.tables.SphereGroup`; its
    ``needed`` is raised to the longest neighbourhood run of this call.
    """
    members, radius = group.members, group.radius
    n_members, batch = members.shape[0], q.shape[2]
    # [B * M] env-major copies: each env's members are one contiguous block for the sort
    x = torch.index_select(q[0], 0, members).t().reshape(-1)
    y = torch.index_select(q[1], 0, members).t().reshape(-1)
    other, valid, needed = candidate_slots(x, y, n_members, group.cell, group.capacity)
    torch.maximum(group.needed, needed, out=group.needed)
    r = radius.repeat(batch)  # [B * M]
    dx = x.unsqueeze(1) - x[other]
    dy = y.unsqueeze(1) - y[other]
    dist_min = r.unsqueeze(1) + r[other]
    dist = torch.addcmul(dx * dx, dy, dy).sqrt_()
    active = mask_ge(dist, MIN_CONTACT_DIST).mul_(mask_le(dist, dist_min)).mul_(valid)
    scale = softplus_of_overlap((dist_min - dist) / params.contact_margin).mul_(active).div_(dist.clamp_min(1e-8))
    scale.mul_(params.collision_force * params.contact_margin)
    fx, fy = dx * scale, dy * scale  # [L, 3K]: on the sphere itself; its partner gets the opposite
    flat = other.reshape(-1)
    on_x = fx.sum(1).index_add_(0, flat, fx.reshape(-1), alpha=-1)
    on_y = fy.sum(1).index_add_(0, flat, fy.reshape(-1), alpha=-1)
    force[0].index_add_(0, members, on_x.view(batch, n_members).t())
    force[1].index_add_(0, members, on_y.view(batch, n_members).t())
