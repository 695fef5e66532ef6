"""Sensors agents carry. The Lidar casts all its rays in one batched call, and a world's
lidars are cast together once per state (``lidars.LidarCaster``)."""
from __future__ import annotations

import abc
import math
from typing import Callable, List, Optional, Sequence, Tuple, Union

import torch
from torch import Tensor

from vmas_ros.simulator.lidar_batch import FILTER_CHANGES
from vmas_ros.simulator.lidars import LidarCaster
from vmas_ros.simulator.thresholds import DIRECT_TRIG_MAX_ELEMENTS
from vmas_ros.simulator.utils import Color

__all__ = ["Sensor", "Lidar", "CollidesWith", "world_lidars"]


class CollidesWith:
    """An ``entity_filter`` for lidars: the entities that collide with ``entity`` both ways.

    Its answers depend only on the entities' collision properties, which the
    world's tables also depend on, so it says ``layout_static``: the world
    works out its targets once per tables instead of calling it for every
    entity on every cast (in sim_node, dozens of filter calls per step).
    """

    layout_static = True

    def __init__(self, entity) -> None:
        self.entity = entity

    def __call__(self, other) -> bool:
        return other.collides(self.entity) and self.entity.collides(other)


class Sensor(abc.ABC):
    """Something an agent measures the world with; bound to its agent by ``Agent.add_sensor``."""

    def __init__(self, world) -> None:
        self._world = world
        self._agent = None

    @property
    def agent(self):
        return self._agent

    @agent.setter
    def agent(self, agent) -> None:
        self._agent = agent

    @property
    def world(self):
        return self._world

    @abc.abstractmethod
    def measure(self):
        """Take a batched measurement for every env."""

    @abc.abstractmethod
    def render(self, env_index: int = 0) -> list:
        """Geoms that show the last measurement."""

    def to(self, device) -> None:
        """Move internal tensors to ``device``."""




