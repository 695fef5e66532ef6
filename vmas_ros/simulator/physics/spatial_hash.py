"""Which points lie near which: a hashed grid over every env at once (the engine's broad phase).

Contacts between spheres and LIDAR rays against spheres both ask the same
question: which targets lie within a distance ``h`` of each query point? With
square cells of side ``h``, such a target lies in the query's own cell or in
one of the eight around it. Per call, all envs at once:

1. each target gets the integer cell ``(floor(x / h), floor(y / h))``, hashed
   with its env into one of ``T`` buckets (``T`` a power of two, at least twice
   the number of targets; spatial hashing after Teschner et al., 2003);
2. the targets are sorted by bucket, and a count per bucket (``bincount``) and
   its running sum give where each bucket's run starts: finding a cell's
   targets is two lookups, not a search;
3. the runs of each query's nine neighbour buckets are laid end to end, for all
   queries, into one list of candidate (query, target) pairs. The hash is
   linear in the cell, so a query's nine buckets are always distinct (see
   ``_PRIME_X``) and each target is listed at most once per query. Far cells
   that share a bucket only add candidates; pairs of different envs are
   marked invalid, and the caller's exact test rejects the rest, so no result
   ever depends on the hash.

Nothing leaves the device: the work is a fixed number of batched ops whose
shapes depend only on the numbers of queries and targets and on
``capacity``, the list's room per query. The list may need more room than it
has; it then says so (``needed``), and the caller grows the capacity and asks
again, so that no pair is ever dropped.
"""
from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

__all__ = ["CELL_MARGIN", "Candidates", "MIN_BUCKETS", "NEAR_OFFSETS", "candidates_near", "candidates_within",
           "grown_capacity", "table_size"]

#: cell coordinates are clamped to +-_LIMIT (points farther out share the edge cells: still exact,
#: only more candidates there), which keeps the hash's products inside an int64
_LIMIT = (1 << 20) - 2
#: the hash's multipliers (large primes, as in Teschner et al., 2003). The hash is linear in the cell,
#: so two of a query's nine neighbour cells land in one bucket only if a * _PRIME_X + b * _PRIME_Y,
#: with a and b in -2..2, is a multiple of the table size; for these two no such sum is divisible by
#: 16, so with at least 16 buckets the nine buckets of a query are always distinct
#: (test_sphere_grid.py checks the property)
_PRIME_X, _PRIME_Y, _PRIME_ENV = 73856093, 19349663, 83492791
MIN_BUCKETS = 16
#: cells are this fraction wider than the distance asked for, so that float rounding of the cell coordinates
#: never puts a point within that distance two cells away
CELL_MARGIN = 0.01
#: the nine neighbour cells' offsets in the hash, dx varying fastest; the query's own cell is entry 4
NEAR_OFFSETS = tuple(dx * _PRIME_X + dy * _PRIME_Y for dy in (-1, 0, 1) for dx in (-1, 0, 1))


class Candidates(NamedTuple):
    """A list of candidate (query, target) pairs, ``[n_queries * capacity]`` entries each.

    ``query``/``target``: int32 flat indices (env-major, as passed in);
    ``valid``: bool, a real entry of the list whose two points share an env;
    ``needed``: 0-d, the room per query the list needed (rounded up), which
    must not exceed the capacity it was built with.
    """

    query: Tensor
    target: Tensor
    valid: Tensor
    needed: Tensor


def table_size(length: int) -> int:
    """Buckets for ``length`` targets: a power of two, at least twice as many, at least MIN_BUCKETS."""
    return max(MIN_BUCKETS, 1 << (2 * length - 1).bit_length())


def grown_capacity(needed: int) -> int:
    """The capacity that holds ``needed`` entries per query: the next power of two (few recompilations)."""
    return 1 << max(needed - 1, 0).bit_length()


def _cell_keys(x: Tensor, y: Tensor, inv_h: float, per_env: int) -> Tensor:
    """The unhashed key of each point's cell and env ``[P]`` (int64); points are env-major, ``per_env`` per env."""
    cx = torch.floor(x * inv_h).clamp_(-_LIMIT, _LIMIT).to(torch.long)
    cy = torch.floor(y * inv_h).clamp_(-_LIMIT, _LIMIT).to(torch.long)
    key = cx.mul_(_PRIME_X).add_(cy.mul_(_PRIME_Y))
    if per_env < x.shape[0]:  # several envs: the env is part of the cell
        env = torch.arange(x.shape[0], device=x.device).div_(per_env, rounding_mode="floor")
        key.add_(env.mul_(_PRIME_ENV))
    return key


