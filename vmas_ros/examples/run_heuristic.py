"""Run a scenario's heuristic policy on a batch of environments and report the mean reward."""
import time
from typing import Type

import torch

from vmas_ros import make_env
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy, RandomPolicy, heuristic_actions
from vmas_ros.simulator.utils import save_video


def run_heuristic(
    scenario_name: str,
    heuristic: Type[BaseHeuristicPolicy] = RandomPolicy,
    n_steps: int = 200,
    n_envs: int = 32,
    env_kwargs: dict = None,
    render: bool = False,
    save_render: bool = False,
    device: str = "cpu",
):
    """Drive every agent with ``heuristic`` for ``n_steps``; returns the mean global reward per step (a float)."""
    if save_render and not render:
        raise ValueError("save_render=True needs render=True: frames come from render()")
    policy = heuristic(continuous_action=True)
    env = make_env(scenario_name, num_envs=n_envs, device=device, continuous_actions=True, wrapper=None,
                   seed=0, **(env_kwargs or {}))
    obs = env.reset()
    frames, total = [], 0.0
    start = time.time()
    for _ in range(n_steps):
        obs, rews, dones, _ = env.step(heuristic_actions(policy, env, obs))
        total += float(torch.stack(rews, dim=1).mean())  # mean over agents, then over envs
        if render:
            frames.append(env.render(mode="rgb_array", agent_index_focus=None, visualize_when_rgb=True))
    print(f"{n_steps} steps of {n_envs} envs of {scenario_name!r} in {time.time() - start:.2f} s, "
          f"mean reward per step {total / n_steps:.4f}")
    if save_render:
        save_video(f"{scenario_name}_heuristic", frames, fps=1 / env.scenario.world.dt)
    return total / n_steps


if __name__ == "__main__":
    from vmas_ros.scenarios.navigation import HeuristicPolicy

    run_heuristic("navigation", heuristic=HeuristicPolicy, n_envs=32, n_steps=200)
