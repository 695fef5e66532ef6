"""One env of the batch on the host after each step: its state and its lidars' readings, as one vector.

What a ROS node (or a viewer) publishes every step: env ``env_index``'s
positions, angles and velocities, and the ranges of the lidars it shows.
:class:`EnvSnapshot` chooses how to take it once, when it is built:

* the world compiles its physics and envs x rays is at most
  :data:`~vmas_ros.simulator.thresholds.RIDE_ALONG_MAX_ELEMENTS`: the step computes it. Gathering after the
  step takes a dozen small tensor calls, a lidar cast and the Python around
  them, which at one env is comparable to the compiled step itself;
  registered as one of the world's state kernels (``World.add_state_kernel``),
  the gather, the casts and the finiteness check become part of the step's
  graph, and taking the snapshot is one tensor handed out by the step;
* otherwise it is gathered after the step (:func:`gather`), the lidars read
  through ``Lidar.measure()``: a reading the scenario took in this state is
  reused, the others are cast together.

Where the step's own snapshot is not there (the first step, another env
index, lidars whose filters read the state or that cannot be cast together,
a reset or a setter since the step) ``take`` gathers it.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import List, Optional, Sequence

import numpy as np
import torch

from vmas_ros.simulator.lidar_batch import castable, layout_static, lidar_layout, same_lidar_layout
from vmas_ros.simulator.thresholds import RIDE_ALONG_MAX_ELEMENTS

__all__ = ["EnvSnapshot", "EnvVector", "gather"]


@dataclass(frozen=True)
class EnvVector:
    """One env on the host.

    ``values`` ``[6 N + sum of rays]``: rows of ``N`` x, y, angle, vx, vy and
    angular velocity, entity by entity as ``world.entities``, then every
    lidar's ranges in the order given. ``finite``: whether no state value is
    NaN or infinite and no range is NaN, when the step worked it out; None
    when it was not checked (gathered after the step).
    """

    values: np.ndarray
    finite: Optional[bool] = None


def gather(world, env_index: int, lidars: Sequence, one_layout: Optional[bool] = None) -> np.ndarray:
    """:attr:`EnvVector.values` of env ``env_index`` from the current state, with one device-to-host copy.
    ``one_layout``: whether the lidars share one ray count (worked out when not given)."""
    with torch.no_grad():
        if one_layout is None:
            one_layout = len({lidar.n_rays for lidar in lidars}) == 1
        if len(lidars) > 1 and one_layout:
            # one stacked read for all (a swarm's thousand measure() calls cost more than its cast)
            readings = [lidars[0].stacked_measure(lidars)[:, env_index].reshape(-1)]
        else:
            readings = [lidar.measure()[env_index].reshape(-1) for lidar in lidars]
        q, v = world.planar_state()  # right after a step: its own output, no copy
        state = torch.cat([q[:, :, env_index], v[:, :, env_index]])  # [6, N]
        return torch.cat([state.reshape(-1)] + [r.to(state.dtype) for r in readings]).cpu().numpy()


def published_env(env_index: torch.Tensor, cast, q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Env ``env_index`` (a one-element index tensor) as one vector: :attr:`EnvVector.values` of
    ``q``, ``v`` ``[3, N, B]`` and ``cast(q)`` ``[L, B, R]`` (None: no lidars), then 1 when the state is
    finite and no range is NaN, else 0. A state kernel: pure in ``q``, ``v``; the index is a tensor so
    that another env needs no new compiled step."""
    state = torch.cat([q.index_select(2, env_index).reshape(-1), v.index_select(2, env_index).reshape(-1)])
    parts, finite = [state], torch.isfinite(state).all()
    if cast is not None:
        ranges = cast(q).index_select(1, env_index).reshape(-1).to(q.dtype)
        parts.append(ranges)
        finite = finite & ~torch.isnan(ranges).any()
    parts.append(finite.to(q.dtype).reshape(1))
    return torch.cat(parts)


class EnvSnapshot:
    """``take(env_index)``: env ``env_index``'s :class:`EnvVector` in the current state.

    ``lidars``: the lidars whose ranges follow the state, in that order.
    ``rides_along`` says which way was chosen (see the module). Riding
    along, the plan (the lidar constants) follows the world's tables and the
    lidars' filters: a change registers a new kernel, which the next
    compiled step compiles anew; another env index is written into the
    kernel's index tensor (no new compile). Either way the snapshot right
    after the change is gathered.
    """

    def __init__(self, world, lidars: Sequence) -> None:
        self._world = world
        self._lidars: List = list(lidars)
        rays = max((lidar.n_rays for lidar in self._lidars), default=1)
        self._one_layout = len({lidar.n_rays for lidar in self._lidars}) == 1
        self.rides_along = bool(world.physics_compiled) and world.batch_dim * rays <= RIDE_ALONG_MAX_ELEMENTS
        self._handle: Optional[int] = None  # of the registered state kernel
        self._key: Optional[tuple] = None  # lidar_batch.lidar_layout() of the registered kernel
        self._index: Optional[torch.Tensor] = None  # the env the kernel gathers, read by every compiled step
        self._computing: Optional[int] = None  # the env index in it since the last step
        self.computed_by_step = False  # the registered kernel computes the whole snapshot

    def take(self, env_index: int) -> EnvVector:
        if self.rides_along:
            values = self._from_step(env_index)
            if values is not None:
                return EnvVector(values[:-1], bool(values[-1]))
        return EnvVector(gather(self._world, env_index, self._lidars, self._one_layout))

    def _from_step(self, env_index: int) -> Optional[np.ndarray]:
        """The step's own vector (its last value the finiteness verdict), or None: gather it."""
        world = self._world
        if self._handle is None or not same_lidar_layout(self._key, world, self._lidars):
            self._plan(env_index)
            return None  # this state was computed with the old plan
        if env_index != self._computing:
            self._index.fill_(env_index)  # the next step gathers this env
            self._computing = env_index
            return None
        if not self.computed_by_step:
            return None
        output = world.take_state_kernel_output(self._handle)
        return None if output is None else output.cpu().numpy()  # None: a reset or a setter since the step

    def _plan(self, env_index: int) -> None:
        # the lidar constants hold each lidar's targets: only filters that follow the tables keep them valid
        world, lidars = self._world, self._lidars
        self._key = lidar_layout(world, lidars)
        self._index = torch.tensor([env_index], device=world.device)
        self._computing = env_index
        cast = castable(world, lidars) if lidars and layout_static(lidars) else None
        self.computed_by_step = not lidars or cast is not None
        kernel = functools.partial(published_env, self._index, cast) if self.computed_by_step else None
        if self._handle is None:
            self._handle = world.add_state_kernel(kernel)
        else:
            world.replace_state_kernel(self._handle, kernel)
