"""The whole batch of an :class:`Environment` as one RLlib ``VectorMultiAgentEnv`` (ray 2.x new API stack).

RLlib's ``MultiAgentEnvRunner`` builds its vector env itself: ``make_vec`` wraps
``num_envs_per_env_runner`` copies of the registered env in a
``SyncVectorMultiAgentEnv``, the only vectorization RLlib implements for a
``MultiAgentEnv``, which resets and steps the copies one after another. Given
copies of the single-env ``"rllib"`` wrapper, that is N Environments of one env
each, so the batched physics step never sees more than one env.

:class:`RLlibVectorMultiAgentEnv` holds one Environment with ``num_envs=N`` and
keeps ``SyncVectorMultiAgentEnv``'s contract: ``step`` takes RLlib's list of N
action dicts, stacks them into one ``[N, size]`` array per agent, steps the
Environment once and splits the results into N dicts of numpy values;
``envs`` are N light views of the sub-envs (agents and spaces; they cannot
step alone). Autoreset is ``"next_step"``: a sub-env that ended on one step
is reset by the next, which ignores its action and returns its first
observation with zero rewards and False flags (``"__all__"`` too). The reset
is one batched ``Environment.reset_at(mask)``.

RLlib does not let a config pick a vector env class, so
:class:`BatchedMultiAgentEnvRunner` overrides ``make_env`` to build this one
from the ``env_config`` the single env reads (see
``vmas_ros.envs.rllib_env.env_creator``)::

    config.env_runners(env_runner_cls=BatchedMultiAgentEnvRunner, num_envs_per_env_runner=64)

VMAS 1.5's ``VectorEnvWrapper`` (``vmas.simulator.environment.rllib``) was a
``VectorEnv`` of RLlib's old API stack; that name is this class, which also
offers its methods (``vector_reset``, ``vector_step``, ``reset_at``, ``seed``,
``try_render_at``, ``get_sub_environments``) with VMAS's return values, for
code that calls them directly.
"""
from __future__ import annotations

from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import torch
from gymnasium import spaces
from ray.rllib.callbacks.utils import make_callback
from ray.rllib.env.env_context import EnvContext
from ray.rllib.env.multi_agent_env import MultiAgentEnv
from ray.rllib.env.multi_agent_env_runner import MultiAgentEnvRunner
from ray.rllib.env.vector.vector_multi_agent_env import VectorMultiAgentEnv
from ray.rllib.utils.annotations import override
from ray.rllib.utils.pre_checks.env import check_multiagent_environments

from vmas_ros.envs import wrapper_common as common
from vmas_ros.envs.environment import Environment
from vmas_ros.envs.gymnasium_env import RENDER_MODES
from vmas_ros.envs.rllib_config import from_config

__all__ = ["BatchedMultiAgentEnvRunner", "RLlibVectorMultiAgentEnv", "VectorEnvWrapper"]


def _unbatch(tree: Any, n: int) -> List[Any]:
    """A nest (dicts, lists) of ``[n, ...]`` numpy arrays -> ``n`` nests of rows (views, not copies)."""
    if isinstance(tree, np.ndarray) and tree.ndim > 0:
        return list(tree)
    if isinstance(tree, Mapping):
        if not tree:
            return [{} for _ in range(n)]
        keys = list(tree)
        columns = [_unbatch(tree[key], n) for key in keys]
        return [dict(zip(keys, row)) for row in zip(*columns)]
    if isinstance(tree, (list, tuple)):
        columns = [_unbatch(item, n) for item in tree]
        return [type(tree)(row) for row in zip(*columns)] if columns else [type(tree)() for _ in range(n)]
    return [tree] * n  # a value shared by every env


def _one_seed(seed: Union[None, int, Sequence[int]]) -> Optional[int]:
    """The batch has one random stream: one int seed (or equal ones, one per env)."""
    if seed is None or isinstance(seed, (int, np.integer)):
        return None if seed is None else int(seed)
    seeds = list(seed)
    if not seeds or any(s != seeds[0] for s in seeds):
        raise ValueError(f"the batch has one random stream: pass one int seed, got {seeds}")
    return int(seeds[0])


