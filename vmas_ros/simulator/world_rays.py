"""The world's ray queries (``cast_ray``, ``cast_rays``, ``cast_rays_along``), a mixin of ``World``.

Kept apart from the physics step: they read the world's entities and its ray
kernels (``World._ray_kernels``, eager or compiled), and change nothing.
"""
from __future__ import annotations

from typing import Callable, List

import torch
from torch import Tensor

from vmas_ros.simulator.entities import Entity


class RayQueries:
    """Ray casting against the world's collidable entities; ``World`` provides ``entities``, ``tables``,
    ``_device``, ``_ray_kernels`` and ``_static_ray_targets``."""

    def cast_ray(self, entity: Entity, angles: Tensor, max_range: float, entity_filter: Callable[[Entity], bool] = lambda _: False) -> Tensor:
        """Distance [B] along one ray per env from ``entity`` to the nearest filtered entity."""
        return self.cast_rays(entity, angles.unsqueeze(-1), max_range, entity_filter).squeeze(-1)

    def ray_targets(self, entity: Entity, entity_filter: Callable[[Entity], bool]) -> List[Entity]:
        """The entities rays from ``entity`` can hit (``entity_filter`` true, not itself); all must collide with it.

        A filter that says ``layout_static`` (its answers follow the entities'
        table properties only, e.g. ``sensors.CollidesWith``) is asked once per
        world tables; any other filter on every call, since it may read the state.
        """
        static = getattr(entity_filter, "layout_static", False)
        if static:
            cached = self._static_ray_targets.get((id(entity), id(entity_filter)))
            if cached is not None and cached[0] is self.tables and cached[1] is entity_filter:
                return cached[2]
        targets = [e for e in self.entities if e is not entity and entity_filter(e)]
        for e in targets:
            if not (e.collides(entity) and entity.collides(e)):
                raise ValueError(f"rays are cast only among collidable entities: {entity.name!r} and {e.name!r} do not collide")
        if static:
            self._static_ray_targets[(id(entity), id(entity_filter))] = (self.tables, entity_filter, targets)
        return targets

    def cast_rays(self, entity: Entity, angles: Tensor, max_range: float, entity_filter: Callable[[Entity], bool] = lambda _: False) -> Tensor:
        """Distances [B, R] along rays at world ``angles`` [B, R]; ``max_range`` where nothing is hit."""
        return self.cast_rays_along(entity, torch.cos(angles), torch.sin(angles), max_range, entity_filter)

    def cast_rays_along(
        self, entity: Entity, cos_a: Tensor, sin_a: Tensor, max_range: float,
        entity_filter: Callable[[Entity], bool] = lambda _: False,
    ) -> Tensor:
        """:meth:`cast_rays` for rays given by their direction ``(cos, sin)``, each ``[B, R]``.

        For sensors that know their directions more cheaply than by two
        transcendental passes over ``[B, R]`` (see ``Lidar.ray_directions``).
        """
        targets = self.ray_targets(entity, entity_filter)
        # rays [1, B, R] against targets [E, B, 1]: every op runs over contiguous [B, R] blocks
        # and the nearest hit is a reduction over the leading dim
        origin = entity.state.pos
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
                radius = torch.tensor([e.shape.radius for e in group], device=self._device).view(-1, 1, 1)
                nearest = torch.minimum(nearest, self._ray_kernels["sphere"](ox, oy, cos_a, sin_a, cx, cy, radius,
                                                                             max_range))
                continue
            else:
                rot = torch.stack([e.state.rot for e in group])  # [E, B, 1]
                cos_r, sin_r = torch.cos(rot), torch.sin(rot)
                length = torch.tensor([e.shape.length for e in group], device=self._device).view(-1, 1, 1)
                if kind == "box":
                    width = torch.tensor([e.shape.width for e in group], device=self._device).view(-1, 1, 1)
                    d = self._ray_kernels["box"](ox, oy, cos_a, sin_a, cx, cy, cos_r, sin_r, length, width, max_range)
                else:
                    d = self._ray_kernels["line"](ox, oy, cos_a, sin_a, cx, cy, cos_r, sin_r, length, max_range)
            nearest = torch.minimum(nearest, d.amin(dim=0))
        return nearest
