"""``make_env(..., num_envs=1, wrapper="gym")``: one environment behind the legacy ``gym`` API.

For code written against VMAS's ``GymWrapper``, which keeps the pre-0.26 gym
calling convention: ``reset()`` returns the observations alone and ``step``
returns ``(obs, rewards, done, info)`` with one ``done`` bool, so the
Environment must be made with ``terminated_truncated=False`` (``make_env``'s
default). Observations are a list in agent order (a dict by name with
``dict_spaces=True``) of numpy arrays (tensors with ``return_numpy=False``),
rewards the same container of Python floats, ``info`` a dict by agent name;
spaces are ``gym.spaces``; ``env.unwrapped`` is the Environment.

``gym`` is an optional extra (``pip install vmas_ros[gym]``): only this module
imports it, so ``import vmas_ros`` and the other wrappers never need it. New
code should prefer ``wrapper="gymnasium"``.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Union

import numpy as np

from vmas_ros.envs import wrapper_common as common
from vmas_ros.envs.environment import Environment

try:
    import gym
except ImportError as error:  # pragma: no cover - depends on the install
    raise ImportError(
        "wrapper='gym' needs the legacy gym package, an optional extra: pip install vmas_ros[gym] "
        "(or use wrapper='gymnasium')"
    ) from error

__all__ = ["GymWrapper", "to_gym_space"]


def to_gym_space(space: Any) -> "gym.spaces.Space":
    """The legacy ``gym`` twin of a space: itself if it is one, else a converted gymnasium space.

    Box, Discrete, MultiDiscrete, MultiBinary, Tuple and Dict (all the
    Environment builds); anything else is refused with its type named.
    """
    if isinstance(space, gym.spaces.Space):
        return space
    kind = type(space).__name__
    if kind == "Box":
        return gym.spaces.Box(low=space.low, high=space.high, shape=space.shape, dtype=space.dtype)
    if kind == "Discrete":
        return gym.spaces.Discrete(int(space.n), start=int(space.start))
    if kind == "MultiDiscrete":
        return gym.spaces.MultiDiscrete(space.nvec, dtype=space.dtype)
    if kind == "MultiBinary":
        return gym.spaces.MultiBinary(space.n)
    if kind == "Tuple":
        return gym.spaces.Tuple([to_gym_space(s) for s in space.spaces])
    if kind == "Dict":
        return gym.spaces.Dict({key: to_gym_space(s) for key, s in space.spaces.items()})
    raise TypeError(f"cannot convert {type(space).__module__}.{kind} to a gym space: {space!r}")


class GymWrapper(common.BaseGymWrapper, gym.Env):
    """A single-env :class:`Environment` (``num_envs=1``, one ``done`` flag) behind legacy gym's ``Env``.

    Args:
        env: the Environment, made with ``num_envs=1`` and ``terminated_truncated=False``.
        return_numpy: False keeps torch tensors (on ``env.device``) for observations and infos.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 30}

    def __init__(self, env: Environment, return_numpy: bool = True) -> None:
        common.require_single_env(env, "gym", "; use wrapper='gymnasium_vec' for a batch of envs")
        if env.terminated_truncated:
            raise ValueError(
                "wrapper 'gym' reports one done flag: make the Environment with terminated_truncated=False "
                "(or use wrapper='gymnasium', which reports terminated and truncated)"
            )
        super().__init__(env, return_numpy=return_numpy, vectorized=False)
        self.observation_space = to_gym_space(env.observation_space)
        self.action_space = to_gym_space(env.action_space)

    def seed(self, seed: Optional[int] = None) -> List[int]:
        """Re-seed the Environment (the pre-0.26 gym call, used by gym's ``EnvCompatibility``)."""
        return self._env.seed(seed)

    def reset(
        self, *, seed: Optional[int] = None, return_info: bool = False, options: Optional[dict] = None
    ) -> Any:
        """Start a new episode: the observations, or ``(obs, info)`` with ``return_info=True``.

        ``seed`` re-seeds the Environment's own streams. VMAS ignores
        ``return_info``; honouring it costs nothing and gives the infos to whoever asks.
        """
        if seed is not None:
            self._env.seed(seed)
        obs, infos = self._env.reset_at(0, return_info=True)
        if return_info:
            return self._per_agent(obs), self._infos(infos)
        return self._per_agent(obs)

    def step(self, action: Union[tuple, list, Dict[str, Any]]) -> tuple:
        """Apply one action per agent (list/tuple in agent order, or dict by name): ``(obs, rewards, done, info)``.

        Each action has the agent's action-space shape, or ``[1, size]`` as
        ``env.unwrapped.get_random_action(agent)`` gives it.
        """
        actions = common.actions_to_tensors(self._env, action, batched=False, batch_of_one=True)
        obs, rews, dones, infos = self._env.step(actions)
        return self._per_agent(obs), self._scalar_rewards(rews), bool(dones[0]), self._infos(infos)

    def render(
        self,
        mode: str = "rgb_array",
        agent_index_focus: Optional[int] = None,
        visualize_when_rgb: bool = False,
        **kwargs: Any,
    ) -> Optional[np.ndarray]:
        """The frame as an HxWx3 uint8 array; ``mode`` is ``"rgb_array"`` (or ``"human"``, drawn the same)."""
        return self._render_env(mode, 0, agent_index_focus, visualize_when_rgb, **kwargs)

    def close(self) -> None:
        self._env.close()
