"""``make_env(..., wrapper="rllib")``: the Environment for RLlib's new API stack (ray 2.x).

With ``num_envs=1`` it is one :class:`RLlibMultiAgentEnv`: ``possible_agents``,
``agents``, ``observation_spaces`` and ``action_spaces`` dicts by agent name,
``reset() -> (obs, infos)``, ``step(action_dict) -> (obs, rewards, terminateds,
truncateds, infos)`` with the ``"__all__"`` key in ``terminateds`` and
``truncateds``. RLlib's default ``MultiAgentEnvRunner`` builds
``num_envs_per_env_runner`` such copies and steps them one after another.

With ``num_envs > 1`` it is the batched
:class:`~vmas_ros.envs.rllib_vector.RLlibVectorMultiAgentEnv`, which steps
all envs in one call; RLlib runs it through
:class:`~vmas_ros.envs.rllib_vector.BatchedMultiAgentEnvRunner`.

``register(name)`` makes the env known to Ray's tune registry so a config can say
``.environment("vmas_ros", env_config={"scenario": "simple_spread", ...})``.
"""
from __future__ import annotations

from typing import Any, Dict, Mapping, Optional, Tuple

from ray.rllib.env.multi_agent_env import MultiAgentEnv

from vmas_ros.envs import wrapper_common as common
from vmas_ros.envs.environment import Environment
from vmas_ros.envs.gymnasium_env import RENDER_MODES, check_render_mode
from vmas_ros.envs.rllib_config import SEED_STRIDE, from_config  # noqa: F401 - re-exported

__all__ = ["RLlibMultiAgentEnv", "env_creator", "from_config", "register", "wrap"]

class RLlibMultiAgentEnv(common.SingleEnvWrapper, MultiAgentEnv):
    """A single-env :class:`Environment` (``num_envs=1``) behind RLlib's ``MultiAgentEnv``.

    All agents act every step and the episode ends for all of them together, so
    ``terminateds["__all__"]`` is the Environment's terminated flag and
    ``truncateds["__all__"]`` its truncated flag (``max_steps``).

    Args:
        env: the Environment, made with ``num_envs=1`` and ``terminated_truncated=True``.
        render_mode: ``"rgb_array"`` (``render()`` returns an HxWx3 uint8 array) or None.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30}

    def __init__(self, env: Environment, render_mode: Optional[str] = "rgb_array") -> None:
        common.require_single_env(
            env, "rllib", "; vmas_ros.envs.rllib_vector.RLlibVectorMultiAgentEnv takes a batch"
        )
        common.require_terminated_truncated(env, "rllib")
        super().__init__()
        self.env = env
        self.render_mode = check_render_mode(render_mode)
        self.possible_agents = common.agent_names(env)
        self.agents = list(self.possible_agents)
        self.observation_spaces, self.action_spaces = common.agent_spaces(env)

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[dict] = None
    ) -> Tuple[Dict[str, Any], Dict[str, Any]]:
        """Start a new episode; ``seed`` re-seeds the Environment's own streams."""
        self.agents = list(self.possible_agents)
        return self._reset_env(seed)

    def step(self, action_dict: Mapping[str, Any]) -> Tuple[Dict[str, Any], ...]:
        """Apply one action per agent (a dict by name; every agent acts every step)."""
        tensors = common.actions_to_tensors(self.env, action_dict, batched=False, names=self.possible_agents)
        obs, rews, terminated, truncated, infos = self.env.step(tensors)
        term, trunc = bool(terminated[0]), bool(truncated[0])
        names = self.possible_agents
        observations = common.to_numpy(common.by_agent(self.env, obs), index=0)
        rewards = {name: float(r[0]) for name, r in common.by_agent(self.env, rews).items()}
        terminateds: Dict[str, bool] = {**{n: term for n in names}, "__all__": term}
        truncateds: Dict[str, bool] = {**{n: trunc for n in names}, "__all__": trunc}
        if term or trunc:
            self.agents = []
        info = common.to_numpy(common.by_agent(self.env, infos), index=0)
        return observations, rewards, terminateds, truncateds, info


def wrap(env: Environment, render_mode: Optional[str] = "rgb_array", batched: Optional[bool] = None) -> Any:
    """What ``make_env(wrapper="rllib")`` returns: an :class:`RLlibMultiAgentEnv` or the batched env.

    ``batched=None`` picks by ``env.num_envs``: the single env for one, the
    batched :class:`~vmas_ros.envs.rllib_vector.RLlibVectorMultiAgentEnv` for
    more; True gives the batched env also for one.
    """
    if not (env.num_envs > 1 if batched is None else batched):
        return RLlibMultiAgentEnv(env, render_mode=render_mode)
    from vmas_ros.envs.rllib_vector import RLlibVectorMultiAgentEnv

    vector = RLlibVectorMultiAgentEnv(env)
    vector.render_mode = check_render_mode(render_mode)
    return vector


def env_creator(config: Optional[Mapping[str, Any]] = None) -> RLlibMultiAgentEnv:
    """Build the RLlib env from an ``env_config`` dict (what Ray's registry calls).

    ``config["scenario"]`` is the scenario name (required); ``scenario_kwargs`` (a
    dict) and every other key go to :func:`vmas_ros.make_env` (``max_steps``,
    ``continuous_actions``, ``device``, ``seed``, ``n_agents``...). RLlib passes an
    ``EnvContext``: with a ``seed`` in the config, the copy on runner ``worker_index``
    gets ``seed + worker_index * 1000 (+ vector_index)``, so runners do not replay
    each other. RLlib builds the ``num_envs_per_env_runner`` copies of one runner from
    the same context; they start apart only when the algorithm config has
    ``.debugging(seed=...)`` (RLlib then resets copy ``i`` with ``seed + i``). Without
    a ``seed`` in env_config each copy draws a fresh one from the OS.
    """
    return from_config(config)


def register(name: str = "vmas_ros") -> str:
    """Register :func:`env_creator` with Ray's tune registry under ``name`` and return it."""
    from ray.tune.registry import register_env

    register_env(name, env_creator)
    return name