def candidates_near(qx: Tensor, qy: Tensor, queries_per_env: int, tx: Tensor, ty: Tensor, targets_per_env: int,
                    cell: float, capacity: int) -> Candidates:
    """Every target within ``cell`` of each query, among other candidates (see the module docstring).

    ``qx``, ``qy``: ``[B * Q]`` query points, env-major (query ``j`` of env
    ``b`` at ``b * Q + j``); ``tx``, ``ty``: ``[B * T]`` target points, alike.
    A target within ``cell`` of a query (in each coordinate) is always in the
    list while ``needed <= capacity``. The same arrays may be passed as
    queries and targets: every point then also meets itself.
    """
    n_queries, n_targets, device = qx.shape[0], tx.shape[0], qx.device
    inv_h, size = 1.0 / cell, table_size(n_targets)
    query_key = _cell_keys(qx, qy, inv_h, queries_per_env)
    # int32 indices from here on: half the memory traffic of int64 in these random gathers
    near = (query_key.unsqueeze(1) + torch.tensor(NEAR_OFFSETS, device=device)).bitwise_and_(size - 1)
    near = near.to(torch.int32)  # [Q, 9]
    if qx is tx and qy is ty:  # the same points: their own cells are the queries' own
        own_bucket = near[:, 4].contiguous()
    else:
        own_bucket = _cell_keys(tx, ty, inv_h, targets_per_env).bitwise_and_(size - 1).to(torch.int32)
    near = near.view(-1)  # [Q * 9]
    order = torch.argsort(own_bucket).to(torch.int32)
    counts = torch.bincount(own_bucket, minlength=size).to(torch.int32)
    starts = torch.cumsum(counts, 0, dtype=torch.int32).sub_(counts)
    runs = torch.index_select(counts, 0, near)  # [Q * 9]: targets in each neighbour bucket
    run_start = torch.cumsum(runs, 0, dtype=torch.int32).sub_(runs)  # where each run begins in the list
    total = run_start[-1].long() + runs[-1]
    needed = (total + n_queries - 1) // n_queries
    room = n_queries * capacity
    # entry t of the list belongs to the last run that starts at or before t (empty runs start where
    # the next one does, so counting run starts up to t finds it)
    marks = torch.zeros(room + 1, dtype=torch.int32, device=device)
    marks.index_add_(0, run_start.clamp(max=room), torch.ones_like(run_start))
    run = torch.cumsum(marks[:room], 0, dtype=torch.int32).sub_(1).clamp_(min=0)
    entry = torch.arange(room, device=device, dtype=torch.int32)
    query = run.div(9, rounding_mode="floor")
    offset = entry.sub_(torch.index_select(run_start, 0, run))  # entry - where its run begins
    at = torch.index_select(starts, 0, torch.index_select(near, 0, run)).add_(offset)
    target = torch.index_select(order, 0, at.clamp_(0, n_targets - 1))
    valid = offset < torch.index_select(runs, 0, run)
    if queries_per_env < n_queries:  # a bucket holds every env's targets whose cells hash alike
        valid &= (query.div(queries_per_env, rounding_mode="floor")
                  == target.div(targets_per_env, rounding_mode="floor"))
    return Candidates(query, target, valid, needed)


def candidates_within(qx: Tensor, qy: Tensor, queries_per_env: int, tx: Tensor, ty: Tensor, targets_per_env: int,
                      within: float, capacity: int):
    """``(candidates, capacity)``: :func:`candidates_near` with cells ``within`` wide (plus
    :data:`CELL_MARGIN`), asked again with more room while the list needs more than it has (one host read
    per call). ``capacity`` is the room the list ended up with: keep it for the next call."""
    cell = within * (1 + CELL_MARGIN)
    while True:
        found = candidates_near(qx, qy, queries_per_env, tx, ty, targets_per_env, cell, capacity)
        needed = int(found.needed)
        if needed <= capacity:
            return found, capacity
        capacity = grown_capacity(needed)
