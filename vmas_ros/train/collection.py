"""Where a training batch comes from: the envs in this process, or collectors on a Ray cluster.

A *collection* hands the trainer one batch per iteration, shaped
``[num_envs, steps_per_batch]`` whichever way it was gathered, so the PPO update
never knows (or changes with) how many processes stepped the envs:

* :class:`LocalCollection` steps one batched env in this process (``--ray-address none``);
* :class:`~vmas_ros.train.ray_collection.RayCollection` asks ``--collectors`` Ray actors
  for ``num_envs / collectors`` envs' worth each and joins their batches.

Both keep the envs running across iterations (an episode may span two batches)
and count finished episodes' returns with the same :class:`EpisodeReturns`.
"""
from __future__ import annotations

import abc
import time
from typing import Any, Dict, List, Tuple

import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

__all__ = ["Collection", "LocalCollection", "EpisodeReturns", "SEED_STRIDE"]

#: collector k's envs are seeded ``seed + k * SEED_STRIDE`` so collectors never replay each other
SEED_STRIDE = 1_000_003


class EpisodeReturns:
    """Running per-env returns across batches; yields the returns of episodes that ended.

    The return of an episode is the sum over its steps of the reward averaged
    over agents (what ``log.csv``'s ``episode_reward_mean`` averages).
    """

    def __init__(self, num_envs: int, device: torch.device) -> None:
        self.running = torch.zeros(num_envs, device=device)

    def update(self, batch: TensorDictBase) -> torch.Tensor:
        """Add a ``[num_envs, T]`` batch; returns the finished episodes' returns (1-D, any length)."""
        rewards = batch.get(("next", "agents", "reward")).mean(dim=(-2, -1))
        done = batch.get(("next", "done")).squeeze(-1)
        finished: List[torch.Tensor] = []
        for t in range(rewards.shape[1]):
            self.running += rewards[:, t]
            finished.append(torch.where(done[:, t], self.running, torch.nan))
            self.running = torch.where(done[:, t], 0.0, self.running)
        episodes = torch.stack(finished)
        return episodes[~torch.isnan(episodes)]


class Collection(abc.ABC):
    """What the trainer asks of a collection (see the module docstring)."""

    @abc.abstractmethod
    def describe(self) -> Dict[str, Any]:
        """Where the envs run and how fast: ``{"ray_address", "collectors": [one entry per process]}``."""

    @abc.abstractmethod
    def collect(self) -> Tuple[TensorDictBase, torch.Tensor]:
        """One batch ``[num_envs, steps_per_batch]`` and the returns of the episodes that ended in it."""

    def policy_updated(self) -> None:
        """The learner changed the policy's weights: the next batch must use them."""

    def close(self) -> None:
        """Stop whatever the collection started (idempotent)."""


class LocalCollection(Collection):
    """Step a batched TorchRL env in this process with the stochastic policy.

    Args:
        env: the :class:`~vmas_ros.envs.torchrl_env.TorchRLEnv` (batch ``[num_envs]``).
        policy: the stochastic policy (reads the observation, writes action and log-prob).
        steps: steps per batch.
    """

    def __init__(self, env, policy, steps: int) -> None:
        self.env, self.policy, self.steps = env, policy, steps
        self._td = env.reset()
        self.returns = EpisodeReturns(env.batch_size[0], env.device)
        self._frames, self._seconds = 0, 0.0

    @torch.no_grad()
    def collect(self) -> Tuple[TensorDictBase, torch.Tensor]:
        start = time.perf_counter()
        steps, td = [], self._td
        with set_exploration_type(ExplorationType.RANDOM):
            for _ in range(self.steps):
                td = self.policy(td)
                step, td = self.env.step_and_maybe_reset(td)
                steps.append(step)
        self._td = td
        batch = torch.stack(steps, dim=1)
        self._frames += batch.numel()
        self._seconds += time.perf_counter() - start
        return batch, self.returns.update(batch)

    def describe(self) -> Dict[str, Any]:
        return {"ray_address": None, "collectors": [{
            "index": 0, "where": "this process", "num_envs": int(self.env.batch_size[0]), "frames": self._frames,
            "collect_seconds": round(self._seconds, 4),
            "frames_per_second": round(self._frames / self._seconds, 1) if self._seconds else None}]}
