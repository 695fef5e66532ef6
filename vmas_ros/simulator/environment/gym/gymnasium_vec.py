"""VMAS's module path ``vmas.simulator.environment.gym.gymnasium_vec``: the wrapper lives in vmas_ros/envs/gymnasium_vec.py."""
from vmas_ros.envs.gymnasium_vec import GymnasiumVectorizedWrapper

__all__ = ["GymnasiumVectorizedWrapper"]
