"""VMAS's module path ``vmas.simulator.environment.gym.base``: the shared wrapper base, in vmas_ros/envs/wrapper_common.py."""
from vmas_ros.envs.wrapper_common import BaseGymWrapper

__all__ = ["BaseGymWrapper"]
