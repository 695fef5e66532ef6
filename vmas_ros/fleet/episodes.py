"""Episodes: where the robots start and where their goals are, read and validated before anything runs.

The format (YAML or JSON), so that a run can replay another simulator's resets::

    episodes:
      - robots: [[x, y, yaw], ...]   # one per robot, in robot order; m, m, rad in the odom frame
        goals: [[x, y], ...]         # optional, any count

With as many goals as robots, goal ``i`` is robot ``i``'s (navigation);
another count makes them landmarks to cover. ``start_poses`` gives one
episode in the same form without the ``episodes`` list. Every refusal names
where the bad value is (``episodes[1].robots[2]``) and what was expected: a
run of many episodes must not stop in its middle over a typo.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, List

import numpy as np
import yaml

from vmas_ros.fleet.contacts import Arena, pairwise_distance

__all__ = ["Episode", "episode_from", "episodes_from", "load_file", "check", "line_up", "plan"]

#: tolerance of the overlap and wall checks of start poses, m (a replayed pose rounded to print)
START_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Episode:
    """One episode's start: ``robots [n, 3]`` (x, y, yaw) and ``goals [g, 2]`` (g may be 0)."""

    robots: np.ndarray
    goals: np.ndarray

    @property
    def per_robot_goals(self) -> bool:
        """Whether goal ``i`` is robot ``i``'s (as many goals as robots)."""
        return len(self.goals) == len(self.robots)

    def to_json(self) -> dict:
        return {"robots": self.robots.tolist(), "goals": self.goals.tolist()}


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _rows(value: Any, width: int, where: str, form: str) -> np.ndarray:
    """``value`` as a ``[k, width]`` array of finite numbers, or a ValueError naming the bad entry."""
    if not isinstance(value, list):
        raise ValueError(f"{where} must be a list of {form}, got {value!r}")
    for i, row in enumerate(value):
        if not (isinstance(row, list) and len(row) == width and all(_number(v) for v in row)):
            raise ValueError(f"{where}[{i}] must be {form} ({width} numbers), got {row!r}")
        if not all(math.isfinite(v) for v in row):
            raise ValueError(f"{where}[{i}] must hold finite numbers, got {row!r}")
    return np.array(value, dtype=np.float64).reshape(-1, width)


def episode_from(data: Any, where: str) -> Episode:
    """One episode from its parsed mapping; ``where`` prefixes messages (``episodes[3]``)."""
    if not isinstance(data, dict):
        raise ValueError(f"{where} must be a mapping {{robots: [[x, y, yaw], ...], goals: [[x, y], ...]}}, "
                         f"got {data!r}")
    unknown = sorted(set(map(str, data)) - {"robots", "goals"})
    if unknown:
        raise ValueError(f"{where} has unknown keys {unknown}: expected robots and (optional) goals")
    if "robots" not in data:
        raise ValueError(f"{where} lacks robots: expected robots: [[x, y, yaw], ...], one per robot")
    robots = _rows(data["robots"], 3, f"{where}.robots", "[x, y, yaw]")
    goals = data.get("goals")
    goals = np.zeros((0, 2)) if goals is None else _rows(goals, 2, f"{where}.goals", "[x, y]")
    return Episode(robots=robots, goals=goals)


def episodes_from(data: Any, where: str) -> List[Episode]:
    """Every episode of a parsed episodes file (``{episodes: [...]}``)."""
    if not isinstance(data, dict) or "episodes" not in data:
        raise ValueError(f"{where} must be a mapping with a list 'episodes', got {str(data)[:80]!r}")
    unknown = sorted(set(map(str, data)) - {"episodes"})
    if unknown:
        raise ValueError(f"{where} has unknown keys {unknown}: expected only 'episodes'")
    listed = data["episodes"]
    if not isinstance(listed, list) or not listed:
        raise ValueError(f"{where}: episodes must be a non-empty list of episodes, got {listed!r}")
    return [episode_from(item, f"{where}: episodes[{i}]") for i, item in enumerate(listed)]


