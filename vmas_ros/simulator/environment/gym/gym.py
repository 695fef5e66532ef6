"""VMAS's module path ``vmas.simulator.environment.gym.gym``: the legacy ``gym`` wrapper, in vmas_ros/envs/gym_env.py.

Importing this module needs the optional ``gym`` extra (``pip install "vmas_ros[gym]"``).
"""
from vmas_ros.envs.gym_env import GymWrapper

__all__ = ["GymWrapper"]
