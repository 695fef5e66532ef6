"""``make_env(..., num_envs=1, wrapper="pettingzoo")``: one environment as a PettingZoo ``ParallelEnv``.

Every agent acts every step, as in the Environment. PettingZoo removes agents
from ``agents`` once they are terminated or truncated; an Environment episode
ends for all agents at once, so ``agents`` empties on the step the episode ends
and ``reset()`` fills it again. Observations are numpy arrays, rewards floats,
all dicts by agent name.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Tuple

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from vmas_ros.envs import wrapper_common as common
from vmas_ros.envs.environment import Environment
from vmas_ros.envs.gymnasium_env import RENDER_MODES, check_render_mode

__all__ = ["PettingZooEnv"]


class PettingZooEnv(common.SingleEnvWrapper, ParallelEnv):
    """A single-env :class:`Environment` (``num_envs=1``) behind PettingZoo's parallel API.

    Args:
        env: the Environment, made with ``num_envs=1`` and ``terminated_truncated=True``.
        render_mode: ``"rgb_array"`` (``render()`` returns an HxWx3 uint8 array) or None.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30, "is_parallelizable": True}

    def __init__(self, env: Environment, render_mode: Optional[str] = "rgb_array") -> None:
        common.require_single_env(env, "pettingzoo")
        common.require_terminated_truncated(env, "pettingzoo")
        self.env = env
        self.render_mode = check_render_mode(render_mode)
        self.metadata = {**type(self).metadata, "name": f"vmas_ros_{type(env.scenario).__module__.rsplit('.', 1)[-1]}"}
        self.possible_agents = common.agent_names(env)
        self.agents = list(self.possible_agents)
        # the same space objects every call: PettingZoo seeds action spaces through them
        self.observation_spaces, self.action_spaces = common.agent_spaces(env)

    def observation_space(self, agent: str) -> spaces.Space:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self.action_spaces[agent]

    def reset(
        self, seed: Optional[int] = None, options: Optional[dict] = None
    ) -> Tuple[Dict[str, Any], Dict[str, Any]]:
        """Start a new episode with every agent; ``seed`` re-seeds the Environment's streams."""
        self.agents = list(self.possible_agents)
        return self._reset_env(seed)

    def step(self, actions: Dict[str, Any]) -> Tuple[Dict[str, Any], ...]:
        """Apply one action per live agent (a dict by name); all live agents must act."""
        if not self.agents:
            raise ValueError("the episode is over (no live agents): call reset() before step()")
        tensors = common.actions_to_tensors(self.env, actions, batched=False, names=self.possible_agents)
        obs, rews, terminated, truncated, infos = self.env.step(tensors)
        term, trunc = bool(terminated[0]), bool(truncated[0])
        names = self.agents
        observations = common.to_numpy(common.by_agent(self.env, obs), index=0)
        rewards = {name: float(r[0]) for name, r in common.by_agent(self.env, rews).items()}
        info = common.to_numpy(common.by_agent(self.env, infos), index=0)
        result = (
            {n: observations[n] for n in names},
            {n: rewards[n] for n in names},
            {n: term for n in names},
            {n: trunc for n in names},
            {n: info[n] for n in names},
        )
        if term or trunc:
            self.agents = []
        return result

