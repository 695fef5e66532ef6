"""Where an agent's observation carries what a robot's sensors measure.

A robot's odometry and lidar are noisy; the engine's observations are exact.
To train for that gap (``vmas_ros.envs.randomisation``), noise must go where a
robot's would: into every observed quantity the robot derives from its own
measured position or velocity, and into the lidar's rays. A scenario says
where those are by returning an :class:`ObservationLayout` from
``BaseScenario.observation_layout(agent)``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

__all__ = ["LidarColumns", "ObservationLayout"]


@dataclass(frozen=True)
class LidarColumns:
    """``count`` lidar readings from column ``start``, each in ``[0, max_value]``; ``miss`` where a ray
    sees nothing (0 for proximities such as ``range - distance``, the range for distances)."""

    start: int
    count: int
    max_value: float
    miss: float = 0.0


@dataclass(frozen=True)
class ObservationLayout:
    """An agent's observation columns that move with its own measured position, velocity and lidar.

    ``position``: ``(column, sign)`` per (x, y) pair that holds the agent's
    position (sign +1; also the position minus something, such as ``pos -
    goal``) or something minus it (sign -1, such as a landmark relative to the
    agent). A position error ``e`` moves every such pair by ``sign * e``, as it
    would on a robot that computes them from its odometry. ``velocity``: the
    same for its velocity. ``lidar``: its rays, or None.
    """

    position: Tuple[Tuple[int, int], ...] = ()
    velocity: Tuple[Tuple[int, int], ...] = ()
    lidar: Optional[LidarColumns] = None

    def width_needed(self) -> int:
        """The smallest observation width these columns fit in."""
        ends = [column + 2 for column, _ in self.position + self.velocity]
        if self.lidar is not None:
            ends.append(self.lidar.start + self.lidar.count)
        return max(ends, default=0)
