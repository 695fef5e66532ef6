"""What the Environment API tests share: the two shipped scenarios they run on and small helpers."""
from __future__ import annotations

import torch

import vmas_ros

SCENARIOS = ["simple_spread", "waterfall"]
# observation size per agent: pos, vel, then relative positions (see the scenario docstrings)
OBS_SIZE = {"simple_spread": 4 + 2 * 3 + 2 * 2, "waterfall": 4 + 2 * 12}
N_AGENTS = {"simple_spread": 3, "waterfall": 5}
N_ENVS = 4


def make(name, **kwargs):
    kwargs.setdefault("num_envs", N_ENVS)
    kwargs.setdefault("seed", 0)
    return vmas_ros.make_env(name, device="cpu", **kwargs)


def positions(env):
    return torch.stack([e.state.pos for e in env.world.entities], dim=1).clone()


def zero_actions(env):
    return [torch.zeros(env.num_envs, env.get_agent_action_size(a)) for a in env.agents]
