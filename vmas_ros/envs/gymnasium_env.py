"""``make_env(..., num_envs=1, wrapper="gymnasium")``: one environment as a ``gymnasium.Env``.

Follows VMAS 1.5's gymnasium wrapper: spaces are gymnasium ``Tuple`` over the
agents (``Dict`` by name with ``dict_spaces=True``); ``reset`` returns
``(obs, info)`` and ``step`` ``(obs, rewards, terminated, truncated, info)``,
where ``obs`` is a list in agent order (a dict with ``dict_spaces``) of numpy
arrays (tensors with ``return_numpy=False``), ``rewards`` the same container of
Python floats, ``terminated``/``truncated`` bools and ``info`` a dict by agent
name. ``env.unwrapped`` is the Environment.

Beyond VMAS: ``sum_rewards=True`` returns one float, for single-reward
algorithms (and what gymnasium's checker expects of a reward).
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple, Union

import gymnasium
import numpy as np

from vmas_ros.envs import wrapper_common as common
from vmas_ros.envs.environment import Environment

__all__ = ["GymnasiumWrapper", "GymnasiumEnv", "RENDER_MODES", "check_render_mode"]

RENDER_MODES = ["rgb_array"]


def check_render_mode(render_mode: Optional[str]) -> Optional[str]:
    """Only headless ``rgb_array`` frames exist (or no rendering); refuse anything else early."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be one of {RENDER_MODES} or None, got {render_mode!r}")
    return render_mode


class GymnasiumWrapper(common.BaseGymWrapper, gymnasium.Env):
    """A single-env :class:`Environment` (``num_envs=1``) behind gymnasium's ``Env`` API.

    Args:
        env: the Environment, made with ``num_envs=1`` and ``terminated_truncated=True``.
        return_numpy: False keeps torch tensors (on ``env.device``) for observations and infos.
        render_mode: ``"rgb_array"`` (``render()`` returns an HxWx3 uint8 array) or None;
            there is no window, so VMAS's ``"human"`` is refused.
        sum_rewards: True returns the agents' rewards summed into one float.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30}

    def __init__(
        self,
        env: Environment,
        return_numpy: bool = True,
        render_mode: Optional[str] = "rgb_array",
        sum_rewards: bool = False,
    ) -> None:
        common.require_single_env(env, "gymnasium", "; use wrapper='gymnasium_vec' for a batch of envs")
        common.require_terminated_truncated(env, "gymnasium")
        super().__init__(env, return_numpy=return_numpy, vectorized=False)
        self.render_mode = check_render_mode(render_mode)
        self.sum_rewards = sum_rewards
        self.observation_space = common.to_gymnasium_space(env.observation_space)
        self.action_space = common.to_gymnasium_space(env.action_space)

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[dict] = None
    ) -> Tuple[Union[List, Dict[str, Any]], Dict[str, Any]]:
        """Start a new episode; ``seed`` re-seeds the Environment's own streams (and ``np_random``)."""
        super().reset(seed=seed)
        # gymnasium (its checker, too) reads the generator off env.unwrapped, which is the Environment
        self._env._np_random = self._np_random
        if seed is not None:
            self._env.seed(seed)
        obs, infos = self._env.reset_at(0, return_info=True)
        return self._per_agent(obs), self._infos(infos)

    def step(self, action: Union[Tuple, list, Dict[str, Any]]) -> Tuple[Any, Any, bool, bool, Dict[str, Any]]:
        """Apply one action per agent (list/tuple in agent order, or dict by name).

        Each action has the agent's action-space shape, or ``[1, size]`` as
        ``env.unwrapped.get_random_action(agent)`` gives it.
        """
        actions = common.actions_to_tensors(self._env, action, batched=False, batch_of_one=True)
        obs, rews, terminated, truncated, infos = self._env.step(actions)
        rewards = self._scalar_rewards(rews)
        reward: Any = float(sum(common.by_agent(self._env, rewards).values())) if self.sum_rewards else rewards
        return self._per_agent(obs), reward, bool(terminated[0]), bool(truncated[0]), self._infos(infos)

    def render(
        self, agent_index_focus: Optional[int] = None, visualize_when_rgb: bool = False, **kwargs: Any
    ) -> Optional[np.ndarray]:
        """The frame as an HxWx3 uint8 array (None when made with ``render_mode=None``)."""
        if self.render_mode is None:
            return None
        return self._render_env(self.render_mode, 0, agent_index_focus, visualize_when_rgb, **kwargs)

    def close(self) -> None:
        self._env.close()


#: the name this wrapper had before it took VMAS's
GymnasiumEnv = GymnasiumWrapper
