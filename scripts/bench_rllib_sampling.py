"""Env steps/s of RLlib sampling on simple_spread: RLlib's default runner (N copies of a num_envs=1 env)
against BatchedMultiAgentEnvRunner (one Environment with num_envs=N), median of --repeats samples.

Run it once per runner: `python scripts/bench_rllib_sampling.py --runner default` and `--runner batched`
(see docs/bench/distributed.md). Ray starts on this machine only, with usage reports off.
"""
import argparse
import os
import statistics
import time

os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

import ray
from ray.rllib.algorithms.ppo import PPOConfig

from vmas_ros.envs import rllib_env
from vmas_ros.envs.rllib_vector import BatchedMultiAgentEnvRunner

parser = argparse.ArgumentParser()
parser.add_argument("--runner", choices=["default", "batched"], required=True)
parser.add_argument("--num-envs", type=int, default=64)
parser.add_argument("--timesteps", type=int, default=6400)
parser.add_argument("--repeats", type=int, default=3)
args = parser.parse_args()

ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
try:
    runners = dict(num_env_runners=0, num_envs_per_env_runner=args.num_envs)
    if args.runner == "batched":
        runners["env_runner_cls"] = BatchedMultiAgentEnvRunner
    config = (
        PPOConfig()
        .environment(rllib_env.register("vmas_ros"), env_config={"scenario": "simple_spread", "max_steps": 25, "seed": 0})
        .env_runners(**runners)
        .learners(num_learners=0)
        .debugging(seed=0)
        .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, episode, **kw: "shared")
    )
    algo = config.build_algo()
    runner = algo.env_runner
    runner.sample(num_timesteps=4 * args.num_envs, explore=True)  # warm-up: first steps compile, if compiling
    rates = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        episodes = runner.sample(num_timesteps=args.timesteps, explore=True)
        elapsed = time.perf_counter() - start
        steps = sum(len(e) for e in episodes)
        rates.append(steps / elapsed)
    print(f"runner={args.runner} num_envs={args.num_envs} VMAS_ROS_COMPILE={os.environ.get('VMAS_ROS_COMPILE', 'auto')} "
          f"env_steps_per_s median={statistics.median(rates):.0f} all={[round(r) for r in rates]}")
    algo.stop()
finally:
    ray.shutdown()
