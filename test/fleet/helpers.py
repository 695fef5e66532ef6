"""What the fleet's tests share: parameter values without ROS, and a world stepped on a fake clock."""
from __future__ import annotations

from typing import Iterable, List, Sequence

import numpy as np

from vmas_ros.fleet.episodes import Episode
from vmas_ros.fleet.params import FleetParams
from vmas_ros.fleet.world import FleetWorld


def params(**values) -> FleetParams:
    """robot_fleet's parameter values: the defaults, with ``values`` over them."""
    return FleetParams(**values)


def episode(robots: Sequence[Sequence[float]], goals: Iterable[Sequence[float]] = ()) -> Episode:
    return Episode(robots=np.array(robots, dtype=float).reshape(-1, 3),
                   goals=np.array(list(goals), dtype=float).reshape(-1, 2))


def run(world: FleetWorld, start: float, seconds: float, dt: float = 0.01) -> List[dict]:
    """Step ``world`` every ``dt`` from ``start`` for ``seconds``; the records of the episodes that ended."""
    ended = []
    for k in range(1, int(round(seconds / dt)) + 1):
        ended += world.step(start + k * dt)
    return ended
