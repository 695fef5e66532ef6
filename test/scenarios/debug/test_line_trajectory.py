"""``line_trajectory`` (debug): API, parity with VMAS 1.5.2 (rewards, info, done), reset, heuristic."""
from __future__ import annotations

import pytest
import torch

from test.scenarios import harness
from test.scenarios.debug.test_circle_trajectory import keep_upstream_rng, lockstep_actions  # noqa: F401
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios.debug import line_trajectory as scenario

NAME = "line_trajectory"


def make(num_envs: int = 6, **kwargs):
    return harness.make(scenario.Scenario(), num_envs, **kwargs)


def test_construction_and_kwargs():
    env = make(2)
    world, agent = env.world, env.agents[0]
    assert [e.name for e in world.entities] == ["agent_0"]
    assert (world.dt, world._substeps, world._drag) == (0.1, 1, 0.1)
    assert (agent.shape.radius, agent.mass, agent.f_range, agent.u_range) == (0.03, 2, 0.5, 1)
    controller = agent.controller
    assert (controller.ctrl_gain, controller.integralTs, controller.derivativeTs) == (4.0, 1.25, 0.001)
    assert env.scenario.obs_noise == 0
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    with pytest.raises(ValueError, match="obs_noise"):
        make(2, obs_noise=-1)
    with pytest.raises(TypeError, match="u_range"):
        scenario.HeuristicPolicy(u_range=1)


@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream(mode):
    harness.check_spaces(make(4, **SPACE_MODES[mode]), harness.make_upstream(NAME, 4, **SPACE_MODES[mode]), 3)


def test_matches_upstream_vmas():
    """Random actions, then the heuristic from near the line's end (it drives past it: ``done`` turns True)."""
    up, ours = harness.make_upstream(NAME, 6), make(6)
    harness.copy_start(up, ours)
    seen = run_lockstep(up, ours, seed=0, actions=lockstep_actions(up, ours), steps=20)
    assert seen.largest_reward > 0.3
    for env in (up, ours):
        agent = env.world.agents[0]
        agent.set_pos(agent.state.pos * torch.tensor([1.0, 0.0]) + torch.tensor([0.0, 1.6]), batch_index=None)
    policy = scenario.HeuristicPolicy()
    follow = lockstep_actions(up, ours, policy=lambda obs: [policy.compute_action(obs[0], 1.0)])
    seen = run_lockstep(up, ours, seed=1, actions=follow, steps=30)
    assert ours.done().all() and seen.fastest > 0.2


def test_matches_upstream_vmas_with_observation_noise(keep_upstream_rng):  # noqa: F811
    up, ours = harness.make_upstream(NAME, 6, obs_noise=0.1), make(6, obs_noise=0.1)
    harness.copy_start(up, ours)
    run_lockstep(up, ours, seed=2, actions=lockstep_actions(up, ours, sync_noise=True), steps=10)


def test_reward_terms_and_done():
    env = make(3)
    agent = env.agents[0]
    agent.set_pos(torch.tensor([[0.25, 0.0], [-0.04, 2.5], [0.0, 1.0]]), batch_index=None)
    agent.set_vel(torch.tensor([[0.0, 1.0], [1.0, 0.0], [0.0, 0.0]]), batch_index=None)
    env.scenario.vel_action = torch.tensor([[0.0, 2.0], [0.0, 1.0], [1.0, 0.0]])
    rews, dones, infos = env.get_from_scenario(False, True, True, True)
    torch.testing.assert_close(infos[0]["pos_rew"], torch.tensor([-0.5, -0.2, 0.0]))
    torch.testing.assert_close(infos[0]["dot_product"], torch.tensor([0.5, 0.0, 0.0]))
    torch.testing.assert_close(infos[0]["steady_rew"], torch.tensor([0.2, 0.0, 0.0]))  # zero velocity: 0
    torch.testing.assert_close(rews[0], torch.tensor([0.2, -0.2, 0.0]))
    assert dones.tolist() == [False, True, False]


@pytest.mark.parametrize("index", [1, [0, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(6)
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        env.step([torch.rand(6, 2, generator=gen) * 2 - 1])
    state = lambda e: {"accum": e.agents[0].controller.accum_errs}  # noqa: E731
    check = harness.check_reset_at(env, index, mask_rows=[2, 5], scenario_state=state, bound=1.0)
    pos = env.agents[0].state.pos[check.chosen]
    assert (check.after["accum"][check.chosen] == 0).all() and (pos[:, 1] <= 0).all()


def test_heuristic():
    """8 envs x 100 steps each way (seed 0). Measured: heuristic ~-2.6, random ~-55."""
    action = scenario.HeuristicPolicy().compute_action(torch.tensor([[0.3, -0.5, 0, 0, 0.3, -0.5]]), 1.0)
    assert action.shape == (1, 2) and action[0, 0] < 0 and action[0, 1] > 0 and action.norm() <= 1 + 1e-6
    torch.manual_seed(0)
    env = make(16, seed=0)
    returns = harness.play_lineups(env, [[scenario.HeuristicPolicy().compute_action], [None]], steps=100)
    heuristic, random = returns[0].tolist()
    assert heuristic > random + 30, returns
