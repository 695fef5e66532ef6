"""Several lidars in one ray cast: the batched strategies of ``lidars.LidarCaster``.

``Lidar.cast_alone`` casts one agent's rays against its targets: with four
agents that is four rounds of the same dozen small tensor ops, and at one env
each op is pure overhead. :class:`BatchedLidars` casts them together: rays
``[L, B, R]`` of all L lidars against the union of their targets ``[E, ...]``,
each lidar's non-targets masked out before the nearest hit is taken. The
intersection functions are the engine's own (``vmas_ros.simulator.raycast``),
elementwise, so every (lidar, target, ray) distance is the same number the
lidar alone computes.

Exactness needs care only with trigonometry, whose vectorised and scalar kernels
may differ in the last bit: the ray directions come from each lidar's own
``ray_directions()``, as when it is cast alone, and box/line headings only when
every lidar has the same targets of that kind (the same stacked tensor as
alone). Lidars that do not fit (another ray count or range, or differing
box/line targets) are refused (None) and cast one by one.
test/simulator/test_lidar_batch.py compares the two bit for bit.

:class:`CompiledCast` is the same for worlds that compile their physics: one
compiled function of the planar state (:func:`lidar_kernel`, sphere targets
only), which ``env_snapshot`` also runs inside the compiled step.
"""
from __future__ import annotations

import contextlib
import functools
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import torch

from vmas_ros.simulator import raycast
from vmas_ros.simulator.compiling import WorldKernel


#: target sets :class:`BatchedLidars` keeps plans for (more are planned again)
MAX_PLANS = 64
#: how many times any lidar's entity_filter was set after construction (``Lidar.entity_filter``): casts
#: that keep a plan for a swarm of lidars compare it instead of asking every lidar for its filter per cast
FILTER_CHANGES = [0]


@dataclass
class _Group:
    """One shape kind of a batched cast: the union of the lidars' targets and their constants."""

    kind: str
    union: list
    mask: torch.Tensor  # [E, L, 1, 1]: is entity e a target of lidar l
    sizes: Tuple[torch.Tensor, ...]  # radius, or length (and width), each [E, 1, 1, 1]
    partial: bool  # some lidar does not see some target of the union (else the mask is all true)


