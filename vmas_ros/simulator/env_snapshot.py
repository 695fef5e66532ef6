"""One env of the batch on the host after each step: its state and its lidars' readings, as one vector.

What a ROS node, the Foxglove bridge or a recorder shows every step: env
``env_index``'s positions, angles and velocities, and the ranges of the
lidars it shows. This module is the one world snapshot everything outside the
engine reads; it imports neither ROS nor Foxglove, and the message
conversion (``vmas_ros.ros.convert``) and the drawing (``vmas_ros.viz``)
build on it.

Taking it: :class:`EnvSnapshot` chooses how to take the vector
(:class:`EnvVector`) once, when it is built:

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

Reading it: :class:`Snapshot` lays the vector out per entity and per lidar
(views, no copies), :class:`PublishedEnv` takes one after each step, and
:class:`ScanGeometry`, :func:`unique_names`, :func:`rgb` and
:func:`yaw_to_quaternion` give what every reader needs alongside it (the
angles of a scan, names valid as ROS and Foxglove ids, colours, poses).
"""
from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence

import numpy as np
import torch

from vmas_ros.simulator.lidar_batch import castable, layout_static, lidar_layout, same_lidar_layout
from vmas_ros.simulator.thresholds import RIDE_ALONG_MAX_ELEMENTS
from vmas_ros.simulator.utils import Color

__all__ = [
    "EnvSnapshot", "EnvVector", "PublishedEnv", "ScanGeometry", "Snapshot", "agent_lidars", "gather", "rgb",
    "ros_name", "unique_names", "yaw_to_quaternion",
]


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


@dataclass
class Snapshot:
    """Host copy of one env: per-entity arrays and per-agent lidar readings."""

    pos: np.ndarray  # [N, 2]
    vel: np.ndarray  # [N, 2]
    rot: np.ndarray  # [N]
    ang_vel: np.ndarray  # [N]
    #: agent index -> the ray count of each of its lidars, in the order the scans follow the state in ``host``
    rays: Dict[int, List[int]]
    #: everything above in one host array: the state's 6 N values, then every scan (see all_finite)
    host: Optional[np.ndarray] = None
    n_state: int = 0
    #: the all_finite answer when whoever took the snapshot worked it out already (a compiled step)
    finite: Optional[bool] = None

    @property
    def scans(self) -> Dict[int, List[np.ndarray]]:
        """Agent index -> one array per lidar (views into ``host``), laid out when first asked for: a swarm's
        publishers take every scan at once (:attr:`scan_block`) and never need the thousand views."""
        scans = self.__dict__.get("_scans")
        if scans is None:
            scans, offset = {}, self.n_state
            for i, counts in self.rays.items():
                scans[i] = []
                for n in counts:
                    scans[i].append(self.host[offset: offset + n])
                    offset += n
            self.__dict__["_scans"] = scans
        return scans

    @property
    def scan_block(self) -> np.ndarray:
        """Every scan's ranges end to end, in ``rays`` order (a view into ``host``)."""
        return self.host[self.n_state:]

    def all_finite(self) -> bool:
        """No NaN or inf in the state and no NaN in a scan (an unhit ray may read inf): two passes in all."""
        if self.finite is not None:
            return self.finite
        return bool(np.isfinite(self.host[: self.n_state]).all() and not np.isnan(self.host[self.n_state:]).any())

    @staticmethod
    def take(world, env_index: int, lidars: Dict[int, list]) -> "Snapshot":
        """Env ``env_index`` gathered from the current state with one device-to-host copy (every lidar measures)."""
        host = gather(world, env_index, [s for sensors in lidars.values() for s in sensors])
        return Snapshot.of_host(host, {i: [s.n_rays for s in sensors] for i, sensors in lidars.items()})

    @staticmethod
    def of_host(host: np.ndarray, rays: Dict[int, List[int]], finite: Optional[bool] = None) -> "Snapshot":
        """The snapshot laid out in ``host`` (:attr:`EnvVector.values`): the ``[6, N]`` state rows
        (x, y, angle, vx, vy, wz), then the scans, ``rays[agent]`` values per lidar in that order (views into
        ``host``, no copies); ``finite``: the :meth:`all_finite` answer when it is known already."""
        n_state = host.size - sum(n for counts in rays.values() for n in counts)
        state = host[:n_state].reshape(6, -1)
        return Snapshot(state[0:2].T, state[3:5].T, state[2], state[5], rays, host, n_state, finite)


