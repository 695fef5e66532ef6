"""``Environment.step`` with every agent's action stacked in one tensor, against VMAS's list form.

The stacked form must give the same episode as the list (same seed, same
actions), its results stacked the same way (observations ``[A, B, D]``,
rewards ``[A, B]``, infos one dict of ``[A, B, ...]``), and refuse what the
list refuses, with messages that say what was expected.
"""
from __future__ import annotations

import re

import pytest
import torch

import vmas_ros


def _episode(env, actions, stacked: bool):
    out = []
    for step in actions:
        obs, rews, dones, infos = env.step(torch.stack(step) if stacked else step)
        if stacked:
            assert isinstance(obs, torch.Tensor) and obs.shape[:2] == (env.n_agents, env.num_envs)
            assert rews.shape == (env.n_agents, env.num_envs) and isinstance(infos, dict)
            infos = {key: value.clone() for key, value in infos.items()}
            out.append((obs.clone(), rews.clone(), dones.clone(), infos))
        else:
            infos = {key: torch.stack([info[key] for info in infos]) for key in infos[0]}
            out.append((torch.stack([o.clone() for o in obs]), torch.stack(rews).clone(), dones.clone(), infos))
    return out


@pytest.mark.parametrize("scenario, kwargs, continuous", [
    ("simple_spread", {}, True),
    ("simple_spread", {}, False),
    ("navigation", {"n_agents": 12}, True),
])
def test_stacked_actions_give_the_episode_of_the_list(device, scenario, kwargs, continuous):
    envs = [vmas_ros.make_env(scenario, num_envs=4, device=device, seed=3, continuous_actions=continuous, **kwargs)
            for _ in range(2)]
    env = envs[0]
    generator = torch.Generator().manual_seed(0)
    if continuous:
        sizes = [env.get_agent_action_size(a) for a in env.agents]
        actions = [[(torch.rand(4, size, generator=generator) * 2 - 1).to(device) for size in sizes]
                   for _ in range(8)]
    else:
        n = env.get_agent_action_space(env.agents[0]).n
        actions = [[torch.randint(0, n, (4, 1), generator=generator).to(device) for _ in env.agents]
                   for _ in range(8)]
    listed, stacked = _episode(envs[0], actions, False), _episode(envs[1], actions, True)
    for a, b in zip(listed, stacked):
        for x, y in zip(a[:3], b[:3]):
            assert torch.equal(x, y)
        assert a[3].keys() == b[3].keys() and all(torch.equal(a[3][k], b[3][k]) for k in a[3])
        assert a[1].abs().sum() > 0, "rewards that are all zero would compare equal whatever the step did"


def test_discrete_stacked_actions_may_leave_out_the_last_dim():
    env = vmas_ros.make_env("simple_spread", num_envs=2, seed=0, continuous_actions=False)
    obs, *_ = env.step(torch.tensor([[1, 2], [0, 4], [3, 3]]))
    again = vmas_ros.make_env("simple_spread", num_envs=2, seed=0, continuous_actions=False)
    expected, *_ = again.step([torch.tensor([[1], [2]]), torch.tensor([[0], [4]]), torch.tensor([[3], [3]])])
    assert torch.equal(obs, torch.stack(expected))


@pytest.mark.parametrize("actions, message", [
    (torch.zeros(3, 2), r"stacked actions have shape \(3, 2\), expected \(n_agents, num_envs, action size\) = "
                        r"\(3, 4, 2\)"),
    (torch.zeros(2, 4, 2), r"expected \(n_agents, num_envs, action size\) = \(3, 4, 2\)"),
    (torch.zeros(3, 4, 2, dtype=torch.bool), "stacked actions have dtype torch.bool"),
])
def test_bad_stacked_actions_are_refused_naming_what_was_expected(actions, message):
    env = vmas_ros.make_env("simple_spread", num_envs=4, seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(actions)


def test_non_finite_stacked_actions_name_the_agent():
    env = vmas_ros.make_env("simple_spread", num_envs=4, seed=0)
    actions = torch.zeros(3, 4, 2)
    actions[1, 2, 0] = float("nan")
    with pytest.raises(ValueError, match=r"action for agent 'agent_1' contains NaN or inf \(first in env 2\)"):
        env.step(actions)


def test_agents_with_different_action_sizes_need_the_list():
    env = vmas_ros.make_env("simple_speaker_listener", num_envs=2, seed=0)
    sizes = [env.get_agent_action_size(a) for a in env.agents]
    assert len(set(sizes)) > 1
    with pytest.raises(ValueError, match=rf"same action size, got {re.escape(str(sizes))}; pass a list"):
        env.step(torch.zeros(len(sizes), 2, max(sizes)))


def test_each_agents_u_is_its_row_of_the_stacked_actions(device):
    env = vmas_ros.make_env("navigation", num_envs=3, device=device, seed=0, n_agents=5)
    actions = torch.rand(5, 3, 2, device=device) * 2 - 1
    env.step(actions)
    for agent, row in zip(env.agents, actions):
        assert torch.equal(agent.action.u, row)
        assert torch.equal(agent.state.force, row)  # holonomic: the action is the force
    # a list step afterwards: each agent's own tensor again, not a stale row
    listed = [torch.full((3, 2), 0.25 * i, device=device) for i in range(5)]
    env.step(listed)
    assert all(torch.equal(agent.action.u, a) for agent, a in zip(env.agents, listed))
    # set by hand after a stacked step: what was set wins
    env.step(actions)
    env.agents[2].action.u = torch.zeros(3, 2, device=device)
    assert torch.equal(env.agents[2].action.u, torch.zeros(3, 2, device=device))
    assert torch.equal(env.agents[1].action.u, actions[1])
    env.reset()
    assert all(float(agent.action.u.abs().sum()) == 0 for agent in env.agents)


def test_observations_of_different_shapes_come_as_the_list(device):
    env = vmas_ros.make_env("simple_adversary", num_envs=2, device=device, seed=0)
    sizes = {tuple(o.shape) for o in env.reset()}
    assert len(sizes) > 1
    obs, rews, dones, infos = env.step(torch.zeros(env.n_agents, 2, 2, device=device))
    assert isinstance(obs, list) and [tuple(o.shape) for o in obs] == [tuple(o.shape) for o in env.reset()]
    assert rews.shape == (env.n_agents, 2) and dones.shape == (2,)
