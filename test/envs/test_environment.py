"""The vectorized Environment API (VMAS 1.5's ``Environment``), scenario-independent.

Spaces, step/reset signatures, truncation, partial resets and random actions,
on the two shipped scenarios (seeding and rendering: test_environment_seeding.py). The discrete
action mapping is checked against upstream VMAS.
"""
from __future__ import annotations


import numpy as np
import pytest
import torch
from gymnasium import spaces

import vmas
import vmas_ros
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.scenario import BaseScenario

from test.envs.environment_cases import N_AGENTS, N_ENVS, OBS_SIZE, SCENARIOS, make, positions, zero_actions


# --------------------------------------------------------------------------- spaces


@pytest.mark.parametrize("name", SCENARIOS)
def test_continuous_spaces(name):
    env = make(name)
    assert env.n_agents == N_AGENTS[name]
    assert isinstance(env.action_space, spaces.Tuple) and len(env.action_space) == env.n_agents
    assert isinstance(env.observation_space, spaces.Tuple) and len(env.observation_space) == env.n_agents
    for act_space, obs_space in zip(env.action_space, env.observation_space):
        assert isinstance(act_space, spaces.Box)
        assert act_space.shape == (2,) and act_space.dtype == np.float32
        np.testing.assert_array_equal(act_space.low, [-1.0, -1.0])
        np.testing.assert_array_equal(act_space.high, [1.0, 1.0])
        assert isinstance(obs_space, spaces.Box)
        assert obs_space.shape == (OBS_SIZE[name],) and obs_space.dtype == np.float32
    obs = env.reset()
    assert isinstance(obs, list) and len(obs) == env.n_agents
    for o, space in zip(obs, env.observation_space):
        assert o.shape == (N_ENVS,) + space.shape
        assert all(space.contains(row.numpy()) for row in o)


@pytest.mark.parametrize("name", SCENARIOS)
def test_discrete_spaces(name):
    env = make(name, continuous_actions=False)
    for space in env.action_space:
        assert isinstance(space, spaces.Discrete) and space.n == 3**2
    assert all(env.get_agent_action_size(a) == 1 for a in env.agents)
    assert all(space.shape == (OBS_SIZE[name],) for space in env.observation_space)


@pytest.mark.parametrize("name", SCENARIOS)
def test_multidiscrete_spaces(name):
    env = make(name, continuous_actions=False, multidiscrete_actions=True)
    for space in env.action_space:
        assert isinstance(space, spaces.MultiDiscrete)
        np.testing.assert_array_equal(space.nvec, [3, 3])
    assert all(env.get_agent_action_size(a) == 2 for a in env.agents)


def test_multidiscrete_needs_discrete():
    with pytest.raises(ValueError, match="multidiscrete"):
        make("simple_spread", continuous_actions=True, multidiscrete_actions=True)


@pytest.mark.parametrize("name", SCENARIOS)
@pytest.mark.parametrize("continuous", [True, False])
def test_dict_spaces(name, continuous):
    env = make(name, dict_spaces=True, continuous_actions=continuous)
    names = [f"agent_{i}" for i in range(N_AGENTS[name])]
    assert isinstance(env.action_space, spaces.Dict) and list(env.action_space.keys()) == names
    assert isinstance(env.observation_space, spaces.Dict) and list(env.observation_space.keys()) == names
    expected = spaces.Box if continuous else spaces.Discrete
    assert all(isinstance(env.action_space[n], expected) for n in names)
    assert all(env.observation_space[n].shape == (OBS_SIZE[name],) for n in names)
    obs = env.reset()
    assert isinstance(obs, dict) and list(obs) == names
    obs, rews, dones, infos = env.step({n: a for n, a in zip(names, env.get_random_actions())})
    for result in (obs, rews, infos):
        assert isinstance(result, dict) and list(result) == names
    assert obs["agent_0"].shape == (N_ENVS, OBS_SIZE[name])
    assert rews["agent_0"].shape == (N_ENVS,)
    assert dones.shape == (N_ENVS,) and dones.dtype == torch.bool


