"""VMAS's module path ``vmas.simulator.environment.gym.gymnasium``: the wrapper lives in vmas_ros/envs/gymnasium_env.py."""
from vmas_ros.envs.gymnasium_env import GymnasiumWrapper

__all__ = ["GymnasiumWrapper"]