class BatchedLidars:
    """Casts several lidars at once; the per-target-set constants are built once and cached.

    Entity filters are asked on every cast (they may depend on the state); only
    a new set of targets builds (and validates) a new plan.
    """

    def __init__(self) -> None:
        self._plans: Dict[tuple, Optional[List[_Group]]] = {}

    def _plan(self, world, sensors, targets) -> Optional[List[_Group]]:
        device = sensors[0].agent.state.pos.device
        groups = []
        for kind in ("box", "sphere", "line"):
            per_lidar = [[e for e in t if e.shape.kind == kind] for t in targets]
            ids = [[id(e) for e in g] for g in per_lidar]
            if kind != "sphere" and any(g and g != ids[0] for g in ids):
                return None  # headings would be stacked differently from a cast alone: not provably equal
            members = [set(g) for g in ids]
            union = [e for e in world.entities if any(id(e) in m for m in members)]
            if not union:
                continue
            mask = torch.tensor([[id(e) in m for m in members] for e in union], device=device)
            column = lambda values: torch.tensor(values, device=device).view(-1, 1, 1, 1)  # noqa: E731
            if kind == "sphere":
                sizes = (column([e.shape.radius for e in union]),)
            elif kind == "box":
                sizes = (column([e.shape.length for e in union]), column([e.shape.width for e in union]))
            else:
                sizes = (column([e.shape.length for e in union]),)
            partial = not all(id(e) in m for e in union for m in members)
            groups.append(_Group(kind, union, mask.view(len(union), len(sensors), 1, 1), sizes, partial))
        return groups

    def cast(self, world, sensors: Sequence, keep_grad: bool = False) -> Optional[List[torch.Tensor]]:
        """Readings ``[B, R]`` of ``sensors`` (same ray count and range) from one cast; None when not batchable.

        ``keep_grad``: record the cast for autograd (scenario observations of
        differentiable envs); the ROS node needs only the numbers.
        """
        if len(sensors) < 2:
            return None
        n_rays, max_range = sensors[0].n_rays, float(sensors[0].max_range)
        if any(s.n_rays != n_rays or float(s.max_range) != max_range for s in sensors):
            return None
        targets = [world.ray_targets(s.agent, s.entity_filter) for s in sensors]
        key = (world.device, tuple(id(s) for s in sensors), tuple(tuple(id(e) for e in t) for t in targets))
        if key not in self._plans:
            if len(self._plans) >= MAX_PLANS:  # filters that read the state may pick new targets every step
                self._plans.clear()
            self._plans[key] = self._plan(world, sensors, targets)
        groups = self._plans[key]
        if groups is None:
            return None
        with contextlib.nullcontext() if keep_grad else torch.no_grad():
            # per lidar, exactly the ray directions of its cast alone
            directions = [s.ray_directions() for s in sensors]
            cos_a = torch.stack([c for c, _ in directions]).unsqueeze(0)  # [1, L, B, R]
            sin_a = torch.stack([s for _, s in directions]).unsqueeze(0)
            origin = torch.stack([s.agent.state.pos for s in sensors]).unsqueeze(0)  # [1, L, B, 2]
            ox, oy = origin[..., 0:1], origin[..., 1:2]  # [1, L, B, 1]
            nearest = torch.full_like(cos_a[0], max_range)  # [L, B, R]
            for group in groups:
                pos = torch.stack([e.state.pos for e in group.union]).unsqueeze(1)  # [E, 1, B, 2]
                cx, cy = pos[..., 0:1], pos[..., 1:2]
                if group.kind == "sphere":  # the nearest hit over the group, as a cast alone
                    ignore = (~group.mask).to(cos_a.dtype) if group.partial else None
                    nearest = torch.minimum(nearest, raycast.ray_sphere_nearest_xy(
                        ox, oy, cos_a, sin_a, cx, cy, group.sizes[0], max_range, ignore=ignore))
                    continue
                else:
                    rot = torch.stack([e.state.rot for e in group.union])  # [E, B, 1], as a cast alone stacks it
                    cos_r, sin_r = torch.cos(rot).unsqueeze(1), torch.sin(rot).unsqueeze(1)
                    if group.kind == "box":
                        d = raycast.ray_box_xy(ox, oy, cos_a, sin_a, cx, cy, cos_r, sin_r, *group.sizes, max_range)
                    else:
                        d = raycast.ray_segment_xy(ox, oy, cos_a, sin_a, cx, cy, cos_r, sin_r, group.sizes[0],
                                                   max_range)
                if group.partial:  # some lidar does not see some of these targets
                    d = torch.where(group.mask, d, float("inf"))
                nearest = torch.minimum(nearest, d.amin(dim=0))
        return list(nearest.unbind(0))


class CompiledCast:
    """Several lidars cast by one compiled :func:`lidar_kernel` call (worlds that compile their physics).

    One compiled call instead of one per lidar, each with a dozen calls of
    Python around its compiled kernel: at a few envs those calls, not the
    kernels, are the cost. Entity filters may depend on the state, and
    entities may be added, so the layout is checked on every cast and a change
    plans (and compiles) again; lidars
    whose filters are all layout-static keep their plan while the world keeps
    its tables (see :func:`layout_static`).
    """

    def __init__(self) -> None:
        self._plan: Optional[tuple] = None  # (layout it was planned for, WorldKernel or None)
        self._static: Optional[tuple] = None  # lidar_layout() of the plan, when its filters are layout-static

    def cast(self, world, sensors: Sequence) -> Optional[List[torch.Tensor]]:
        """Readings ``[B, R]`` of ``sensors``, or None when they cannot be cast together (see :func:`_kernel_constants`)."""
        if not same_lidar_layout(self._static, world, sensors):
            targets = tuple(tuple(id(e) for e in world.ray_targets(s.agent, s.entity_filter)) for s in sensors)
            layout = (world.device, tuple(id(e) for e in world.entities), tuple(id(s) for s in sensors), targets)
            self._static = lidar_layout(world, sensors) if layout_static(sensors) else None
            if self._plan is None or self._plan[0] != layout:
                cast = castable(world, sensors, targets)
                self._plan = (layout, None if cast is None else WorldKernel(world, cast))
        kernel = self._plan[1]
        if kernel is None:
            return None
        return list(kernel(world.planar_state()[0]).unbind(0))


def layout_static(sensors: Sequence) -> bool:
    """Whether every lidar's filter answers from the tables only (``sensors.CollidesWith``), so that
    its targets last as long as the world's tables object."""
    return all(getattr(s.entity_filter, "layout_static", False) for s in sensors)