class PublishedEnv:
    """The published env's :class:`Snapshot` after each step, from an :class:`EnvSnapshot`.

    Built once with the node's world and lidars (``agent_lidars``); the
    engine chooses then how every snapshot is taken. ``take(env_index)``
    after a step or a reset.
    """

    def __init__(self, world, lidars: Dict[int, list]) -> None:
        self.source = EnvSnapshot(world, [s for sensors in lidars.values() for s in sensors])
        self._rays = {i: [s.n_rays for s in sensors] for i, sensors in lidars.items()}

    def take(self, env_index: int) -> Snapshot:
        vector = self.source.take(env_index)
        return Snapshot.of_host(vector.values, self._rays, vector.finite)


@dataclass
class ScanGeometry:
    """LaserScan angles and ranges of one lidar; count == round((max - min) / increment) + 1 == n_rays.

    The angles are the lidar's own rays: a full circle's last ray stops one
    increment short of the first (no ray twice), a partial span ends on its
    ``angle_end``. ``range_min`` 0 means the lidar has none.
    """

    angle_min: float
    angle_max: float
    angle_increment: float
    range_max: float
    range_min: float = 0.0

    @staticmethod
    def of(lidar, range_min: float = 0.0) -> "ScanGeometry":
        angles = lidar.angles[0].detach().cpu().tolist()
        increment = (angles[-1] - angles[0]) / (len(angles) - 1) if len(angles) > 1 else 0.0
        return ScanGeometry(float(angles[0]), float(angles[-1]), float(increment), float(lidar.max_range),
                            float(range_min))


def agent_lidars(world) -> Dict[int, list]:
    """Agent index -> its Lidar sensors (the ones the node publishes as LaserScan)."""
    from vmas_ros.simulator.sensors import Lidar

    found = {}
    for i, agent in enumerate(world.agents):
        lidars = [s for s in agent.sensors if isinstance(s, Lidar)]
        if lidars:
            found[i] = lidars
    return found


def unique_names(names: Sequence[str]) -> List[str]:
    """Sanitised names, made unique by suffixes when sanitising makes two equal."""
    seen: Dict[str, int] = {}
    result = []
    for name in names:
        token = ros_name(name)
        count = seen.get(token, 0)
        seen[token] = count + 1
        result.append(token if count == 0 else f"{token}_{count}")
    return result


#: what a ROS name token cannot hold
_INVALID = re.compile(r"[^A-Za-z0-9_]")


def ros_name(name: str) -> str:
    """A valid ROS name token for an entity name ("landmark 0" -> "landmark_0", "1a" -> "n1a")."""
    token = _INVALID.sub("_", name.strip()) or "entity"
    token = re.sub(r"_+", "_", token)
    return token if not token[0].isdigit() else "n" + token


def yaw_to_quaternion(yaw: float) -> tuple:
    """(x, y, z, w) of a rotation by ``yaw`` about +z."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def rgb(color, env_index: int = 0) -> tuple:
    """(r, g, b) floats of an entity colour: a Color, a tuple, or a tensor ([3] or per-env [B, 3])."""
    if isinstance(color, Color):
        color = color.value
    if isinstance(color, torch.Tensor):
        color = (color[env_index] if color.dim() > 1 else color).flatten()[:3].tolist()
    return tuple(float(c) for c in color[:3])
