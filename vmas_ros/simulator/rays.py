"""Ray queries against a world's entities: which entities a ray can hit, and the distance to the nearest hit.

``World.cast_ray``, ``cast_rays``, ``cast_rays_along`` and ``ray_targets``
(VMAS's names) call these with the world's entities, tables and ray kernels.
They read the state and change nothing. The kernels themselves, one per
target shape kind, are in :mod:`vmas_ros.simulator.raycast`; a world swaps in
compiled copies of them when it compiles its physics.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Dict, List, Mapping

import torch
from torch import Tensor

from vmas_ros.simulator import raycast

if TYPE_CHECKING:
    from vmas_ros.simulator.entities import Entity
    from vmas_ros.simulator.tables import WorldTables

__all__ = ["EAGER_KERNELS", "cast_rays_along", "ray_targets"]

EntityFilter = Callable[["Entity"], bool]
#: (entity id, filter id) -> (tables, filter, targets) of the layout-static filters seen so far
TargetCache = Dict[tuple, tuple]

#: the eager ray kernels by target shape kind (spheres: the nearest hit over the targets; boxes and
#: lines: per target)
EAGER_KERNELS: Mapping[str, Callable] = {
    "sphere": raycast.ray_sphere_nearest_xy, "box": raycast.ray_box_xy, "line": raycast.ray_segment_xy,
}


def ray_targets(entities: List["Entity"], entity: "Entity", entity_filter: EntityFilter, tables: "WorldTables",
                cache: TargetCache) -> List["Entity"]:
    """The ``entities`` rays from ``entity`` can hit (``entity_filter`` true, not itself); all must collide with it.

    A filter that says ``layout_static`` (its answers follow the entities'
    table properties only, e.g. ``sensors.CollidesWith``) is asked once per
    ``tables`` (the answer is kept in ``cache``); any other filter on every
    call, since it may read the state.
    """
    static = getattr(entity_filter, "layout_static", False)
    if static:
        cached = cache.get((id(entity), id(entity_filter)))
        if cached is not None and cached[0] is tables and cached[1] is entity_filter:
            return cached[2]
    targets = [e for e in entities if e is not entity and entity_filter(e)]
    for e in targets:
        if not (e.collides(entity) and entity.collides(e)):
            raise ValueError(
                f"rays are cast only among collidable entities: {entity.name!r} and {e.name!r} do not collide")
    if static:
        cache[(id(entity), id(entity_filter))] = (tables, entity_filter, targets)
    return targets


def cast_rays_along(origin: Tensor, targets: List["Entity"], cos_a: Tensor, sin_a: Tensor, max_range: float,
                    kernels: Mapping[str, Callable]) -> Tensor:
    """Distances ``[B, R]`` from ``origin`` ``[B, 2]`` along rays ``(cos_a, sin_a)`` (each ``[B, R]``) to the
    nearest of ``targets``, ``max_range`` where none is hit; ``kernels``: the ray kernel per shape kind
    (:data:`EAGER_KERNELS` or compiled copies)."""
    # rays [1, B, R] against targets [E, B, 1]: every op runs over contiguous [B, R] blocks
    # and the nearest hit is a reduction over the leading dim
    device = origin.device
    ox, oy = origin[:, 0].view(1, -1, 1), origin[:, 1].view(1, -1, 1)
    nearest = torch.full_like(cos_a, float(max_range))
    cos_a, sin_a = cos_a.unsqueeze(0), sin_a.unsqueeze(0)
    for kind in ("box", "sphere", "line"):
        group = [e for e in targets if e.shape.kind == kind]
        if not group:
            continue
        pos = torch.stack([e.state.pos for e in group])  # [E, B, 2]
        cx, cy = pos[..., 0:1], pos[..., 1:2]
        if kind == "sphere":  # its kernel returns the nearest hit over the group already
            radius = torch.tensor([e.shape.radius for e in group], device=device).view(-1, 1, 1)
            nearest = torch.minimum(nearest, kernels["sphere"](ox, oy, cos_a, sin_a, cx, cy, radius, max_range))
            continue
        rot = torch.stack([e.state.rot for e in group])  # [E, B, 1]
        cos_r, sin_r = torch.cos(rot), torch.sin(rot)
        length = torch.tensor([e.shape.length for e in group], device=device).view(-1, 1, 1)
        if kind == "box":
            width = torch.tensor([e.shape.width for e in group], device=device).view(-1, 1, 1)
            d = kernels["box"](ox, oy, cos_a, sin_a, cx, cy, cos_r, sin_r, length, width, max_range)
        else:
            d = kernels["line"](ox, oy, cos_a, sin_a, cx, cy, cos_r, sin_r, length, max_range)
        nearest = torch.minimum(nearest, d.amin(dim=0))
    return nearest