# ----------------------------------------------------------------------------- step


def test_step_with_list_and_dict_actions_is_the_same():
    by_list, by_dict = make("simple_spread"), make("simple_spread")
    gen = torch.Generator().manual_seed(0)
    for _ in range(3):
        actions = [torch.rand(N_ENVS, 2, generator=gen) * 2 - 1 for _ in by_list.agents]
        out_list = by_list.step(actions)
        out_dict = by_dict.step({a.name: act for a, act in zip(by_dict.agents, actions)})
        for o_l, o_d in zip(out_list[0], out_dict[0]):
            assert torch.equal(o_l, o_d)
        for r_l, r_d in zip(out_list[1], out_dict[1]):
            assert torch.equal(r_l, r_d)
    assert not torch.equal(positions(by_list), positions(make("simple_spread"))), "the agents moved"
    # dicts may list the agents in any order
    shuffled = {a.name: torch.zeros(N_ENVS, 2) for a in reversed(by_dict.agents)}
    by_dict.step(shuffled)


def test_step_accepts_tuples_and_numpy_arrays():
    env = make("simple_spread")
    env.step(tuple(np.full((N_ENVS, 2), 0.5, dtype=np.float32) for _ in env.agents))
    torch.testing.assert_close(env.agents[0].action.u, torch.full((N_ENVS, 2), 0.5))


def test_step_applies_actions_per_env():
    env = make("simple_spread")
    for i, agent in enumerate(env.agents):  # far apart: no contacts
        agent.set_pos(torch.tensor([1.0 * i, -1.0 * i]), batch_index=None)
    before = [a.state.pos.clone() for a in env.agents]
    actions = [torch.tensor([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]) for _ in env.agents]
    env.step(actions)
    for agent, pos in zip(env.agents, before):
        delta = agent.state.pos - pos
        # force 1, mass 1, dt 0.1: dv = 0.1 (drag applies to the velocity before the force)
        torch.testing.assert_close(delta, actions[0] * 0.1 * 0.1, atol=1e-6, rtol=0)


@pytest.mark.parametrize("name", SCENARIOS)
def test_step_returns_four_tuple(name):
    env = make(name)
    result = env.step(zero_actions(env))
    assert isinstance(result, (list, tuple)) and len(result) == 4
    obs, rews, dones, infos = result
    assert len(obs) == len(rews) == len(infos) == env.n_agents
    assert all(r.shape == (N_ENVS,) for r in rews)
    assert dones.shape == (N_ENVS,) and dones.dtype == torch.bool and not dones.any()
    assert all(isinstance(i, dict) for i in infos)


@pytest.mark.parametrize("name", SCENARIOS)
def test_step_returns_five_tuple_with_terminated_truncated(name):
    env = make(name, terminated_truncated=True)
    result = env.step(zero_actions(env))
    assert len(result) == 5
    obs, rews, terminated, truncated, infos = result
    assert len(obs) == len(rews) == len(infos) == env.n_agents
    for flags in (terminated, truncated):
        assert flags.shape == (N_ENVS,) and flags.dtype == torch.bool and not flags.any()


def test_reset_return_options():
    env = make("simple_spread")
    obs = env.reset()
    assert isinstance(obs, list) and obs[0].shape == (N_ENVS, OBS_SIZE["simple_spread"])
    obs, infos = env.reset(return_info=True)
    assert len(infos) == env.n_agents
    obs, dones, infos = env.reset(return_info=True, return_dones=True)  # VMAS's order
    assert len(infos) == env.n_agents
    assert dones.shape == (N_ENVS,) and not dones.any()
    assert env.reset(return_observations=False) is None


