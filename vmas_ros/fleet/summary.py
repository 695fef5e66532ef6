"""What an evaluation measured, per episode, and the JSON file that keeps it.

:class:`EpisodeTracker` follows one episode step by step (times in episode
seconds, distances in m, from the true state, never the noisy odometry):

* ``time_to_goal [n]``: when each robot's centre first came within
  ``goal_radius`` of its own goal (only with one goal per robot);
* ``all_at_goal_time``: the first time every robot was within ``goal_radius``
  of its goal at once (a navigation episode's ``done``);
* contact onsets per robot, with robots and with walls (see
  :mod:`vmas_ros.fleet.contacts`);
* ``min_separation``: the smallest centre distance between two robots seen
  (``2 * robot_radius``: they touched).

:func:`document` puts the finished episodes together with the node's
parameters, so that a table built from the file can state the noise,
latency and lag it ran with; :func:`write_atomic` replaces the file in one
step (a reader never sees half a file, a crash leaves the previous one).
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from vmas_ros.fleet.contacts import pairwise_distance
from vmas_ros.fleet.episodes import Episode

__all__ = ["EpisodeTracker", "coverage", "document", "write_atomic", "ENDINGS"]

#: why an episode ended: its time was up, every robot stood on its goal (``end_on_goals``), ~/reset asked, or
#: the node stopped during it
ENDINGS = ("time", "goals", "reset", "shutdown")


def _plain(value: float) -> Optional[float]:
    """A float for JSON; None for NaN or inf (JSON has neither)."""
    return float(value) if math.isfinite(value) else None


def coverage(positions: np.ndarray, goals: np.ndarray) -> Optional[float]:
    """Mean over ``goals [g, 2]`` of the distance to the nearest of ``positions [n, 2]``; None without goals."""
    if not len(goals):
        return None
    gaps = goals[:, None, :] - positions[None, :, :]  # [g, n, 2]
    return float(np.sqrt((gaps * gaps).sum(axis=-1)).min(axis=1).mean())


class EpisodeTracker:
    """The metrics of one running episode (see the module); ``advance`` once per integration step."""

    def __init__(self, index: int, plan_index: int, episode: Episode, goal_radius: float) -> None:
        self.index, self.plan_index = index, plan_index  # episodes run before it; its place in the plan
        self.episode, self.goal_radius = episode, goal_radius
        n = len(episode.robots)
        self.elapsed = 0.0  # episode seconds
        self.steps = 0
        self.time_to_goal = np.full(n, np.nan)  # [n]
        self.all_at_goal_time = math.nan  # the first time every robot stood within goal_radius at once
        self.robot_contacts = np.zeros(n, dtype=np.int64)  # [n] onsets with another robot
        self.wall_contacts = np.zeros(n, dtype=np.int64)  # [n] onsets with a wall
        self.min_separation = math.inf
        self.observe(episode.robots)

    def advance(self, dt: float, pose: np.ndarray, robot_onsets: np.ndarray, wall_onsets: np.ndarray) -> None:
        """One step of ``dt`` s ended with the fleet at ``pose [n, 3]`` and these onsets ``[n]``."""
        self.elapsed += dt
        self.steps += 1
        self.robot_contacts += robot_onsets
        self.wall_contacts += wall_onsets
        self.observe(pose)

    def observe(self, pose: np.ndarray) -> None:
        """Note goals reached and the separation at ``pose [n, 3]``, at the current ``elapsed``."""
        if self.episode.per_robot_goals:
            distance = np.linalg.norm(pose[:, :2] - self.episode.goals, axis=1)
            within = distance <= self.goal_radius
            self.time_to_goal[np.isnan(self.time_to_goal) & within] = self.elapsed
            if math.isnan(self.all_at_goal_time) and within.all():
                self.all_at_goal_time = self.elapsed
        if len(pose) > 1:
            self.min_separation = min(self.min_separation, float(pairwise_distance(pose[:, :2]).min()))

    @property
    def all_at_goal(self) -> bool:
        """Whether every robot has stood within ``goal_radius`` of its own goal at once (navigation's done)."""
        return not math.isnan(self.all_at_goal_time)

    def reached(self) -> int:
        """How many robots have reached their goal so far."""
        return int((~np.isnan(self.time_to_goal)).sum()) if self.episode.per_robot_goals else 0

    def record(self, pose: np.ndarray, ended_by: str) -> Dict[str, Any]:
        """The finished episode's entry of the summary, the fleet standing at ``pose [n, 3]``."""
        episode = self.episode
        per_robot = episode.per_robot_goals
        times = [_plain(t) for t in self.time_to_goal] if per_robot else None
        all_reached = (float(np.max(self.time_to_goal))
                       if per_robot and not np.isnan(self.time_to_goal).any() else None)
        final = (np.linalg.norm(pose[:, :2] - episode.goals, axis=1).tolist() if per_robot else None)
        return {
            "index": self.index,
            "plan_index": self.plan_index,
            "ended_by": ended_by,
            "start": episode.to_json(),
            "duration": self.elapsed,
            "steps": self.steps,
            "final_poses": pose.tolist(),
            "time_to_goal": times,
            "all_reached_time": all_reached,
            "all_at_goal_time": _plain(self.all_at_goal_time) if per_robot else None,
            "final_distance": final,
            "collisions": {
                "robot_robot": int(self.robot_contacts.sum() // 2),
                "robot_wall": int(self.wall_contacts.sum()),
                "per_robot_robot": self.robot_contacts.tolist(),
                "per_robot_wall": self.wall_contacts.tolist(),
            },
            "coverage": coverage(pose[:, :2], episode.goals),
            "min_separation": _plain(self.min_separation),
        }


def document(parameters: Dict[str, Any], names: List[str], planned: int, records: List[dict],
             complete: bool) -> Dict[str, Any]:
    """The whole summary: the node's parameters, its robots and every finished episode."""
    return {
        "node": "robot_fleet",
        "robot_names": list(names),
        "parameters": dict(parameters),
        "episodes_planned": planned,
        "complete": complete,
        "episodes": list(records),
    }


def write_atomic(path: str, doc: Dict[str, Any]) -> None:
    """Write ``doc`` as JSON to ``path`` through a temporary file and ``os.replace``."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        with open(temporary, "w", encoding="utf-8") as out:
            json.dump(doc, out, indent=2, allow_nan=False)
            out.write("\n")
            out.flush()
            os.fsync(out.fileno())
        os.replace(temporary, target)
    finally:
        if temporary.exists():
            temporary.unlink()