class _SubEnv(MultiAgentEnv):
    """Env ``index`` of a batched :class:`RLlibVectorMultiAgentEnv`, as RLlib's runner reads it.

    Agents and spaces are the batch's; ``agents`` is empty while the env waits
    for its autoreset. It steps and resets only with the whole batch, so its
    own ``reset`` and ``step`` raise.
    """

    def __init__(self, vector: "RLlibVectorMultiAgentEnv", index: int) -> None:
        self.vector = vector
        self.index = index
        self.possible_agents = vector.possible_agents
        self.observation_spaces = vector.single_observation_spaces
        self.action_spaces = vector.single_action_spaces
        self.metadata = vector.metadata
        super().__init__()

    @property
    def agents(self) -> List[str]:
        return [] if self.vector.finished[self.index] else list(self.possible_agents)

    @property
    def env(self) -> Environment:
        """The batch's Environment (shared by every view)."""
        return self.vector.env

    @property
    def render_mode(self) -> Optional[str]:
        return self.vector.render_mode

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        raise RuntimeError(f"env {self.index} of a batched RLlibVectorMultiAgentEnv resets with the whole "
                           f"batch: call reset() on the vector env")

    def step(self, action_dict):
        raise RuntimeError(f"env {self.index} of a batched RLlibVectorMultiAgentEnv steps with the whole "
                           f"batch: call step() on the vector env with one action dict per env")

    def render(self) -> Optional[np.ndarray]:
        """This env's frame as an HxWx3 uint8 array (None when the batch has ``render_mode=None``)."""
        if self.render_mode is None:
            return None
        return self.vector.env.render(mode="rgb_array", env_index=self.index)


