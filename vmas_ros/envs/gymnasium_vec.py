"""``make_env(..., num_envs=N, wrapper="gymnasium_vec")``: the whole batch as a ``gymnasium.vector.VectorEnv``.

The Environment already steps all ``num_envs`` copies in one call, so this
wrapper only converts, as VMAS's vectorized gymnasium wrapper does:
observations are a list in agent order (a dict by name with ``dict_spaces``) of
``[num_envs, ...]`` numpy arrays (tensors with ``return_numpy=False``), rewards
the same container of ``[num_envs]`` arrays (one array with ``sum_rewards=True``),
``terminated``/``truncated`` ``[num_envs]`` bool arrays, and infos by agent name
in gymnasium's vector layout (each key ``k`` with a ``_k`` mask).
``env.unwrapped`` is the Environment.

Autoreset follows gymnasium 1.x's ``AutoresetMode``, chosen by ``autoreset_mode``
and declared in ``metadata["autoreset_mode"]`` (gymnasium's own vector wrappers,
e.g. ``RecordEpisodeStatistics``, read it there). Each mode gives, step by step,
what ``SyncVectorEnv`` of the single-env ``"gymnasium"`` wrapper gives:

- ``NEXT_STEP`` (the default, as in gymnasium): an env that finished is reset
  on the *next* step, which ignores its action and returns its first
  observation with reward 0 and both flags False.
- ``SAME_STEP``: finished envs are reset in the step they finish, which returns
  their first observation of the new episode; the last one of the finished
  episode is in ``info["final_obs"]`` (an object array, None where no episode
  ended, with the ``info["_final_obs"]`` mask), its infos in ``info["final_info"]``.
- ``DISABLED`` (VMAS's behaviour): nothing is reset; reset some envs with
  ``reset(options={"reset_mask": mask})``.

Either autoreset is one batched ``Environment.reset_at(mask)`` call: the
finished envs are stepped with the rest and then reset, so a step stays one
batched physics step.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from vmas_ros.envs import wrapper_common as common
from vmas_ros.envs.environment import Environment
from vmas_ros.envs.gymnasium_env import RENDER_MODES, check_render_mode

__all__ = ["GymnasiumVectorizedWrapper", "GymnasiumVecEnv"]


def _autoreset_mode(value: Union[str, AutoresetMode]) -> AutoresetMode:
    """An ``AutoresetMode`` from a member, its value (``"NextStep"``) or its name (``"next_step"``)."""
    if isinstance(value, AutoresetMode):
        return value
    for mode in AutoresetMode:
        if isinstance(value, str) and value.lower() in (mode.value.lower(), mode.name.lower()):
            return mode
    raise ValueError(
        f"autoreset_mode must be one of {[m.value for m in AutoresetMode]} (or gymnasium.vector.AutoresetMode), "
        f"got {value!r}"
    )


def _zero_where(mask: torch.Tensor, tree: Any) -> Any:
    """``tree`` with the rows of envs in ``mask`` set to zero (dicts and lists of ``[num_envs]`` tensors)."""
    if isinstance(tree, torch.Tensor):
        return torch.where(mask, torch.zeros_like(tree), tree)
    if isinstance(tree, dict):
        return {key: _zero_where(mask, value) for key, value in tree.items()}
    return type(tree)(_zero_where(mask, value) for value in tree)


class GymnasiumVectorizedWrapper(common.BaseGymWrapper, VectorEnv):
    """All ``num_envs`` envs of an :class:`Environment` behind gymnasium's ``VectorEnv`` API.

    Args:
        env: the Environment, made with ``terminated_truncated=True``.
        return_numpy: False keeps torch tensors on ``env.device``, as in VMAS.
        render_mode: ``"rgb_array"`` or None; ``render()`` returns one frame per env
            in ``render_env_indices`` (default: every env).
        sum_rewards: True returns one ``[num_envs]`` reward array, summed over agents.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default), ``SAME_STEP`` or ``DISABLED``
            (or their values or names, e.g. ``"same_step"``).
        render_env_indices: which envs ``render()`` draws.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        env: Environment,
        return_numpy: bool = True,
        render_mode: Optional[str] = "rgb_array",
        sum_rewards: bool = False,
        autoreset_mode: Union[str, AutoresetMode] = AutoresetMode.NEXT_STEP,
        render_env_indices: Optional[Sequence[int]] = None,
    ) -> None:
        common.require_terminated_truncated(env, "gymnasium_vec")
        super().__init__(env, return_numpy=return_numpy, vectorized=True)
        self.num_envs = env.num_envs
        self.autoreset_mode = _autoreset_mode(autoreset_mode)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        self.render_mode = check_render_mode(render_mode)
        self.render_env_indices = list(range(env.num_envs)) if render_env_indices is None else list(render_env_indices)
        self.sum_rewards = sum_rewards
        self.single_observation_space = common.to_gymnasium_space(env.observation_space)
        self.single_action_space = common.to_gymnasium_space(env.action_space)
        self.observation_space = batch_space(self.single_observation_space, n=self.num_envs)
        self.action_space = batch_space(self.single_action_space, n=self.num_envs)
        # [num_envs] bool: envs that finished last step (NEXT_STEP resets them on this one)
        self._pending = torch.zeros(env.num_envs, dtype=torch.bool, device=env.device)

    def _vector_infos(self, infos, mask: np.ndarray) -> Dict[str, Any]:
        return common.vector_info(self._infos(infos), mask)

    def reset(
        self, *, seed: Optional[Union[int, Sequence[int]]] = None, options: Optional[dict] = None
    ) -> Tuple[Union[List, Dict[str, Any]], Dict[str, Any]]:
        """Reset every env, or only ``options["reset_mask"]`` (a ``[num_envs]`` bool array).

        ``seed`` is one int for the whole batch: the Environment has one random
        stream for all its envs. A list of equal seeds is accepted (what
        gymnasium passes when one seed is broadcast), differing seeds are not.
        Infos carry the mask of the envs that were reset.
        """
        if seed is not None and not isinstance(seed, (int, np.integer)):
            seeds = list(seed)
            if any(s != seeds[0] for s in seeds):
                raise ValueError(f"the batch has one random stream: pass one int seed, got {seeds}")
            seed = seeds[0]
        super().reset(seed=seed)
        if seed is not None:
            self._env.seed(int(seed))
        mask = None if options is None else options.get("reset_mask")
        if mask is None:
            self._pending.zero_()
            obs, infos = self._env.reset(return_info=True)
            return self._per_agent(obs), self._vector_infos(infos, np.ones(self.num_envs, dtype=bool))
        mask = np.asarray(mask)
        if mask.shape != (self.num_envs,) or mask.dtype != np.bool_:
            raise ValueError(
                f"options['reset_mask'] must be a bool array of shape ({self.num_envs},), "
                f"got dtype {mask.dtype} shape {mask.shape}"
            )
        reset = torch.as_tensor(mask, device=self._env.device)
        self._pending &= ~reset
        obs, infos = self._env.reset_at(reset, return_info=True)
        return self._per_agent(obs), self._vector_infos(infos, mask.copy())

    def step(self, actions: Union[Tuple, list, Dict[str, Any]]) -> Tuple[Any, Any, Any, Any, Dict[str, Any]]:
        """Step every env with ``[num_envs, ...]`` actions per agent (list/tuple, or dict by name)."""
        tensors = common.actions_to_tensors(self._env, actions, batched=True)
        obs, rews, terminated, truncated, infos = self._env.step(tensors)
        extra: Dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            pending = self._pending
            if bool(pending.any()):
                # these envs finished last step: this step is their reset, their action is ignored
                reset_obs, reset_infos = self._env.reset_at(pending, return_info=True)
                obs = common.merge_where(pending, reset_obs, obs)
                infos = common.merge_where(pending, reset_infos, infos)
                rews = _zero_where(pending, rews)
                terminated, truncated = terminated & ~pending, truncated & ~pending
            self._pending = terminated | truncated
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:
            done = terminated | truncated
            if bool(done.any()):
                extra = self._final(obs, infos, done)
                reset_obs, reset_infos = self._env.reset_at(done, return_info=True)
                obs = common.merge_where(done, reset_obs, obs)
                infos = common.merge_where(done, reset_infos, infos)
        rewards = self._convert(common.by_agent(self._env, rews))
        reward: Any = sum(rewards.values()) if self.sum_rewards else common.pack(rewards, self.dict_spaces)
        info = self._vector_infos(infos, np.ones(self.num_envs, dtype=bool))
        info.update(extra)
        return self._per_agent(obs), reward, self._convert(terminated), self._convert(truncated), info

    def _final(self, obs, infos, done: torch.Tensor) -> Dict[str, Any]:
        """The finished episodes' last observations and infos, in gymnasium's SAME_STEP layout."""
        mask = done.cpu().numpy()
        final_obs = np.full(self.num_envs, None, dtype=object)
        per_agent = common.by_agent(self._env, obs)
        for i in np.flatnonzero(mask):
            if self.return_numpy:
                row = common.to_numpy(per_agent, index=int(i))
            else:
                row = common.select_env(per_agent, int(i))
            final_obs[i] = common.pack(row, self.dict_spaces)
        return {
            "final_obs": final_obs,
            "_final_obs": mask,
            "final_info": self._vector_infos(infos, mask),
            "_final_info": mask.copy(),
        }

    def render(
        self, agent_index_focus: Optional[int] = None, visualize_when_rgb: bool = False, **kwargs: Any
    ) -> Optional[Tuple[np.ndarray, ...]]:
        """One HxWx3 uint8 frame per env in ``render_env_indices`` (None with ``render_mode=None``)."""
        if self.render_mode is None:
            return None
        return tuple(
            self._render_env(self.render_mode, i, agent_index_focus, visualize_when_rgb, **kwargs)
            for i in self.render_env_indices
        )

    def close_extras(self, **kwargs: Any) -> None:
        self._env.close()


#: the name this wrapper had before it took VMAS's
GymnasiumVecEnv = GymnasiumVectorizedWrapper
