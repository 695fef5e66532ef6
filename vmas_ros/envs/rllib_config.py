"""The RLlib env an ``env_config`` dict describes (:func:`from_config`), seeded per runner copy.

Both RLlib envs build from it: :func:`vmas_ros.envs.rllib_env.env_creator`
(one env, what Ray's registry calls) and the batched runner of
:mod:`vmas_ros.envs.rllib_vector`. It goes through ``make_env`` and imports
neither Ray nor either wrapper, so both wrappers can use it.
"""
from __future__ import annotations

from typing import Any, Mapping, Optional

import numpy as np

__all__ = ["SEED_STRIDE", "from_config"]

#: the seed of env copy (worker w, vector index v) is seed + w * SEED_STRIDE + v
SEED_STRIDE = 1000


def from_config(
    config: Optional[Mapping[str, Any]], num_envs: int = 1, batched: bool = False, **overrides: Any
) -> Any:
    """The RLlib env an ``env_config`` describes (see :func:`vmas_ros.envs.rllib_env.env_creator`), with ``num_envs`` envs.

    ``batched=False`` (``num_envs`` must be 1) gives an :class:`~vmas_ros.envs.rllib_env.RLlibMultiAgentEnv`,
    ``batched=True`` a :class:`~vmas_ros.envs.rllib_vector.RLlibVectorMultiAgentEnv`
    of ``num_envs`` envs, also for one. ``overrides`` are further ``make_env``
    arguments that win over the config's.
    """
    from vmas_ros.envs.make_env import make_env, wrapper_name

    options = dict(config or {})
    if "scenario" not in options:
        raise ValueError(f"env_config needs a 'scenario' (a name or a BaseScenario), got keys {sorted(options)}")
    if not batched and num_envs != 1:
        raise ValueError(f"one RLlibMultiAgentEnv holds num_envs=1, got num_envs={num_envs}; pass batched=True")
    scenario = options.pop("scenario")
    scenario_kwargs = dict(options.pop("scenario_kwargs", None) or {})
    wrapper_kwargs = dict(options.pop("wrapper_kwargs", None) or {})
    wrapper = options.pop("wrapper", "rllib")
    if wrapper_name(wrapper) != "rllib":
        raise ValueError(f"env_config['wrapper'] is {wrapper!r}; the RLlib env is always wrapper='rllib'")
    if options.get("num_envs", num_envs) != num_envs:
        raise ValueError(
            f"env_config['num_envs'] is {options['num_envs']!r}, but this RLlib env holds num_envs={num_envs}: "
            f"to batch N envs in one runner, leave it out and use env_runner_cls=BatchedMultiAgentEnvRunner "
            f"with num_envs_per_env_runner=N (vmas_ros.envs.rllib_vector)"
        )
    options.pop("num_envs", None)
    seed = options.pop("seed", None)
    if seed is None:
        # RLlib builds all copies of one runner from the same env_config: a fixed default
        # would make them replay identical episodes
        seed = int(np.random.SeedSequence().generate_state(1)[0])
    else:
        seed = int(seed) + getattr(config, "worker_index", 0) * SEED_STRIDE + getattr(config, "vector_index", 0)
    options.update(overrides)
    return make_env(
        scenario, num_envs=num_envs, wrapper="rllib", seed=seed, wrapper_kwargs={**wrapper_kwargs, "batched": batched},
        **options, **scenario_kwargs,
    )
