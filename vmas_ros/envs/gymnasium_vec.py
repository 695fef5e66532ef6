"""``make_env(..., num_envs=N, wrapper="gymnasium_vec")``: the whole batch as a ``gymnasium.vector.VectorEnv``.

The Environment already steps all ``num_envs`` copies in one call, so this
wrapper only converts: observations are numpy arrays with a leading batch
dimension (a tuple over agents, or a dict with ``dict_spaces=True``), rewards
per agent ``[num_envs]`` float32 arrays (or summed with ``sum_rewards=True``),
``terminated``/``truncated`` ``[num_envs]`` bool arrays.

Autoreset is gymnasium 1.x's ``AutoresetMode.SAME_STEP`` (the default): the
envs that finish in a step are reset in that same step, with one batched
``Environment.reset_at(mask)`` call, and the step returns their *first*
observation of the new episode; the last observation of the finished episode is
in ``info["final_obs"]`` (an object array, None for envs that did not finish,
with the ``info["_final_obs"]`` mask) and its infos in ``info["final_info"]``.
SAME_STEP rather than NEXT_STEP because the reset costs no extra step and no
action is ever ignored. ``autoreset_mode="Disabled"`` leaves finished envs
alone; reset them with ``reset(options={"reset_mask": mask})``.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Sequence, Tuple, Union

import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from vmas_ros.envs import wrapper_common as common
from vmas_ros.envs.environment import Environment
from vmas_ros.envs.gymnasium_env import RENDER_MODES, check_render_mode

__all__ = ["GymnasiumVecEnv"]

_MODES = (AutoresetMode.SAME_STEP, AutoresetMode.DISABLED)


class GymnasiumVecEnv(VectorEnv):
    """All ``num_envs`` envs of an :class:`Environment` behind gymnasium's ``VectorEnv`` API.

    Args:
        env: the Environment, made with ``terminated_truncated=True``.
        render_mode: ``"rgb_array"`` or None; ``render()`` returns one frame per env
            in ``render_env_indices`` (default: every env).
        return_numpy: False keeps torch tensors on ``env.device``, as in VMAS.
        sum_rewards: True returns one ``[num_envs]`` reward array, summed over agents.
        autoreset_mode: ``AutoresetMode.SAME_STEP`` (default) or ``DISABLED`` (or their values).
        render_env_indices: which envs ``render()`` draws.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30, "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        env: Environment,
        render_mode: Optional[str] = "rgb_array",
        return_numpy: bool = True,
        sum_rewards: bool = False,
        autoreset_mode: Union[str, AutoresetMode] = AutoresetMode.SAME_STEP,
        render_env_indices: Optional[Sequence[int]] = None,
    ) -> None:
        common.require_terminated_truncated(env, "gymnasium_vec")
        mode = AutoresetMode(autoreset_mode) if not isinstance(autoreset_mode, AutoresetMode) else autoreset_mode
        if mode not in _MODES:
            raise ValueError(f"autoreset_mode must be one of {[m.value for m in _MODES]}, got {mode.value!r}")
        self.env = env
        self.num_envs = env.num_envs
        self.autoreset_mode = mode
        self.metadata = {**type(self).metadata, "autoreset_mode": mode}
        self.render_mode = check_render_mode(render_mode)
        self.render_env_indices = list(range(env.num_envs)) if render_env_indices is None else list(render_env_indices)
        self.return_numpy = return_numpy
        self.sum_rewards = sum_rewards
        self.single_observation_space = env.observation_space
        self.single_action_space = env.action_space
        self.observation_space = batch_space(self.single_observation_space, n=self.num_envs)
        self.action_space = batch_space(self.single_action_space, n=self.num_envs)

    # ------------------------------------------------------------------ helpers
    def _out(self, value: Any) -> Any:
        return common.to_numpy(value) if self.return_numpy else value

    def _observation(self, obs) -> Union[Tuple, Dict[str, Any]]:
        return common.pack(self._out(common.by_agent(self.env, obs)), self.env.dict_spaces)

    def _info(self, infos, mask: np.ndarray) -> Dict[str, Any]:
        return common.vector_info(self._out(common.by_agent(self.env, infos)), mask)

    def _all(self) -> np.ndarray:
        return np.ones(self.num_envs, dtype=bool)

    # -------------------------------------------------------------------- API
    def reset(
        self, *, seed: Optional[Union[int, Sequence[int]]] = None, options: Optional[dict] = None
    ) -> Tuple[Union[Tuple, Dict[str, Any]], Dict[str, Any]]:
        """Reset every env, or only ``options["reset_mask"]`` (a ``[num_envs]`` bool array).

        ``seed`` is one int for the whole batch: the Environment has one random
        stream for all its envs. A list of equal seeds is accepted (what
        gymnasium passes when one seed is broadcast), differing seeds are not.
        """
        if seed is not None and not isinstance(seed, (int, np.integer)):
            seeds = list(seed)
            if any(s != seeds[0] for s in seeds):
                raise ValueError(f"the batch has one random stream: pass one int seed, got {seeds}")
            seed = seeds[0]
        super().reset(seed=seed)
        if seed is not None:
            self.env.seed(int(seed))
        mask = None if options is None else options.get("reset_mask")
        if mask is None:
            obs, infos = self.env.reset(return_info=True)
            return self._observation(obs), self._info(infos, self._all())
        mask = np.asarray(mask)
        if mask.shape != (self.num_envs,) or mask.dtype != np.bool_:
            raise ValueError(
                f"options['reset_mask'] must be a bool array of shape ({self.num_envs},), "
                f"got dtype {mask.dtype} shape {mask.shape}"
            )
        obs, infos = self.env.reset_at(torch.as_tensor(mask, device=self.env.device), return_info=True)
        return self._observation(obs), self._info(infos, self._all())

    def step(self, actions: Union[Tuple, list, Dict[str, Any]]) -> Tuple[Any, Any, Any, Any, Dict[str, Any]]:
        """Step every env with ``[num_envs, ...]`` actions per agent (tuple/list, or dict by name)."""
        tensors = common.actions_to_tensors(self.env, actions, batched=True)
        obs, rews, terminated, truncated, infos = self.env.step(tensors)
        done = terminated | truncated
        extra: Dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP and bool(done.any()):
            extra = self._final(obs, infos, done)
            # one batched reset; envs that did not finish keep this step's observation
            reset_obs, reset_infos = self.env.reset_at(done, return_info=True)
            obs = common.merge_where(done, reset_obs, obs)
            infos = common.merge_where(done, reset_infos, infos)
        rewards = self._out(common.by_agent(self.env, rews))
        if self.sum_rewards:
            reward: Any = sum(rewards.values())
        else:
            reward = common.pack(rewards, self.env.dict_spaces)
        info = self._info(infos, self._all())
        info.update(extra)
        return self._observation(obs), reward, self._out(terminated), self._out(truncated), info

    def _final(self, obs, infos, done: torch.Tensor) -> Dict[str, Any]:
        """The finished episodes' last observations and infos, in gymnasium's SAME_STEP layout."""
        mask = done.cpu().numpy()
        final_obs = np.full(self.num_envs, None, dtype=object)
        per_agent = common.by_agent(self.env, obs)
        for i in np.flatnonzero(mask):
            if self.return_numpy:
                row = common.to_numpy(per_agent, index=int(i))
            else:
                row = common.select_env(per_agent, int(i))
            final_obs[i] = common.pack(row, self.env.dict_spaces)
        return {
            "final_obs": final_obs,
            "_final_obs": mask,
            "final_info": self._info(infos, mask),
            "_final_info": mask.copy(),
        }

    def render(self) -> Optional[Tuple[np.ndarray, ...]]:
        """One HxWx3 uint8 frame per env in ``render_env_indices`` (None with ``render_mode=None``)."""
        if self.render_mode is None:
            return None
        return tuple(self.env.render(mode="rgb_array", env_index=i) for i in self.render_env_indices)

    def close_extras(self, **kwargs: Any) -> None:
        self.env.close()
