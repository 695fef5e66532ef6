"""The envs behind gymnasium's ids: ``gymnasium.make("vmas_ros/<scenario>-v0")`` and ``gymnasium.make_vec(...)``.

The ids are registered by :mod:`vmas_ros.compat.gymnasium_ids`; these are their entry points.

Two conventions meet here, and both hold (docs/python_api.md):

* ``make_env(..., wrapper="gymnasium")`` and ``"gymnasium_vec"`` follow VMAS:
  ``env.unwrapped`` is the vmas_ros ``Environment`` (VMAS code reads
  ``env.unwrapped.agents``), rewards are one float per agent.
* The registered ids follow gymnasium: the env is gymnasium-native, so
  ``env.unwrapped`` is the gymnasium env itself and gymnasium's
  ``check_env(env.unwrapped)`` applies; the agents' rewards come summed into
  one float (``sum_rewards=False`` gives them per agent); no rendering unless
  ``render_mode="rgb_array"`` is asked for. ``env.env`` is the Environment.

Keyword arguments go to ``make_env`` (``max_steps``, ``seed``, ``device``,
``continuous_actions``, the scenario's own), or to the wrapper
(``sum_rewards``, ``return_numpy``, ``render_mode``, and ``autoreset_mode``
for the vector env). ``max_episode_steps`` of ``make_vec`` is ``max_steps``.

Where a scenario follows VMAS in a way gymnasium's conventions rule out, its
id takes gymnasium's side unless told otherwise (:data:`GYMNASIUM_SIDE`):
road_traffic's steering history is cleared on reset, so that a seeded reset
repeats its episode, as gymnasium's checker requires.
"""
from __future__ import annotations

from typing import Any, Optional

from vmas_ros.compat.gymnasium_ids import NAMESPACE, VERSION, env_id, register_envs
from vmas_ros.envs.gymnasium_env import GymnasiumWrapper
from vmas_ros.envs.gymnasium_vec import GymnasiumVectorizedWrapper

__all__ = ["GYMNASIUM_SIDE", "NAMESPACE", "VERSION", "GymnasiumNativeEnv", "GymnasiumNativeVectorEnv", "env_id", "make_single",
           "make_vector", "register_envs"]


def _as_tuple(values: Any) -> Any:
    """Per-agent values as gymnasium's ``Tuple`` space holds them: a tuple (VMAS hands out a list)."""
    return tuple(values) if isinstance(values, list) else values


class GymnasiumNativeEnv(GymnasiumWrapper):
    """One env, gymnasium's way: ``unwrapped`` is this env (gymnasium's checker reads it), and per-agent
    observations are tuples, as its ``Tuple`` space holds them."""

    @property
    def unwrapped(self) -> "GymnasiumNativeEnv":
        return self

    def _per_agent(self, values: Any) -> Any:
        return _as_tuple(super()._per_agent(values))


class GymnasiumNativeVectorEnv(GymnasiumVectorizedWrapper):
    """The batch as gymnasium's ``VectorEnv``: ``unwrapped`` is this env; per-agent values are tuples."""

    @property
    def unwrapped(self) -> "GymnasiumNativeVectorEnv":
        return self

    def _per_agent(self, values: Any) -> Any:
        return _as_tuple(super()._per_agent(values))


#: scenario -> kwargs its id passes to ``make_env`` unless the caller gives them: gymnasium's side where VMAS's
#: behaviour breaks one of gymnasium's conventions (``make_env`` itself keeps VMAS's)
GYMNASIUM_SIDE = {"road_traffic": {"reset_steering_history": True}}


def _gymnasium_side(scenario: Any, kwargs: dict) -> dict:
    return {**GYMNASIUM_SIDE.get(scenario, {}), **kwargs} if isinstance(scenario, str) else kwargs


def make_single(scenario: str, render_mode: Optional[str] = None, sum_rewards: bool = True,
                return_numpy: bool = True, **kwargs: Any) -> GymnasiumNativeEnv:
    """The entry point of ``vmas_ros/<scenario>-v0``: one env."""
    from vmas_ros.envs.make_env import make_env

    env = make_env(scenario, num_envs=1, terminated_truncated=True, **_gymnasium_side(scenario, kwargs))
    return GymnasiumNativeEnv(env, return_numpy=return_numpy, render_mode=render_mode, sum_rewards=sum_rewards)


def make_vector(scenario: str, num_envs: int = 1, render_mode: Optional[str] = None, sum_rewards: bool = True,
                return_numpy: bool = True, autoreset_mode: Any = "next_step", max_episode_steps: Optional[int] = None,
                **kwargs: Any) -> GymnasiumNativeVectorEnv:
    """The vector entry point of ``vmas_ros/<scenario>-v0``: ``num_envs`` envs in one batch."""
    from vmas_ros.envs.make_env import make_env

    if max_episode_steps is not None:
        if kwargs.get("max_steps") not in (None, max_episode_steps):
            raise ValueError(f"max_episode_steps={max_episode_steps} and max_steps={kwargs['max_steps']} differ; "
                             f"give one of them")
        kwargs["max_steps"] = max_episode_steps
    env = make_env(scenario, num_envs=num_envs, terminated_truncated=True, **_gymnasium_side(scenario, kwargs))
    return GymnasiumNativeVectorEnv(env, return_numpy=return_numpy, render_mode=render_mode, sum_rewards=sum_rewards,
                                    autoreset_mode=autoreset_mode)