@pytest.mark.parametrize("terminated_truncated", [False, True])
def test_max_steps_truncates_exactly_at_max_steps(terminated_truncated):
    max_steps = 5
    env = make("simple_spread", max_steps=max_steps, terminated_truncated=terminated_truncated)

    def flags():
        out = env.step(zero_actions(env))
        if terminated_truncated:
            _, _, terminated, truncated, _ = out
            assert not terminated.any(), "simple_spread never terminates by itself"
            return truncated
        return out[2]

    for step in range(1, max_steps):
        assert not flags().any(), f"done too early, at step {step}"
        assert torch.equal(env.steps, torch.full((N_ENVS,), float(step)))
    assert flags().all(), "every env must be done at step max_steps"
    assert flags().all(), "and stay done until reset"
    env.reset_at(1)
    done = flags()
    assert done.tolist() == [True, False, True, True], "the reset env restarts its step count"
    env.reset()
    assert not flags().any()


# ------------------------------------------------------------------------ reset_at


def _check_reset_at(env, index, expected_rows):
    gen = torch.Generator().manual_seed(3)
    for _ in range(3):
        env.step([torch.rand(N_ENVS, 2, generator=gen) * 2 - 1 for _ in env.agents])
    before_pos = positions(env)
    before_vel = torch.stack([e.state.vel for e in env.world.entities], dim=1).clone()
    obs = env.reset_at(index)
    after_pos = positions(env)
    after_vel = torch.stack([e.state.vel for e in env.world.entities], dim=1)
    reset = torch.zeros(N_ENVS, dtype=torch.bool)
    reset[expected_rows] = True
    # untouched envs keep everything
    assert torch.equal(after_pos[~reset], before_pos[~reset])
    assert torch.equal(after_vel[~reset], before_vel[~reset])
    assert torch.equal(env.steps[~reset], torch.full((int((~reset).sum()),), 3.0))
    # reset envs start over: agents re-placed, everything at rest, step count 0
    n_agents = len(env.agents)  # entities are landmarks first, then agents
    assert (after_pos[reset][:, -n_agents:] != before_pos[reset][:, -n_agents:]).any(dim=-1).all()
    assert not after_vel[reset].any()
    assert not env.steps[reset].any()
    # the returned observations are the current ones for every env
    for o, agent in zip(obs, env.agents):
        torch.testing.assert_close(o[:, :2], agent.state.pos)


@pytest.mark.parametrize(
    "index,rows",
    [
        (2, [2]),
        (-1, [3]),
        ([0, 3], [0, 3]),
        (torch.tensor([1, 2], dtype=torch.long), [1, 2]),
        (torch.tensor([True, False, False, True]), [0, 3]),
    ],
    ids=["int", "negative-int", "list", "long-tensor", "bool-mask"],
)
def test_reset_at_resets_exactly_those_envs(index, rows):
    _check_reset_at(make("simple_spread"), index, rows)


def test_reset_at_waterfall_resets_only_those_envs():
    env = make("waterfall")
    start = positions(env)
    _check_reset_at(env, [1, 2], [1, 2])
    assert torch.equal(positions(env)[1:3], start[1:3]), "waterfall always starts from the same layout"


def test_reset_at_waterfall_restores_the_start_layout():
    env = make("waterfall")
    start = positions(env)
    for _ in range(3):
        env.step([torch.tensor([[0.0, -1.0]]).expand(N_ENVS, 2) for _ in env.agents])
    assert not torch.equal(positions(env), start)
    agents_before = torch.stack([a.state.pos for a in env.agents], dim=1).clone()
    env.reset_at([1, 2])
    assert torch.equal(positions(env)[1:3], start[1:3]), "waterfall always starts from the same layout"
    assert torch.equal(env.steps, torch.tensor([3.0, 0.0, 0.0, 3.0]))
    # the agents of the other envs are untouched
    agents_after = torch.stack([a.state.pos for a in env.agents], dim=1)
    assert torch.equal(agents_after[[0, 3]], agents_before[[0, 3]])


