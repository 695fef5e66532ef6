"""VMAS's module path ``vmas.simulator.environment.environment``: the class lives in vmas_ros/envs/environment.py."""
from vmas_ros.envs.environment import Environment

__all__ = ["Environment"]
