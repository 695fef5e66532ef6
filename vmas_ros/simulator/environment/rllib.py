"""VMAS's module path ``vmas.simulator.environment.rllib``: RLlib's batched wrapper, in vmas_ros/envs/rllib_env.py.

Resolved on first use, so importing this path does not need ray.
"""
import importlib

__all__ = ["VectorEnvWrapper"]


def __getattr__(name: str):
    if name in __all__:
        return getattr(importlib.import_module("vmas_ros.envs.rllib_env"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
