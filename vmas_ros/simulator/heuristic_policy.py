"""Hand-written policies: the baselines scenarios ship beside their task."""
from __future__ import annotations

import abc
from typing import List, Optional, Sequence

import torch

__all__ = ["BaseHeuristicPolicy", "RandomPolicy", "heuristic_actions"]


class BaseHeuristicPolicy(abc.ABC):
    """A decentralised policy mapping one agent's observation to its action, batched over envs."""

    def __init__(self, continuous_action: bool = True) -> None:
        self.continuous_actions = continuous_action

    @abc.abstractmethod
    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        """Action [batch, action_size] for observation [batch, obs_size]."""


class RandomPolicy(BaseHeuristicPolicy):
    """Gaussian noise clipped to the action range; the baseline heuristics must beat."""

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        n_envs = observation.shape[0]
        return torch.clamp(torch.randn(n_envs, 2, device=observation.device), -u_range, u_range)


def heuristic_actions(
    policy: Optional[BaseHeuristicPolicy], env, observations: Sequence[torch.Tensor]
) -> List[torch.Tensor]:
    """Every agent's action ``[batch, action_size]``, in ``env.agents`` order, from ``policy``.

    Each agent's observation ``[batch, obs_size]`` goes through
    ``policy.compute_action`` with that agent's ``u_range``. ``policy`` None:
    the env's uniform random actions, the baseline a heuristic is compared with.
    """
    if policy is None:
        return env.get_random_actions()
    return [policy.compute_action(obs, u_range=agent.u_range) for obs, agent in zip(observations, env.agents)]