def lidar_layout(world, sensors: Sequence) -> tuple:
    """The world's tables object and the (sensor, filter) pairs: what layout-static lidars' targets follow."""
    return world.tables, [(s, s.entity_filter) for s in sensors]


def same_lidar_layout(known: Optional[tuple], world, sensors: Sequence) -> bool:
    """Whether ``known`` (a :func:`lidar_layout`) still holds: one identity test, not a target
    search per cast."""
    return known is not None and known[0] is world.tables and known[1] == [(s, s.entity_filter) for s in sensors]


def castable(world, sensors: Sequence, targets: Optional[tuple] = None) -> Optional[Callable[[torch.Tensor], torch.Tensor]]:
    """``cast(q) -> [L, B, R]``: :func:`lidar_kernel` with these lidars' constants (a pure function of the
    planar state, for a :class:`WorldKernel` or a state kernel), or None when they cannot be cast together
    (targets other than spheres, differing ray counts or ranges, no targets). ``targets``: each lidar's
    target ids, as :meth:`CompiledCast.cast` computes them (worked out here when not given)."""
    if targets is None:
        targets = tuple(tuple(id(e) for e in world.ray_targets(s.agent, s.entity_filter)) for s in sensors)
    constants = _kernel_constants(world, sensors, targets)
    return None if constants is None else functools.partial(lidar_kernel, **constants)


def _kernel_constants(world, sensors: Sequence, targets: tuple) -> Optional[dict]:
    """The constants of :func:`lidar_kernel` for these lidars, or None when it cannot cast them
    (targets other than spheres, differing ray counts or ranges, no targets)."""
    first = sensors[0]
    if any(s.n_rays != first.n_rays or float(s.max_range) != float(first.max_range) for s in sensors):
        return None
    kinds = {id(e): e.shape.kind for e in world.entities}
    union = [e for e in world.entities if any(id(e) in t for t in targets)]
    if not union or any(kinds[i] != "sphere" for t in targets for i in t):
        return None
    device = first.agent.state.pos.device
    seen = torch.tensor([[id(e) in t for t in targets] for e in union], device=device)  # [E, L]
    angles = torch.stack([s.angles[0] for s in sensors]).unsqueeze(1)  # [L, 1, R]: relative ray angles
    slot = {id(e): i for i, e in enumerate(world.entities)}
    return dict(
        origins=torch.tensor([slot[id(s.agent)] for s in sensors], device=device),
        targets=torch.tensor([slot[id(e)] for e in union], device=device),
        radius=torch.tensor([e.shape.radius for e in union], device=device).view(-1, 1, 1, 1),
        cos0=torch.cos(angles), sin0=torch.sin(angles), max_range=float(first.max_range),
        ignore=None if bool(seen.all()) else (~seen).to(angles.dtype).view(len(union), len(sensors), 1, 1),
    )


def lidar_kernel(q: torch.Tensor, origins: torch.Tensor, targets: torch.Tensor, radius: torch.Tensor,
                 cos0: torch.Tensor, sin0: torch.Tensor, max_range: float,
                 ignore: Optional[torch.Tensor]) -> torch.Tensor:
    """Every lidar's distances ``[L, B, R]`` against sphere targets, from the planar state ``q`` ``[3, N, B]``.

    A pure function of the state (compiled as a ``WorldKernel``): lidar ``l``
    sits on entity ``origins[l]`` and its rays point at the relative angles
    whose cosines and sines are ``cos0``/``sin0`` ``[L, 1, R]``; ``targets``
    are the entity rows of the spheres, ``ignore`` (float 0/1 ``[E, L, 1, 1]``)
    the (sphere, lidar) pairs a lidar does not see. The same numbers as
    ``Lidar.cast_alone()`` to float rounding.
    """
    ox, oy = q[0].index_select(0, origins).unsqueeze(-1), q[1].index_select(0, origins).unsqueeze(-1)  # [L, B, 1]
    heading = q[2].index_select(0, origins).unsqueeze(-1)
    cos_r, sin_r = torch.cos(heading), torch.sin(heading)
    cos_a, sin_a = cos0 * cos_r - sin0 * sin_r, sin0 * cos_r + cos0 * sin_r  # [L, B, R]
    cx = q[0].index_select(0, targets)[:, None, :, None]  # [E, 1, B, 1]
    cy = q[1].index_select(0, targets)[:, None, :, None]
    return raycast.ray_sphere_nearest_xy(ox, oy, cos_a, sin_a, cx, cy, radius, max_range, ignore=ignore)