def test_reset_at_empty_mask_changes_nothing():
    env = make("simple_spread")
    env.step(zero_actions(env))
    before = positions(env)
    env.reset_at(torch.zeros(N_ENVS, dtype=torch.bool))
    assert torch.equal(positions(env), before)
    assert torch.equal(env.steps, torch.ones(N_ENVS))


def test_steps_count_as_a_plain_tensor_would():
    """``env.steps`` is brought up to date when read: a tensor read earlier keeps its values, writes into
    the tensor read and assignments hold, and counting resumes from them."""
    env = make("simple_spread")
    env.step(zero_actions(env))
    earlier = env.steps
    env.step(zero_actions(env))
    env.step(zero_actions(env))
    assert torch.equal(earlier, torch.ones(N_ENVS)) and torch.equal(env.steps, torch.full((N_ENVS,), 3.0))
    env.steps[0] = 10  # in place, as reset_at does
    env.step(zero_actions(env))
    assert env.steps.tolist() == [11.0] + [4.0] * (N_ENVS - 1)
    env.steps = torch.zeros(N_ENVS)
    env.step(zero_actions(env))
    assert torch.equal(env.steps, torch.ones(N_ENVS))


class _CountingScenario(BaseScenario):
    """A scenario without batched resets, recording every reset_world_at call."""

    def make_world(self, batch_dim, device, **kwargs):
        self.calls = []
        world = World(batch_dim, device)
        world.add_agent(Agent("agent_0", shape=Sphere(0.05)))
        world.add_landmark(Landmark("goal", collide=False))
        return world

    def reset_world_at(self, env_index=None):
        self.calls.append(env_index)
        for e in self.world.entities:
            pos = torch.rand(2, device=self.world.device) if env_index is not None else torch.rand(self.world.batch_dim, 2)
            e.set_pos(pos, batch_index=env_index)

    def observation(self, agent):
        return agent.state.pos

    def reward(self, agent):
        return agent.state.pos[:, 0]


def test_reset_at_calls_unbatched_scenarios_one_env_at_a_time():
    scenario = _CountingScenario()
    env = vmas_ros.make_env(scenario, num_envs=N_ENVS, seed=0)
    assert scenario.calls == [None]
    env.reset_at(torch.tensor([True, False, True, True]))
    assert scenario.calls[1:] == [0, 2, 3]
    assert all(isinstance(i, int) for i in scenario.calls[1:])
    env.reset_at(1)
    assert scenario.calls[-1] == 1


# ----------------------------------------------------------------- random actions


@pytest.mark.parametrize("name", SCENARIOS)
@pytest.mark.parametrize("mode", ["continuous", "discrete", "multidiscrete"])
def test_random_actions_are_in_the_action_space(name, mode):
    kwargs = {"continuous": {}, "discrete": dict(continuous_actions=False),
              "multidiscrete": dict(continuous_actions=False, multidiscrete_actions=True)}[mode]
    env = make(name, num_envs=8, **kwargs)
    seen = set()
    for _ in range(4):
        actions = env.get_random_actions()
        assert len(actions) == env.n_agents
        for action, agent, space in zip(actions, env.agents, env.action_space):
            # a discrete action is one index per env, [B], as VMAS draws it
            assert action.shape == ((8,) if mode == "discrete" else (8, env.get_agent_action_size(agent)))
            for row in action:
                value = row.numpy()
                if mode == "discrete":
                    assert space.contains(value)  # a 0-d array, as VMAS's own test checks it
                    seen.add(int(value))
                elif mode == "multidiscrete":
                    assert space.contains(value.astype(np.int64))
                    seen.update(value.tolist())
                else:
                    assert space.contains(value.astype(np.float32))
                    seen.add(float(value[0]) > 0)
    expected = {"continuous": {True, False}, "discrete": set(range(9)), "multidiscrete": {0, 1, 2}}[mode]
    assert seen == expected, "random actions should cover the whole space"
    env.step(env.get_random_actions())  # and they are accepted


# -------------------------------------------------------------- discrete mapping

