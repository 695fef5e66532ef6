"""A policy's episodes in the engine, from start states another simulator can replay.

:func:`engine_episodes` resets a batch of envs (one episode each) with a seed,
keeps every start state (robots ``[x, y, yaw]``, goals ``[x, y]``) in the form
``robot_fleet`` reads, then runs the exported policy (``OnnxPolicy``, the
same ONNX file policy_node runs) for ``seconds`` of simulated time, batched
over the episodes. Per episode it measures what robot_fleet's summary
measures, the same way, so the two can sit side by side:

* ``coverage``: mean over the goals (a coverage task's landmarks) of the
  distance to the nearest robot at the end;
* with one goal per robot: ``time_to_goal`` per robot (first time within
  ``goal_radius``), ``all_reached_time`` (the last of those),
  ``all_at_goal_time`` (the first time all are within it at once: navigation's
  ``done``) and ``final_distance``;
* ``collisions``: contact onsets between two robots (centres closer than the
  sum of their radii), counted once per contact, as robot_fleet counts them.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import torch

#: envs reset per wanted episode, so that enough start with the robots apart (see engine_episodes)
OVERSAMPLE = 4


def goals_of(env) -> Tuple[torch.Tensor, bool]:
    """``(goals [B, g, 2], per_robot)``: every agent's own goal entity (navigation: ``per_robot``), else
    every landmark (simple_spread's, to be covered by any robot)."""
    agents = env.world.agents
    if all(getattr(a, "goal", None) is not None for a in agents):
        return torch.stack([a.goal.state.pos for a in agents], dim=1), True
    landmarks = env.world.landmarks
    if not landmarks:
        return torch.zeros(env.num_envs, 0, 2, device=env.device), False
    return torch.stack([lm.state.pos for lm in landmarks], dim=1), False


def robot_poses(env) -> torch.Tensor:
    """Every agent's ``[x, y, yaw]``: ``[B, n, 3]``."""
    return torch.stack([torch.cat([a.state.pos, a.state.rot], dim=-1) for a in env.world.agents], dim=1)


def agent_radius(env) -> float:
    """The agents' disc radius (robot_fleet's ``robot_radius``); refuses teams of other shapes or sizes."""
    radii = {round(float(getattr(a.shape, "radius", math.nan)), 9) for a in env.world.agents}
    if len(radii) != 1 or not all(math.isfinite(r) for r in radii):
        raise ValueError(f"the fleet's robots are discs of one radius; this scenario's agents have radii {radii}")
    return radii.pop()


def _first_time(mask: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Per row of ``mask [steps, ...]``, the time of the first true entry; NaN where none."""
    hit = mask.any(axis=0)
    first = mask.argmax(axis=0)
    return np.where(hit, times[first], np.nan)


def engine_episodes(policy, scenario: str, kwargs: Dict[str, Any], episodes: int, seed: int, seconds: float,
                    goal_radius: Optional[float] = None, device: str = "cpu",
                    end_at_done: bool = False) -> Dict[str, Any]:
    """Run ``policy`` for ``episodes`` episodes of ``seconds`` from the envs' resets with ``seed``.

    Robots cannot start inside one another, while some scenarios (simple_spread)
    spawn agents that overlap: the batch holds ``OVERSAMPLE`` times as many envs
    as episodes, and the episodes are its first envs whose robots start apart
    (``env_index`` says which). Returns ``{"dt", "radius", "goal_radius",
    "starts": [{"robots", "goals"}], "episodes": [per-episode metrics]}``.
    ``goal_radius`` defaults to the agents' radius (navigation's ``done`` rule).
    With ``end_at_done`` an episode with one goal per robot ends where every
    robot first stood on its goal (as robot_fleet's ``end_on_goals``): its
    coverage is taken there, and no collision after it counts.
    """
    from vmas_ros.envs.make_env import make_env

    env = make_env(scenario, num_envs=episodes * OVERSAMPLE, seed=seed, device=device, **kwargs)
    obs = env.reset()
    radius = agent_radius(env)
    kept = _apart(robot_poses(env)[..., :2].cpu().numpy(), radius)[:episodes]
    if len(kept) < episodes:
        raise ValueError(f"seed {seed}: only {len(kept)} of {episodes * OVERSAMPLE} {scenario} resets start with "
                         f"the robots apart, {episodes} needed: ask for fewer episodes per seed")
    goal_radius = radius if goal_radius is None else goal_radius
    dt, steps = env.world.dt, int(round(seconds / env.world.dt))
    goals, per_robot = goals_of(env)
    start_poses, goals = robot_poses(env).cpu().numpy(), goals.cpu().numpy()
    positions = [start_poses[..., :2]]
    for _ in range(steps):
        batch = torch.stack([o.reshape(env.num_envs, -1) for o in obs], dim=1).float()
        actions = torch.as_tensor(policy.act(batch.cpu().numpy()), device=env.device)
        obs, _, _, _ = env.step(list(actions.unbind(1)))
        positions.append(robot_poses(env)[..., :2].cpu().numpy())
    track = np.stack(positions)  # [steps + 1, B, n, 2]
    times = np.arange(steps + 1) * dt
    final = robot_poses(env).cpu().numpy()
    collisions, separation = contact_onsets(track, radius)
    records: List[Dict[str, Any]] = []
    for b in kept:
        end = len(track)  # steps of this episode's track that count, start included
        if per_robot:
            within_all = np.linalg.norm(track[:, b] - goals[b][None], axis=-1) <= goal_radius  # [T, n]
            done = within_all.all(axis=1)
            if end_at_done and done.any():
                end = int(done.argmax()) + 1
        if end < len(track):
            cut_collisions, cut_separation = contact_onsets(track[:end, b:b + 1], radius)
            onsets, closest, last = int(cut_collisions[0]), cut_separation[0], track[end - 1, b]
        else:
            onsets, closest, last = int(collisions[b]), separation[b], final[b, :, :2]
        record = {"env_index": int(b), "coverage": _coverage(last, goals[b]), "robot_robot": onsets,
                  "min_separation": _plain(closest), "duration": float(times[end - 1])}
        if per_robot:
            reached = _first_time(within_all[:end], times[:end])
            record.update(time_to_goal=[_plain(t) for t in reached],
                          all_reached_time=None if np.isnan(reached).any() else float(reached.max()),
                          all_at_goal_time=_plain(_first_time(done[:end], times[:end])),
                          final_distance=np.linalg.norm(track[end - 1, b] - goals[b], axis=-1).tolist())
        records.append(record)
    starts = [{"robots": start_poses[b].tolist(), "goals": goals[b].tolist()} for b in kept]
    return {"dt": dt, "steps": steps, "radius": radius, "goal_radius": goal_radius, "per_robot_goals": per_robot,
            "starts": starts, "episodes": records}


def contact_onsets(track: np.ndarray, radius: float) -> Tuple[np.ndarray, np.ndarray]:
    """``(onsets [B], min_separation [B])`` of robot discs along ``track [T, B, n, 2]``.

    A pair is in contact while its centres are closer than ``2 * radius``; each
    contact counts once, when it begins (robots that start apart, as every
    replayable start does), as robot_fleet counts its collisions.
    """
    gaps = np.linalg.norm(track[:, :, :, None] - track[:, :, None], axis=-1)  # [T, B, n, n]
    n = gaps.shape[-1]
    upper = np.triu(np.ones((n, n), dtype=bool), k=1)
    touching = (gaps < 2 * radius) & upper
    onsets = (touching[1:] & ~touching[:-1]).sum(axis=(0, 2, 3))
    separation = np.where(upper, gaps, np.inf).min(axis=(0, 2, 3)) if n > 1 else np.full(track.shape[1], np.inf)
    return onsets, separation


def _apart(positions: np.ndarray, radius: float) -> List[int]:
    """Indices of the envs whose robots ``[B, n, 2]`` start with their discs apart."""
    n = positions.shape[1]
    if n < 2:
        return list(range(len(positions)))
    gaps = np.linalg.norm(positions[:, :, None] - positions[:, None], axis=-1)
    gaps[:, np.arange(n), np.arange(n)] = np.inf  # a robot is not apart from itself
    return np.flatnonzero(gaps.min(axis=(1, 2)) >= 2 * radius).tolist()


def _coverage(positions: np.ndarray, goals: np.ndarray) -> Optional[float]:
    if not len(goals):
        return None
    return float(np.linalg.norm(goals[:, None] - positions[None], axis=-1).min(axis=1).mean())


def _plain(value: float) -> Optional[float]:
    return float(value) if math.isfinite(value) else None
