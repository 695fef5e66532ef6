"""VMAS's module path ``vmas.simulator.environment.rllib``: ``VectorEnvWrapper``, the batched RLlib env.

It is :class:`vmas_ros.envs.rllib_vector.RLlibVectorMultiAgentEnv`, a
``VectorMultiAgentEnv`` of RLlib's new API stack, trained through
``BatchedMultiAgentEnvRunner``; it also offers VMAS's ``vector_reset``,
``vector_step``, ``reset_at``, ``seed``, ``try_render_at`` and
``get_sub_environments``. Resolved on first use, so importing this path does not need ray.
"""
import importlib

__all__ = ["VectorEnvWrapper"]


def __getattr__(name: str):
    if name in __all__:
        return getattr(importlib.import_module("vmas_ros.envs.rllib_vector"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
