"""Environments: the vectorized Environment, make_env, and wrappers for RL libraries."""
from vmas_ros.envs.environment import Environment
from vmas_ros.envs.make_env import make_env

__all__ = ["Environment", "make_env"]