class RLlibVectorMultiAgentEnv(VectorMultiAgentEnv):
    """All ``num_envs`` envs of an :class:`Environment` behind RLlib's ``VectorMultiAgentEnv``.

    ``reset`` and ``step`` return lists with one dict by agent name per env, as
    ``SyncVectorMultiAgentEnv`` does: observations and infos as numpy, rewards
    as floats, ``terminateds``/``truncateds`` with ``"__all__"``.
    ``render_mode`` (an attribute: ``"rgb_array"`` or None) decides whether
    ``render()`` draws a frame per env.

    Args:
        env: the Environment, made with ``terminated_truncated=True``
            (``make_env(..., wrapper="rllib")`` sets it).
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30, "autoreset_mode": "next_step"}
    render_mode: Optional[str] = "rgb_array"

    def __init__(self, env: Environment) -> None:
        common.require_terminated_truncated(env, "rllib")
        self._env = env
        self.num_envs = env.num_envs
        self.metadata = dict(type(self).metadata)
        self.possible_agents = common.agent_names(env)
        self.single_observation_spaces, self.single_action_spaces = common.agent_spaces(env)
        self.single_observation_space = spaces.Dict(self.single_observation_spaces)
        self.single_action_space = spaces.Dict(self.single_action_spaces)
        #: [num_envs] bool: the envs whose episode ended on the last step (the next step resets them)
        self.finished = np.zeros(env.num_envs, dtype=bool)
        # the action a waiting env gets when RLlib sends none: zeros are inside every space the Environment builds
        self._idle = {name: np.zeros(space.shape, dtype=space.dtype)
                      for name, space in self.single_action_spaces.items()}
        self.envs = [_SubEnv(self, i) for i in range(env.num_envs)]

    @property
    def env(self) -> Environment:
        """The wrapped Environment (one for the whole batch)."""
        return self._env

    # ------------------------------------------------------------- RLlib's API
    def reset(
        self, *, seed: Union[None, int, Sequence[int]] = None, options: Optional[dict] = None
    ) -> Tuple[List[Dict[str, Any]], List[Dict[str, Any]]]:
        """Reset every env: per env, observations and infos by agent name.

        ``seed`` re-seeds the Environment's one random stream for the whole batch
        (``SyncVectorMultiAgentEnv`` would seed copy ``i`` with ``seed + i``);
        a list of equal seeds is taken too. ``options`` are not used.
        """
        seed = _one_seed(seed)
        super().reset(seed=seed)
        if seed is not None:
            self._env.seed(seed)
        obs, infos = self._env.reset(return_info=True)
        self.finished[:] = False
        return self._per_env(obs), self._per_env(infos)

    def step(self, actions: Sequence[Mapping[str, Any]]) -> Tuple[List[Dict[str, Any]], ...]:
        """Step every env once with ``actions``, one dict by agent name per env.

        An env whose episode ended on the last step is reset instead (its
        action may be an empty dict and is ignored): its observations and
        infos are those of the new episode, its rewards 0.0, its flags False.
        """
        waiting = self.finished
        obs, rews, terminated, truncated, infos = self._env.step(self._batch_actions(actions, waiting))
        if waiting.any():
            mask = torch.as_tensor(waiting, device=self._env.device)
            reset_obs, reset_infos = self._env.reset_at(mask, return_info=True)
            obs = common.merge_where(mask, reset_obs, obs)
            infos = common.merge_where(mask, reset_infos, infos)
        term = terminated.cpu().numpy() & ~waiting
        trunc = truncated.cpu().numpy() & ~waiting
        self.finished = term | trunc
        per_agent = common.to_numpy(common.by_agent(self._env, rews)).values()  # [num_envs] each
        rewards = [np.where(waiting, 0.0, r).tolist() for r in per_agent]
        per_env_rewards = [dict(zip(self.possible_agents, row)) for row in zip(*rewards)]
        return self._per_env(obs), per_env_rewards, self._flags(term), self._flags(trunc), self._per_env(infos)

    def render(self) -> Optional[Tuple[np.ndarray, ...]]:
        """One HxWx3 uint8 frame per env (None with ``render_mode=None``)."""
        if self.render_mode is None:
            return None
        return tuple(self._env.render(mode="rgb_array", env_index=i) for i in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        if getattr(self, "_env", None) is not None:
            self._env.close()

    # ------------------------------------------------ VMAS's VectorEnvWrapper
    def vector_reset(self) -> List[Any]:
        """VMAS's reset of every env: per env, the observations in agent order (a dict with ``dict_spaces``)."""
        obs = self._env.reset()
        self.finished[:] = False
        return [common.pack(row, self._env.dict_spaces) for row in self._per_env(obs)]

    def reset_at(self, index: Optional[int] = None) -> Any:
        """VMAS's reset of env ``index`` alone; returns its observations as :meth:`vector_reset` does."""
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise ValueError(f"reset_at needs one env index (an int in [0, {self.num_envs})), got {index!r}")
        obs = self._env.reset_at(int(index))
        self.finished[index] = False
        return common.pack(common.to_numpy(common.by_agent(self._env, obs), index=int(index)), self._env.dict_spaces)

    def vector_step(self, actions: Sequence[Union[Sequence, Mapping[str, Any]]]) -> Tuple[List, List, List, List]:
        """VMAS's step: per env, actions in agent order (or a dict by name); no env is reset.

        Returns, per env, the observations (as :meth:`vector_reset`), the mean
        reward over agents, the done flag (terminated or truncated) and infos
        by agent name plus ``"rewards"``: each agent's reward by agent index.
        As in VMAS, the caller resets finished envs (:meth:`reset_at`, :meth:`vector_reset`).
        """
        rows = [self._named_actions(i, row) for i, row in enumerate(self._check_length(actions))]
        obs, rews, terminated, truncated, infos = self._env.step(self._batch_actions(rows, None))
        self.finished[:] = False
        rewards = torch.stack(list(common.by_agent(self._env, rews).values())).float()  # [n_agents, num_envs]
        per_agent = rewards.T.tolist()
        infos = [{"rewards": dict(enumerate(r)), **info} for r, info in zip(per_agent, self._per_env(infos))]
        return ([common.pack(row, self._env.dict_spaces) for row in self._per_env(obs)],
                rewards.mean(0).tolist(), (terminated | truncated).tolist(), infos)

    def seed(self, seed: Optional[int] = None) -> List[int]:
        """Re-seed the Environment's random stream (all envs share it)."""
        return self._env.seed(seed)

    def try_render_at(self, index: Optional[int] = None, mode="human", agent_index_focus: Optional[int] = None,
                      visualize_when_rgb: bool = False, **kwargs: Any) -> Optional[np.ndarray]:
        """Env ``index``'s frame (env 0 when None), drawn headless: ``Environment.render``'s keywords."""
        return self._env.render(mode=mode, env_index=0 if index is None else index,
                                agent_index_focus=agent_index_focus, visualize_when_rgb=visualize_when_rgb, **kwargs)

    def get_sub_environments(self) -> List[Environment]:
        """``[env]``: VMAS's answer, the one Environment that holds every env (``envs`` has the views)."""
        return [self._env]

    # --------------------------------------------------------------- helpers
    def _per_env(self, values: Any) -> List[Dict[str, Any]]:
        """Per-agent batched tensors (a list or dict by name) -> per env, a dict by agent name of numpy rows."""
        return _unbatch(common.to_numpy(common.by_agent(self._env, values)), self.num_envs)

    def _flags(self, flags: np.ndarray) -> List[Dict[str, bool]]:
        """``[num_envs]`` bools -> per env, the flag for every agent and ``"__all__"``."""
        return [{**dict.fromkeys(self.possible_agents, flag), "__all__": flag} for flag in flags.tolist()]

    def _check_length(self, actions: Any) -> Sequence:
        if not isinstance(actions, (list, tuple)):
            raise ValueError(f"actions must be a list with one entry per env ({self.num_envs}), "
                             f"got {type(actions).__name__}")
        if len(actions) != self.num_envs:
            raise ValueError(f"actions must be a list with one entry per env: expected {self.num_envs}, "
                             f"got {len(actions)}")
        return actions

    def _named_actions(self, index: int, row: Any) -> Any:
        """One env's actions in agent order -> a dict by name (a dict, or anything else, passes through)."""
        if isinstance(row, (list, tuple)):
            if len(row) != len(self.possible_agents):
                raise ValueError(f"actions[{index}] must hold one action per agent {self.possible_agents}, "
                                 f"got {len(row)}")
            return dict(zip(self.possible_agents, row))
        return row

    def _batch_actions(self, actions: Any, waiting: Optional[np.ndarray]) -> List[torch.Tensor]:
        """RLlib's per-env action dicts -> one ``[num_envs, size]`` tensor per agent on the env's device.

        Envs in ``waiting`` may send an empty dict (they are reset, not
        stepped); a bad entry raises a ValueError naming the env, the agent and
        what was expected.
        """
        rows = list(self._check_length(actions))
        if waiting is not None:
            for i in np.flatnonzero(waiting):
                if isinstance(rows[i], Mapping) and not rows[i]:
                    rows[i] = self._idle
        names = self.possible_agents
        try:
            if any(len(row) != len(names) for row in rows):
                raise KeyError("agents")
            batch = {name: np.stack([row[name] for row in rows]) for name in names}
            return common.actions_to_tensors(self._env, batch, batched=True, names=names)
        except (KeyError, TypeError, ValueError):
            self._explain(rows)  # names the culprit when it can
            raise

    def _explain(self, rows: Sequence[Any]) -> None:
        """Raise a ValueError naming the first bad action dict, agent or shape (return if none is found)."""
        names = self.possible_agents
        for i, row in enumerate(rows):
            if not isinstance(row, Mapping):
                raise ValueError(f"actions[{i}] must be a dict by agent name, got {type(row).__name__}: {row!r}")
            missing = [name for name in names if name not in row]
            unknown = [key for key in row if key not in names]
            if missing or unknown:
                raise ValueError(f"actions[{i}] must have exactly the agents {names}; "
                                 f"missing {missing}, unknown {unknown}")
            for name in names:
                space = self.single_action_spaces[name]
                accepted = [space.shape] + ([(1,)] if isinstance(space, spaces.Discrete) else [])
                shape = np.shape(row[name])
                if shape not in accepted:
                    raise ValueError(f"actions[{i}][{name!r}] has shape {shape}, expected {space.shape} "
                                     f"(action space {space})")


