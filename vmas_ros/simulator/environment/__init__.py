"""VMAS-compatible module path for the environment (``vmas.simulator.environment``)."""
from enum import Enum

from vmas_ros.envs.environment import Environment


class Wrapper(Enum):
    """Library wrappers ``make_env(wrapper=...)`` knows by name."""

    GYM = "gym"
    GYMNASIUM = "gymnasium"
    GYMNASIUM_VEC = "gymnasium_vec"
    PETTINGZOO = "pettingzoo"
    TORCHRL = "torchrl"
    RLLIB = "rllib"


__all__ = ["Environment", "Wrapper"]
