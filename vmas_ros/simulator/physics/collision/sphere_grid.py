"""Contacts in a large group of spheres, found through a hashed grid (the broad phase of a swarm).

Testing every pair of ``M`` spheres costs ``M^2 / 2`` per env. Two spheres
touch only when their centres are at most the sum of their radii apart, so
with square cells at least that wide, each sphere needs testing only against
the spheres in its own cell and the eight around it. Per step, all envs at once:

1. each sphere gets the integer cell ``(floor(x / h), floor(y / h))``, hashed
   with its env into one of ``T`` buckets (``T`` a power of two, at least twice
   the number of spheres; spatial hashing after Teschner et al., 2003);
2. the spheres are sorted by bucket, and a count per bucket
   (``bincount``) and its running sum give where each bucket's run starts:
   finding a neighbour cell's spheres is two lookups, not a search;
3. the runs of a sphere's nine neighbour buckets are laid end to end, for all
   spheres, into one list of candidate pairs (the hash is linear in the cell,
   so a sphere's nine buckets are always distinct, see ``_PRIME_X``). Far
   cells that share a bucket only add candidates: pairs of different envs are
   masked out, the rest the narrow phase rejects by distance, so exactness
   does not depend on the hash;
4. the narrow phase (the same soft contact as every sphere pair, see
   :mod:`.sphere_sphere`) runs on that list, masked where an entry is past its
   end or holds a pair already counted from its other member.

Nothing leaves the device: the work is a fixed number of batched ops whose
shapes depend only on the group's size, the number of envs and ``capacity``,
the list's room per sphere.

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
from vmas_ros.simulator.physics.types import StepParams

__all__ = ["add_group_contact_forces", "candidate_pairs", "table_size"]

#: cell coordinates are clamped to +-_LIMIT (entities farther out share the edge cells: still exact,
#: only more candidates there), which keeps the hash's products inside an int64
_LIMIT = (1 << 20) - 2
#: the hash's multipliers (large primes, as in Teschner et al., 2003). The hash is linear in the cell,
#: so two of a sphere's nine neighbour cells land in one bucket only if a * _PRIME_X + b * _PRIME_Y,
#: with a and b in -2..2, is a multiple of the table size; for these two no such sum is divisible by
#: 16, so with at least 16 buckets the nine buckets of a sphere are always distinct (each candidate
#: is listed once without a check; test_sphere_grid.py checks the property)
_PRIME_X, _PRIME_Y, _PRIME_ENV = 73856093, 19349663, 83492791
MIN_BUCKETS = 16
#: the nine neighbour cells' offsets in the hash, dx varying fastest; the sphere's own cell is entry 4
_NEAR = tuple(dx * _PRIME_X + dy * _PRIME_Y for dy in (-1, 0, 1) for dx in (-1, 0, 1))


def _cells(x: Tensor, inv_h: float) -> Tensor:
    return torch.floor(x * inv_h).clamp_(-_LIMIT, _LIMIT).to(torch.long)


def table_size(length: int) -> int:
    """Buckets for ``length`` spheres: a power of two, at least twice as many, at least MIN_BUCKETS."""
    return max(MIN_BUCKETS, 1 << (2 * length - 1).bit_length())


def candidate_pairs(x: Tensor, y: Tensor, n_members: int, cell: float, capacity: int):
    """Candidate pairs of spheres that may touch: ``(first, second, valid, needed)``.

    ``x``, ``y``: ``[L]`` centres, env-major (``L = B * M``, member ``m`` of env
    ``b`` at ``b * M + m``). Returns ``first`` and ``second`` ``[L * capacity]``
    flat indices of the two spheres of each candidate, ``valid`` (same shape,
    bool: a real candidate, of one env, with ``first < second``, so each pair
    appears once) and ``needed`` (0-d: the candidates per sphere the list
    needed, rounded up, which must not exceed ``capacity``).
    """
    length, device = x.shape[0], x.device
    inv_h, size = 1.0 / cell, table_size(length)
    key = _cells(x, inv_h).mul_(_PRIME_X).add_(_cells(y, inv_h).mul_(_PRIME_Y))
    if n_members < length:  # several envs: the env is part of the cell
        key.add_(torch.arange(length, device=device).div_(n_members, rounding_mode="floor").mul_(_PRIME_ENV))
    # int32 indices from here on: half the memory traffic of int64 in these random gathers
    near = (key.unsqueeze(1) + torch.tensor(_NEAR, device=device)).bitwise_and_(size - 1).to(torch.int32)  # [L, 9]
    own = near[:, 4]
    order = torch.argsort(own).to(torch.int32)
    counts = torch.bincount(own, minlength=size).to(torch.int32)
    starts = torch.cumsum(counts, 0, dtype=torch.int32).sub_(counts)
    near = near.view(-1)
    runs = torch.index_select(counts, 0, near)  # [L * 9]: spheres in each neighbour bucket
    run_start = torch.cumsum(runs, 0, dtype=torch.int32).sub_(runs)  # where each run begins in the list
    total = run_start[-1].long() + runs[-1]
    needed = (total + length - 1) // length
    room = length * capacity
    # entry t of the list belongs to the last run that starts at or before t (empty runs start where
    # the next one does, so counting run starts up to t finds it)
    marks = torch.zeros(room + 1, dtype=torch.int32, device=device)
    marks.index_add_(0, run_start.clamp(max=room), torch.ones_like(run_start))
    run = torch.cumsum(marks[:room], 0, dtype=torch.int32).sub_(1).clamp_(min=0)
    entry = torch.arange(room, device=device, dtype=torch.int32)
    first = run.div(9, rounding_mode="floor")
    offset = entry.sub_(torch.index_select(run_start, 0, run))  # entry - where its run begins
    at = torch.index_select(starts, 0, torch.index_select(near, 0, run)).add_(offset)
    second = torch.index_select(order, 0, at.clamp_(0, length - 1))
    valid = (offset < torch.index_select(runs, 0, run)) & (second > first)
    if n_members < length:  # a bucket holds every env's spheres whose cells hash alike
        valid &= first.div(n_members, rounding_mode="floor") == second.div(n_members, rounding_mode="floor")
    return first, second, valid, needed


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