#: VMAS's name (``vmas.simulator.environment.rllib.VectorEnvWrapper``) for the batched env
VectorEnvWrapper = RLlibVectorMultiAgentEnv


class BatchedMultiAgentEnvRunner(MultiAgentEnvRunner):
    """RLlib's ``MultiAgentEnvRunner`` over one batched Environment of ``num_envs_per_env_runner`` envs.

    Everything but ``make_env`` is RLlib's: it builds an
    :class:`RLlibVectorMultiAgentEnv` from the algorithm's ``env_config``, read
    as ``vmas_ros.envs.rllib_env.env_creator`` reads it (``scenario``,
    ``scenario_kwargs``, ``seed`` offset by the runner's index, ``max_steps``,
    ``device``...). Unless env checking is disabled, RLlib's
    ``check_multiagent_environments`` runs on one single-env
    ``RLlibMultiAgentEnv`` built from the same config (eagerly: the check
    is of the API), since the batch's views cannot step alone.
    """

    @override(MultiAgentEnvRunner)
    def make_env(self) -> None:
        if self.env is not None:
            self.env.close()
            self.env = None
        context = self.config.env_config
        if not isinstance(context, EnvContext):
            context = EnvContext(context, worker_index=self.worker_index or 0,
                                 num_workers=self.config.num_env_runners, remote=self.config.remote_worker_envs)
        if not self.config.disable_env_checking:
            probe = from_config(context, compile_physics=False)
            try:
                check_multiagent_environments(probe)
            finally:
                probe.close()
        self.env = from_config(context, num_envs=self.config.num_envs_per_env_runner, batched=True)
        self.num_envs = self.env.num_envs
        self._needs_initial_reset = True
        make_callback(
            "on_environment_created",
            callbacks_objects=self._callbacks,
            callbacks_functions=self.config.callbacks_on_environment_created,
            kwargs=dict(env_runner=self, metrics_logger=self.metrics, env=self.env.unwrapped, env_context=context),
        )