def load_file(path: str) -> List[Episode]:
    """The episodes of a YAML or JSON file (``.json``: JSON; otherwise YAML)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"episodes_file {path!r} cannot be read: {error}") from None
    try:
        data = json.loads(text) if path.endswith(".json") else yaml.safe_load(text)
    except (ValueError, yaml.YAMLError) as error:
        raise ValueError(f"episodes_file {path!r} is not valid {'JSON' if path.endswith('.json') else 'YAML'}: "
                         f"{error}") from None
    return episodes_from(data, f"episodes_file {path}")


def check(episode: Episode, n_robots: int, radius: float, arena: Arena, where: str) -> None:
    """Refuse an episode the fleet cannot start: wrong robot count, overlapping robots, anything outside the walls."""
    robots = episode.robots
    if len(robots) != n_robots:
        raise ValueError(f"{where} has {len(robots)} robots, n_robots is {n_robots}: expected one [x, y, yaw] "
                         f"per robot")
    if n_robots > 1:
        distance = pairwise_distance(robots[:, :2])
        i, j = np.unravel_index(np.argmin(distance), distance.shape)
        if distance[i, j] < 2 * radius - START_TOLERANCE:
            i, j = sorted((int(i), int(j)))
            raise ValueError(f"{where}: robots {i} at {robots[i, :2].tolist()} and {j} at {robots[j, :2].tolist()} "
                             f"overlap ({distance[i, j]:.4g} m apart): robots of radius {radius:g} need "
                             f">= {2 * radius:g} m between centres")
    room = arena.halves - radius + START_TOLERANCE
    outside = np.flatnonzero((np.abs(robots[:, :2]) > room).any(axis=1))
    if len(outside):
        k = int(outside[0])
        raise ValueError(f"{where}: robot {k} at {robots[k, :2].tolist()} is not inside the walls: expected "
                         f"|x| <= {room[0]:g} and |y| <= {room[1]:g} (arena half sizes minus robot_radius)")
    beyond = np.flatnonzero((np.abs(episode.goals) > arena.halves).any(axis=1))
    if len(beyond):
        k = int(beyond[0])
        raise ValueError(f"{where}: goal {k} at {episode.goals[k].tolist()} is outside the walls: expected "
                         f"|x| <= {arena.halves[0]:g} and |y| <= {arena.halves[1]:g}")


def line_up(n_robots: int, radius: float, arena: Arena) -> Episode:
    """Robots side by side on the y axis, all facing +x (free to drive forward), a diameter of free space
    between neighbours, no goals."""
    spacing = 4 * radius
    y = (np.arange(n_robots) - (n_robots - 1) / 2) * spacing
    if arena.half_y and y[-1] > arena.half_y - radius:
        raise ValueError(f"{n_robots} robots side by side need arena_half_y >= {y[-1] + radius:g}, it is "
                         f"{arena.half_y:g}: give start_poses or an episodes_file")
    robots = np.stack([np.zeros(n_robots), y, np.zeros(n_robots)], axis=1)
    return Episode(robots=robots, goals=np.zeros((0, 2)))


def plan(params) -> List[Episode]:
    """The episodes robot_fleet's parameter values ask for, every one checked."""
    arena = Arena(params.arena_half_x, params.arena_half_y)
    if params.episodes_file:
        episodes = load_file(params.episodes_file)
        where = [f"episodes_file {params.episodes_file}: episodes[{i}]" for i in range(len(episodes))]
    elif params.start_poses:
        episodes = [episode_from(yaml.safe_load(params.start_poses), "start_poses")]
        where = ["start_poses"]
    else:
        episodes, where = [line_up(params.n_robots, params.robot_radius, arena)], ["the default start"]
    for episode, place in zip(episodes, where):
        check(episode, params.n_robots, params.robot_radius, arena, place)
    return episodes
