"""``make_env(..., num_envs=1, wrapper="gymnasium")``: one environment as a ``gymnasium.Env``.

Follows VMAS 1.5's gymnasium wrapper: spaces are gymnasium ``Tuple`` over the
agents (``Dict`` by name with ``dict_spaces=True``), observations numpy
arrays, the reward per agent (a tuple, or a dict), ``terminated`` and
``truncated`` plain bools and ``info`` a dict by agent name. ``sum_rewards=True``
returns one float instead, for single-reward algorithms (and it is what
gymnasium's checker expects of a reward).
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Tuple, Union

import gymnasium
import numpy as np

from vmas_ros.envs import wrapper_common as common
from vmas_ros.envs.environment import Environment

__all__ = ["GymnasiumEnv"]

RENDER_MODES = ["rgb_array"]


def check_render_mode(render_mode: Optional[str]) -> Optional[str]:
    """Only headless ``rgb_array`` frames exist (or no rendering); refuse anything else early."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be one of {RENDER_MODES} or None, got {render_mode!r}")
    return render_mode


class GymnasiumEnv(common.SingleEnvWrapper, gymnasium.Env):
    """A single-env :class:`Environment` (``num_envs=1``) behind gymnasium's ``Env`` API.

    Args:
        env: the Environment, made with ``num_envs=1`` and ``terminated_truncated=True``.
        render_mode: ``"rgb_array"`` (``render()`` returns an HxWx3 uint8 array) or None.
        return_numpy: False keeps torch tensors (on ``env.device``) instead of numpy, as in VMAS.
        sum_rewards: True returns the agents' rewards summed into one float.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30}

    def __init__(
        self,
        env: Environment,
        render_mode: Optional[str] = "rgb_array",
        return_numpy: bool = True,
        sum_rewards: bool = False,
    ) -> None:
        common.require_single_env(env, "gymnasium", "; use wrapper='gymnasium_vec' for a batch of envs")
        common.require_terminated_truncated(env, "gymnasium")
        self.env = env
        self.render_mode = check_render_mode(render_mode)
        self.return_numpy = return_numpy
        self.sum_rewards = sum_rewards
        self.observation_space = env.observation_space
        self.action_space = env.action_space

    def _convert(self, value: Any) -> Any:
        # row 0: the only env; tensors stay tensors (sliced) when return_numpy is off
        if self.return_numpy:
            return common.to_numpy(value, index=0)
        return common.select_env(value, 0)

    def _observation(self, obs) -> Union[Tuple, Dict[str, Any]]:
        return common.pack(self._convert(common.by_agent(self.env, obs)), self.env.dict_spaces)

    def _info(self, infos) -> Dict[str, Any]:
        return self._convert(common.by_agent(self.env, infos))

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[dict] = None
    ) -> Tuple[Union[Tuple, Dict[str, Any]], Dict[str, Any]]:
        """Start a new episode; ``seed`` re-seeds the Environment's own streams (and ``np_random``)."""
        super().reset(seed=seed)
        if seed is not None:
            self.env.seed(seed)
        obs, infos = self.env.reset(return_info=True)
        return self._observation(obs), self._info(infos)

    def step(self, action: Union[Tuple, list, Dict[str, Any]]) -> Tuple[Any, Any, bool, bool, Dict[str, Any]]:
        """Apply one action per agent (tuple/list in agent order, or dict by name)."""
        actions = common.actions_to_tensors(self.env, action, batched=False)
        obs, rews, terminated, truncated, infos = self.env.step(actions)
        rewards = common.by_agent(self.env, rews)
        if self.sum_rewards:
            reward: Any = float(sum(float(r[0]) for r in rewards.values()))
        elif self.return_numpy:
            reward = common.pack({name: float(r[0]) for name, r in rewards.items()}, self.env.dict_spaces)
        else:
            reward = common.pack({name: r[0] for name, r in rewards.items()}, self.env.dict_spaces)
        return self._observation(obs), reward, bool(terminated[0]), bool(truncated[0]), self._info(infos)


