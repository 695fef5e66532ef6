"""Train a VMAS scenario with RLlib: see vmas_ros/envs/rllib_env.py (``register``), vmas_ros/envs/rllib_vector.py
(``BatchedMultiAgentEnvRunner``) and vmas_ros/train/.

VMAS keeps an RLlib training script at this path; ours only points at the RLlib
env, so that importing the path needs neither ray nor wandb.
"""
from vmas_ros.simulator.environment.rllib import __getattr__  # noqa: F401 - VectorEnvWrapper, on first use