class Lidar(Sensor):
    """A 2D range finder: ``n_rays`` rays at angles relative to the agent's heading.

    ``measure()`` returns distances [batch, n_rays]; ``max_range`` where a ray hits
    nothing that passes ``entity_filter``. A full circle (start == end mod 2 pi)
    spaces rays evenly without duplicating the first one.

    All lidars of a world share one :class:`~vmas_ros.simulator.lidars.LidarCaster`,
    which casts those of one layout together once per state and decides how
    (compiled, batched, or each alone); ``measure()`` hands out this lidar's
    row. An ``entity_filter`` is asked once per state (one that says
    ``layout_static`` once per world tables), so it may read the world's state
    but nothing that changes within one state.
    """

    def __init__(
        self,
        world,
        angle_start: float = 0.0,
        angle_end: float = 2 * math.pi,
        n_rays: int = 8,
        max_range: float = 1.0,
        entity_filter: Callable = lambda _: True,
        render_color: Union[Color, Tuple[float, float, float]] = Color.GRAY,
        alpha: float = 1.0,
        render: bool = True,
    ) -> None:
        super().__init__(world)
        if not isinstance(n_rays, int) or n_rays < 1:
            raise ValueError(f"Lidar n_rays must be an int >= 1, got {n_rays!r}")
        if not max_range > 0:
            raise ValueError(f"Lidar max_range must be > 0, got {max_range}")
        full_circle = (angle_start - angle_end) % (2 * math.pi) < 1e-5
        if full_circle:
            angles = torch.linspace(angle_start, angle_end, n_rays + 1, device=world.device)[:n_rays]
        else:
            angles = torch.linspace(angle_start, angle_end, n_rays, device=world.device)
        self._angles = angles.repeat(world.batch_dim, 1)
        self._max_range = max_range
        self._entity_filter = entity_filter
        self._render_color = render_color
        self._alpha = alpha
        self._render = render
        self._last_measurement: Optional[Tensor] = None
        self._unit_rays: Optional[tuple] = None  # (device and dtype, cos, sin) of the relative angles [1, R]
        self._caster: Optional[LidarCaster] = None  # the world's, shared with its other lidars

    n_rays = property(lambda self: self._angles.shape[1])
    max_range = property(lambda self: self._max_range)
    alpha = property(lambda self: self._alpha)

    @property
    def last_measurement(self) -> Optional[Tensor]:
        """The distances [batch, n_rays] of the last cast that measured this lidar (``measure``, or a
        scenario's ``stacked_measure`` of the whole swarm), None before any."""
        if self._caster is not None:
            latest = self._caster.latest(self)
            if latest is not None:
                return latest
        return self._last_measurement

    @property
    def angles(self) -> Tensor:
        """Ray angles [batch, n_rays] relative to the agent's heading."""
        return self._angles

    @property
    def entity_filter(self) -> Callable:
        return self._entity_filter

    @entity_filter.setter
    def entity_filter(self, value: Callable) -> None:
        self._entity_filter = value
        FILTER_CHANGES[0] += 1

    @property
    def render_color(self):
        return self._render_color.value if isinstance(self._render_color, Color) else self._render_color

    def to(self, device) -> None:
        self._angles = self._angles.to(device)

    def set_render(self, render: bool) -> None:
        self._render = render

    def ray_directions(self) -> Tuple[Tensor, Tensor]:
        """``(cos, sin)`` of every ray's world angle, each ``[batch, n_rays]``.

        ``cos(a + rot) = cos a cos rot - sin a sin rot``: the relative angles'
        cosines and sines are computed once, so a cast costs two trigonometric
        calls per env instead of two per ray (they were a fifth of a LIDAR
        scenario's observation). Equal to ``cos(angles + rot)`` to float rounding.
        Up to ``DIRECT_TRIG_MAX_ELEMENTS`` envs x rays the direct form is used:
        there the number of calls, not the passes, is the cost.
        """
        rot = self._agent.state.rot  # [B, 1]
        if self._angles.numel() <= DIRECT_TRIG_MAX_ELEMENTS:  # few rays: fewer calls win
            angles = self._angles + rot
            return torch.cos(angles), torch.sin(angles)
        key = (self._angles.device, self._angles.dtype)
        if self._unit_rays is None or self._unit_rays[0] != key:
            row = self._angles[:1]  # every env has the same relative angles
            self._unit_rays = (key, torch.cos(row), torch.sin(row))
        _, cos0, sin0 = self._unit_rays
        cos_r, sin_r = torch.cos(rot), torch.sin(rot)
        return torch.addcmul(cos0 * cos_r, sin0, sin_r, value=-1), torch.addcmul(sin0 * cos_r, cos0, sin_r)

    def measure(self, vectorized: bool = True) -> Tensor:
        """Distances [batch, n_rays] in the current state (read-only: shared with whoever asks in this state).

        Cast together with the world's other lidars of this layout (see
        :mod:`vmas_ros.simulator.lidars`): bit-equal to :meth:`cast_alone` on
        an eager world, equal to float rounding on one that compiles its
        physics. ``vectorized`` is VMAS's argument; every cast here is.
        """
        measurement = self._world_caster().reading(self)
        self._last_measurement = measurement
        return measurement

    def stacked_measure(self, lidars: Sequence["Lidar"]) -> Tensor:
        """Distances ``[len(lidars), batch, n_rays]`` of ``lidars`` (this one's world's, one ray count and
        range), cast together once per state: a swarm's observation without a call per lidar. The same
        numbers as each one's :meth:`measure`."""
        return self._world_caster().stacked_readings(self._world, lidars)

    def cast_alone(self) -> Tensor:
        """Distances [batch, n_rays] from this lidar's own cast: all its rays against all its targets at once."""
        cos_a, sin_a = self.ray_directions()
        return self._world.cast_rays_along(self._agent, cos_a, sin_a, self._max_range, self._entity_filter)

    def _world_caster(self) -> LidarCaster:
        """The caster of this lidar's world: the one its other lidars have, else a new one for all of them."""
        if self._caster is None:
            lidars = world_lidars(self._world)
            caster = next((lidar._caster for lidar in lidars if lidar._caster is not None), None)
            caster = caster if caster is not None else LidarCaster(world_lidars)
            for lidar in lidars + [self]:
                if lidar._caster is None:
                    lidar._caster = caster
        return self._caster

    def render(self, env_index: int = 0) -> List:
        from vmas_ros.simulator import rendering

        if not self._render or self._last_measurement is None:
            return []
        geoms = []
        origin = self._agent.state.pos[env_index].tolist()
        heading = float(self._agent.state.rot[env_index])
        for angle, dist in zip(self._angles[env_index].tolist(), self._last_measurement[env_index].tolist()):
            ray = rendering.Line((0, 0), (dist, 0), width=0.05)
            xform = rendering.Transform()
            xform.set_translation(*origin)
            xform.set_rotation(angle + heading)
            ray.add_attr(xform)
            ray.set_color(0, 0, 0, alpha=self._alpha)
            tip = rendering.make_circle(0.01)
            tip_xform = rendering.Transform()
            tip_xform.set_translation(origin[0] + dist * math.cos(angle + heading), origin[1] + dist * math.sin(angle + heading))
            tip.add_attr(tip_xform)
            tip.set_color(*self.render_color, alpha=self._alpha)
            geoms += [ray, tip]
        return geoms


def world_lidars(world) -> List[Lidar]:
    """Every agent's lidars, agent by agent, in sensor order."""
    return [sensor for agent in world.agents for sensor in agent.sensors if isinstance(sensor, Lidar)]
