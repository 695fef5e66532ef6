"""The published env's snapshot, computed by the compiled step itself (sim_node at a few envs).

After every step sim_node needs one env's state and every lidar scan on the
host (``convert.Snapshot``). Gathering them after the step takes a dozen small
tensor calls, a lidar cast and the Python around them: at one env that is
comparable to the compiled step's own time. Registered as one of the
world's state kernels (``World.add_state_kernel``), the gather and
the casts become part of the step's graph, and taking the snapshot is one
tensor handed out by the step, read as NumPy.

Where it does not apply (eager worlds, many envs, lidars that cannot be cast
together, entity filters that read the state, the state changed since the
step) ``take`` returns None and the node gathers the snapshot as before.
"""
from __future__ import annotations

import functools
from typing import Dict, Optional

import torch

from vmas_ros.ros.convert import Snapshot
from vmas_ros.simulator.lidar_batch import castable, layout_static, lidar_layout, same_lidar_layout

#: up to this many envs x rays the step gathers the snapshot (above, one more pass over the batch per step)
RIDE_ALONG_MAX_ELEMENTS = 4096


def published_env(env_index: torch.Tensor, cast, q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Env ``env_index`` (a one-element index tensor) as one vector: its ``[3, N]`` positions and angles,
    ``[3, N]`` velocities, every lidar's ranges in order (``cast(q)`` ``[L, B, R]``; None: no lidars), and
    last 1 when the state is finite and no range is NaN, else 0 (``Snapshot.all_finite``). A state kernel:
    pure in ``q``, ``v``; the index is a tensor so that another env needs no new compiled step."""
    state = torch.cat([q.index_select(2, env_index).reshape(-1), v.index_select(2, env_index).reshape(-1)])
    parts, finite = [state], torch.isfinite(state).all()
    if cast is not None:
        ranges = cast(q).index_select(1, env_index).reshape(-1).to(q.dtype)
        parts.append(ranges)
        finite = finite & ~torch.isnan(ranges).any()
    parts.append(finite.to(q.dtype).reshape(1))
    return torch.cat(parts)


class RideAlongSnapshot:
    """``take(world, env_index)``: the step's own snapshot of env ``env_index``, or None (gather it yourself).

    ``lidars`` is ``convert.agent_lidars(world)``; the scans come in its order,
    as ``Snapshot.take`` lays them out. The plan (the lidar constants) follows
    the world's tables and the lidars' filters: a change registers a new
    kernel, which the next compiled step compiles anew. Another env index is
    written into the kernel's index tensor (no new compile); either way the
    snapshot right after the change is gathered by the caller.
    """

    def __init__(self, lidars: Dict[int, list]) -> None:
        self._sensors = [sensor for sensors in lidars.values() for sensor in sensors]
        self._rays = {i: [sensor.n_rays for sensor in sensors] for i, sensors in lidars.items()}
        self._handle: Optional[int] = None
        self._key: Optional[tuple] = None  # lidar_batch.lidar_layout() of the registered kernel
        self._index: Optional[torch.Tensor] = None  # the env the kernel gathers, read by every compiled step
        self._computing: Optional[int] = None  # the env index in it since the last step
        self.active = False  # the registered kernel computes the whole snapshot

    @staticmethod
    def suits(world, lidars: Dict[int, list]) -> bool:
        """Whether the world compiles its step and the batch is small enough to gather inside it."""
        rays = max((s.n_rays for sensors in lidars.values() for s in sensors), default=1)
        return bool(world.physics_compiled) and world.batch_dim * rays <= RIDE_ALONG_MAX_ELEMENTS

    def take(self, world, env_index: int) -> Optional[Snapshot]:
        if self._handle is None or not same_lidar_layout(self._key, world, self._sensors):
            self._plan(world, env_index)
            return None  # this state was computed with the old plan
        if env_index != self._computing:
            self._index.fill_(env_index)  # the next step gathers this env
            self._computing = env_index
            return None
        if not self.active:
            return None
        host = world.take_state_kernel_output(self._handle)
        if host is None:  # a reset or a setter since the step
            return None
        return Snapshot.of_host(host.cpu().numpy(), self._rays, verdict=True)

    def _plan(self, world, env_index: int) -> None:
        # the lidar constants hold each lidar's targets: only filters that follow the tables keep them valid
        self._key = lidar_layout(world, self._sensors)
        self._index = torch.tensor([env_index], device=world.device)
        self._computing = env_index
        cast = castable(world, self._sensors) if self._sensors and layout_static(self._sensors) else None
        self.active = not self._sensors or cast is not None
        kernel = functools.partial(published_env, self._index, cast) if self.active else None
        if self._handle is None:
            self._handle = world.add_state_kernel(kernel)
        else:
            world.replace_state_kernel(self._handle, kernel)

