"""Many lidars against many spheres, each ray tested only against the spheres within its lidar's reach.

A swarm of ``L`` agents that see each other casts ``L`` lidars against about
``L`` spheres: every (lidar, sphere, ray) triple is ``L^2 R`` distances, most
of them to spheres far out of range. A ray of range ``r`` from ``o`` can hit
a sphere of radius ``rho`` only if the centre lies within ``r + rho`` of
``o``, so the engine's spatial hash
(:func:`~vmas_ros.simulator.physics.spatial_hash.candidates_near`), with
cells that wide, lists the spheres each lidar has to test: a few per lidar in
a sparse swarm.

Each listed (lidar, sphere) pair gets the all-pairs cast's own arithmetic
(:func:`~vmas_ros.simulator.raycast.ray_sphere_reach_xy`), and the nearest
hit per ray is the minimum over the lidar's pairs. A sphere out of reach
would have given ``max_range``, which the cap gives anyway, so the readings
equal the all-pairs cast's; the ray directions come from one batched
``cos``/``sin``, which may differ from a lidar's own in the last bit
(test/simulator/test_lidar_grid.py compares them).

Exactness needs every pair within reach in the list: the cast reads how much
room the list needed (one host read per cast) and, when it outgrew its
capacity, casts again with room to spare. The capacity is kept for the next
cast.

Which lidars qualify (:func:`grid_plan`): the same ray count and range, only
sphere targets, filters that answer from the layout alone
(``layout_static``), and targets that are one set for all, minus the lidar's
own body (a swarm that sees itself). Others are cast as before.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import torch
from torch import Tensor

from vmas_ros.simulator import raycast
from vmas_ros.simulator.lidar_batch import FILTER_CHANGES, layout_static
from vmas_ros.simulator.physics.spatial_hash import candidates_within

__all__ = ["GridCast", "GridPlan", "grid_plan", "GRID_LIDAR_START_CAPACITY"]

#: room per lidar in the candidate list to start with; a cast that needs more grows it (never a lost hit)
GRID_LIDAR_START_CAPACITY = 8


@dataclass
class GridPlan:
    """The constants of one grid cast: ``L`` lidars against ``E`` sphere targets."""

    origins: Tensor  # [L] entity rows the lidars sit on
    targets: Tensor  # [E] entity rows of the spheres
    own: Tensor  # [L] int32: index of the lidar's own body in ``targets``, -1 if it is none of them
    radius: Tensor  # [E]
    cos0: Tensor  # [L, R]: cosines of the rays' angles relative to the heading
    sin0: Tensor  # [L, R]
    max_range: float
    reach: float  # the farthest centre a ray can hit: max_range plus the largest radius


def grid_plan(world, sensors: Sequence) -> Optional[GridPlan]:
    """The plan for casting ``sensors`` through the grid, or None when they do not qualify (module docstring)."""
    first = sensors[0]
    max_range = float(first.max_range)
    if any(s.n_rays != first.n_rays or float(s.max_range) != max_range for s in sensors):
        return None
    if not layout_static(sensors):
        return None
    union = _shared_targets(world, sensors)
    targets = None
    if union is None:
        targets = [world.ray_targets(s.agent, s.entity_filter) for s in sensors]
        union_ids = set()
        for t in targets:
            union_ids.update(id(e) for e in t)
        union = [e for e in world.entities if id(e) in union_ids]
    position = {id(e): i for i, e in enumerate(union)}
    own = [position.get(id(s.agent), -1) for s in sensors]
    # each lidar must see the whole union but its own body (which ray_targets never lists)
    if targets is not None and any(len(t) != len(union) - (o >= 0) for t, o in zip(targets, own)):
        return None
    if not union or any(e.shape.kind != "sphere" for e in union):
        return None
    slot = {id(e): i for i, e in enumerate(world.entities)}
    device = first.agent.state.pos.device
    angles = torch.stack([s.angles[0] for s in sensors])  # [L, R]
    radius = torch.tensor([e.shape.radius for e in union], device=device)
    reach = max_range + float(radius.max())
    return GridPlan(
        origins=torch.tensor([slot[id(s.agent)] for s in sensors], device=device),
        targets=torch.tensor([slot[id(e)] for e in union], device=device),
        own=torch.tensor(own, device=device, dtype=torch.int32),
        radius=radius, cos0=torch.cos(angles), sin0=torch.sin(angles), max_range=max_range, reach=reach,
    )


def _shared_targets(world, sensors: Sequence) -> Optional[list]:
    """The targets of lidars that share one filter object and whose agents, like every entity the filter
    accepts, collide with everything: what the filter accepts, asked once (each lidar's targets are these
    but its own body, as ``World.ray_targets`` would list them one lidar at a time); None otherwise."""
    from vmas_ros.simulator.entities import collide_with_all

    entity_filter = sensors[0].entity_filter
    if any(s.entity_filter is not entity_filter for s in sensors):
        return None
    everything = lambda e: e._collide and e._collision_filter is collide_with_all  # noqa: E731
    if not all(everything(s.agent) for s in sensors):
        return None
    accepted = [e for e in world.entities if entity_filter(e)]
    return accepted if all(everything(e) for e in accepted) else None


def _env_major(row: Tensor, index: Tensor) -> Tensor:
    """``row[index]`` of a ``[N, B]`` state row, laid out env-major: ``[B * len(index)]``."""
    return torch.index_select(row, 0, index).t().reshape(-1)


def grid_cast(q: Tensor, plan: GridPlan, capacity: int) -> tuple:
    """``(distances [L, B, R], capacity)`` of the plan's lidars in the planar state ``q`` ``[3, N, B]``;
    ``capacity`` is the room per lidar the cast ended up with (grown when the list needed more)."""
    n_lidars, n_targets, batch = plan.origins.shape[0], plan.targets.shape[0], q.shape[2]
    ox, oy = _env_major(q[0], plan.origins), _env_major(q[1], plan.origins)  # [B * L]
    tx, ty = _env_major(q[0], plan.targets), _env_major(q[1], plan.targets)  # [B * E]
    found, capacity = candidates_within(ox, oy, n_lidars, tx, ty, n_targets, plan.reach, capacity)
    query, target = found.query, found.target
    member = target.remainder(n_targets)
    valid = found.valid & (member != torch.index_select(plan.own, 0, query.remainder(n_lidars)))
    # every lidar's ray directions [B * L, R], then each candidate's
    heading = _env_major(q[2], plan.origins).unsqueeze(1)
    cos_r, sin_r = torch.cos(heading), torch.sin(heading)
    cos0, sin0 = plan.cos0.repeat(batch, 1), plan.sin0.repeat(batch, 1)
    cos_a = torch.addcmul(cos0 * cos_r, sin0, sin_r, value=-1)
    sin_a = torch.addcmul(sin0 * cos_r, cos0, sin_r)
    column = lambda values, index: torch.index_select(values, 0, index).unsqueeze(1)  # noqa: E731
    distance = raycast.ray_sphere_reach_xy(
        column(ox, query), column(oy, query), torch.index_select(cos_a, 0, query),
        torch.index_select(sin_a, 0, query), column(tx, target), column(ty, target),
        column(plan.radius, member))  # [C, R]
    distance.masked_fill_(~valid.unsqueeze(1), float("inf"))
    nearest = torch.full_like(cos_a, plan.max_range)
    nearest.scatter_reduce_(0, query.long().unsqueeze(1).expand_as(distance), distance, "amin")
    return nearest.view(batch, n_lidars, -1).transpose(0, 1), capacity


class GridCast:
    """Casts a world's swarm of lidars through the grid; the plan is kept while the layout holds."""

    def __init__(self) -> None:
        self._layout: Optional[tuple] = None
        self._plan: Optional[GridPlan] = None
        self.capacity = GRID_LIDAR_START_CAPACITY

    def cast(self, world, sensors: Sequence) -> Optional[Tensor]:
        """Distances ``[L, B, R]`` of ``sensors``, or None when they do not qualify (see :func:`grid_plan`)."""
        known = self._layout  # (tables, lidars, filter changes): the plan holds while all three do
        if known is None or known[0] is not world.tables or known[2] != FILTER_CHANGES[0] or known[1] != sensors:
            self._layout = (world.tables, list(sensors), FILTER_CHANGES[0])
            self._plan = grid_plan(world, sensors)
        if self._plan is None:
            return None
        with torch.no_grad():
            distances, self.capacity = grid_cast(world.planar_state()[0], self._plan, self.capacity)
        return distances