# flat index i -> (x choice, y choice) = (i // 3, i % 3); choice 0 -> 0, 1 -> -u, 2 -> +u
EXPECTED_U = [[0, 0], [0, -1], [0, 1], [-1, 0], [-1, -1], [-1, 1], [1, 0], [1, -1], [1, 1]]


def test_discrete_action_mapping_matches_upstream():
    ours = vmas_ros.make_env("simple_spread", num_envs=9, continuous_actions=False, seed=0)
    up = vmas.make_env("simple_spread", num_envs=9, continuous_actions=False, seed=0)
    flat = torch.arange(9).unsqueeze(-1)
    ours.step([flat.clone() for _ in ours.agents])
    up.step([flat.clone() for _ in up.agents])
    for a_ours, a_up in zip(ours.agents, up.agents):
        assert torch.equal(a_ours.action.u, a_up.action.u)
        assert torch.equal(a_ours.action.u, torch.tensor(EXPECTED_U, dtype=torch.float32))
    # a 1-D [num_envs] index tensor is accepted too
    ours.step([flat.squeeze(-1) for _ in ours.agents])
    assert ours.agents[0].action.u.tolist() == EXPECTED_U


def test_multidiscrete_mapping_matches_flat_mapping():
    env = make("simple_spread", num_envs=9, continuous_actions=False, multidiscrete_actions=True)
    flat = torch.arange(9)
    env.step([torch.stack([flat // 3, flat % 3], dim=-1) for _ in env.agents])
    assert env.agents[1].action.u.tolist() == EXPECTED_U


def test_discrete_actions_scale_with_u_multiplier():
    env = make("waterfall", num_envs=9, continuous_actions=False)  # waterfall agents: u_multiplier 0.7
    env.step([torch.arange(9).unsqueeze(-1) for _ in env.agents])
    torch.testing.assert_close(env.agents[0].action.u, 0.7 * torch.tensor(EXPECTED_U, dtype=torch.float32))


class _OneRewardBuffer(_CountingScenario):
    """Writes every agent's reward into one buffer and returns it, as some VMAS scenarios do."""

    def make_world(self, batch_dim, device, **kwargs):
        world = super().make_world(batch_dim, device)
        world.add_agent(Agent("agent_1", shape=Sphere(0.05)))
        self.buffer = torch.zeros(batch_dim, device=device)
        return world

    def reward(self, agent):
        self.buffer.fill_(float(agent.name[-1]) + 1)
        return self.buffer


def test_each_reward_is_copied_as_the_scenario_returns_it():
    env = vmas_ros.make_env(_OneRewardBuffer(), num_envs=N_ENVS, seed=0)
    _, rewards, _, _ = env.step([torch.zeros(N_ENVS, 2)] * 2)
    assert [r.tolist() for r in rewards] == [[1.0] * N_ENVS, [2.0] * N_ENVS]
    rewards[0].add_(5)  # the caller's own copies
    assert rewards[1].tolist() == [2.0] * N_ENVS and env.scenario.buffer.tolist() == [2.0] * N_ENVS
    _, stacked_rewards, _, _ = env.step(torch.zeros(2, N_ENVS, 2))  # the stacked step copies as they come too
    assert stacked_rewards.tolist() == [[1.0] * N_ENVS, [2.0] * N_ENVS]


def test_fresh_rewards_go_out_uncopied_yet_each_agent_and_call_has_its_own():
    env = vmas_ros.make_env("simple_spread", num_envs=2, seed=0)
    assert env.scenario.fresh_rewards, "simple_spread at a few envs gives each agent a row of its own"
    _, rewards, _, _ = env.step([torch.zeros(2, 2)] * env.n_agents)
    again = env.get_from_scenario(get_observations=False, get_rewards=True, get_infos=False, get_dones=False)[0]
    assert len({r.data_ptr() for r in rewards + again}) == 2 * env.n_agents, "no two share memory"
    expected = rewards[1].clone()
    rewards[0].add_(5)
    assert torch.equal(rewards[1], expected) and torch.equal(again[0], expected)
