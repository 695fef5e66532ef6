"""Environments: the vectorized Environment, make_env, and wrappers for RL libraries.

The wrappers (``gymnasium_env``, ``gymnasium_vec``, ``pettingzoo_env``,
``rllib_env``, ``rllib_vector``, ``torchrl_env``) are not imported here: ``make_env(wrapper=...)``
imports the one asked for, so ``import vmas_ros`` never loads ray, pettingzoo or torchrl.
"""
from vmas_ros.envs.environment import Environment
from vmas_ros.envs.make_env import WRAPPERS, make_env, wrap

__all__ = ["Environment", "WRAPPERS", "make_env", "wrap"]
