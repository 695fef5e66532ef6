"""Whether a world's step fits in memory, checked before the first reset or step allocates it.

Why: the count limits (:mod:`vmas_ros.envs.limits`) stop absurd kwargs, but a
world within them can still need more memory than the machine has (ten
thousand agents that all collide pairwise, in a thousand envs). Left alone,
the first step allocates until the system's out-of-memory killer ends the
process, with no message. So once ``make_world`` has built the entities (a
few bytes each) and before anything else runs, the environment estimates what
a step will hold at once and refuses the world when that is more than the
device has available, naming both figures.

The estimate is a lower bound of a step's peak, from the largest tensors a
step holds at once (each with its number of live temporaries):

* the state: every entity's fields in every env, and the step's stacked copies;
* contacts: every pair of colliding entities the pair tables list (the
  spatial hash's spheres excepted, which cost a few candidates each), times
  the envs, times the per-pair floats the contact kernels keep live;
* lidars: each cast's ``[targets, envs, rays]`` distances, or the grid cast's
  candidates for a swarm of lidars.

A lower bound never refuses a world that fits; a world it lets through may
still need more (scenario tensors are not counted). The check is skipped when
``VMAS_ROS_ALLOW_LARGE_WORLDS`` is ``1``, like the count limits.
"""
from __future__ import annotations

import os
from typing import Dict, Optional

import torch

from vmas_ros.envs.limits import ALLOW_ENV

__all__ = ["available_bytes", "check_memory", "estimate_step_bytes"]

#: floats per entity and env a step holds: its state fields (position, velocity, angle, angular velocity,
#: force, torque), the planar stacks q and v, the action input and the new state
STATE_FLOATS = 24
#: floats per pair of colliding entities and env the contact kernels keep live at once (offsets, distance,
#: overlap, scale, the force on each side)
PAIR_FLOATS = 8
#: bytes per sphere and env of the spatial hash: its cell keys, nine neighbour buckets, and a candidate
#: list of a few entries with their indices and masks
GRID_BYTES = 9 * 8 + 4 * 20
#: floats per (target, env, ray) a lidar cast keeps live at once
CAST_FLOATS = 3
#: room per lidar a grid cast starts with (lidar_grid.GRID_LIDAR_START_CAPACITY), and its live floats
GRID_LIDAR_CANDIDATES, GRID_LIDAR_FLOATS = 8, 6


def _pairs(world, members: int) -> int:
    """Pairs of colliding entities the pair tables would list, counted without building them: every pair of
    collidable entities of which at least one can move, less those among the ``members`` spheres the
    spatial hash takes."""
    collidable = [e for e in world.entities if e._collide]
    movable = sum(1 for e in collidable if e.movable)
    fixed = len(collidable) - movable
    pairs = movable * (movable - 1) // 2 + movable * fixed
    return max(0, pairs - members * (members - 1) // 2)


def _lidar_bytes(world, batch: int) -> int:
    from vmas_ros.simulator.sensors import world_lidars
    from vmas_ros.simulator.thresholds import GRID_MIN_LIDARS, LIDAR_BATCH_MAX_ELEMENTS

    lidars = world_lidars(world)
    if not lidars:
        return 0
    rays = max(lidar.n_rays for lidar in lidars)
    targets = sum(1 for e in world.entities if e._collide)
    if len(lidars) >= GRID_MIN_LIDARS:  # a swarm's grid cast: a few candidates per lidar
        return 4 * len(lidars) * batch * rays * GRID_LIDAR_CANDIDATES * GRID_LIDAR_FLOATS
    together = len(lidars) if batch * rays <= LIDAR_BATCH_MAX_ELEMENTS else 1  # one batched cast, or one by one
    return 4 * together * targets * batch * rays * CAST_FLOATS


def estimate_step_bytes(world) -> Dict[str, int]:
    """The lower bound of a step's peak (see the module docstring), by part: ``state``, ``contacts``,
    ``grid``, ``lidars`` (bytes)."""
    from vmas_ros.simulator.tables import grid_members

    batch, members = world.batch_dim, len(grid_members(world, world.entities))
    return {
        "state": 4 * STATE_FLOATS * len(world.entities) * batch,
        "contacts": 4 * PAIR_FLOATS * _pairs(world, members) * batch,
        "grid": GRID_BYTES * members * batch,
        "lidars": _lidar_bytes(world, batch),
    }


def _cgroup_room() -> Optional[int]:
    """What the process's cgroup (v2) still allows, if it sets a limit."""
    try:
        with open("/sys/fs/cgroup/memory.max") as handle:
            limit = handle.read().strip()
        if limit == "max":
            return None
        with open("/sys/fs/cgroup/memory.current") as handle:
            return int(limit) - int(handle.read().strip())
    except (OSError, ValueError):
        return None


def available_bytes(device) -> Optional[int]:
    """Memory a new allocation on ``device`` can still get: free GPU memory, or the host's ``MemAvailable``
    (the tighter of it and the cgroup's room); None when the platform does not say."""
    device = torch.device(device)
    if device.type == "cuda":
        free, _ = torch.cuda.mem_get_info(device)
        return int(free)
    if device.type != "cpu":
        return None
    room = None
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    room = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError):
        pass
    cgroup = _cgroup_room()
    if cgroup is not None:
        room = cgroup if room is None else min(room, cgroup)
    return room


def _gb(n: int) -> str:
    return f"{n / 1e9:.1f} GB" if n >= 1e8 else f"{n / 1e6:.0f} MB"


def check_memory(world, scenario=None) -> None:
    """Refuse (MemoryError) a world whose step needs more than its device has available; the message
    names the ``scenario`` (its module), the envs and the agents."""
    if os.environ.get(ALLOW_ENV) == "1":
        return
    room = available_bytes(world.device)
    if room is None:
        return
    parts = estimate_step_bytes(world)
    need = sum(parts.values())
    if need <= room:
        return
    detail = ", ".join(f"{part} {_gb(value)}" for part, value in parts.items() if value)
    name = type(scenario).__module__.rsplit(".", 1)[-1] if scenario is not None else "the world"
    what = f"{name} with {world.batch_dim:,} envs and {len(world.agents):,} agents"
    raise MemoryError(
        f"{what} needs at least {_gb(need)} of memory per step ({detail}), but {_gb(room)} is available on "
        f"{world.device}; use fewer envs or agents (colliding pairs grow with the square of the agents), "
        f"or set {ALLOW_ENV}=1 to try anyway")
