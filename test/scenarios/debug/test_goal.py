"""``goal`` (debug): API, parity with VMAS 1.5.2 (rewards and info, goal reached or not), reset, heuristic."""
from __future__ import annotations

import pytest
import torch

from test.scenarios import harness
from test.scenarios.debug.test_circle_trajectory import lockstep_actions
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import vmas_states
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios.debug import goal as scenario

NAME = "goal"
CUSTOM = {
    "energy_rew_coeff": 0.5, "dt_delay": 1, "pos_shaping_factor": 2.0, "time_rew_coeff": -0.1,
    "u_range": 0.7, "linear_friction": 0.2, "min_input_norm": 0.2,
}


def make(num_envs: int = 6, **kwargs):
    return harness.make(scenario.Scenario(), num_envs, **kwargs)


def test_construction_and_kwargs():
    env = make(2)
    world, agent = env.world, env.agents[0]
    assert [e.name for e in world.entities] == ["goal", "agent 0"]
    assert (world.dt, world._substeps, world._drag) == (0.05, 5, 0.0)
    assert agent.shape.radius == 0.16 and agent.linear_friction == 0.1 and agent.f_range == pytest.approx(1.1)
    assert world.landmarks[0].shape.radius == 0.06 and not world.landmarks[0].collide
    assert (env.scenario.time_rew_coeff, env.scenario.energy_rew_coeff) == (-0.01, 0.0)
    with pytest.warns(UserWarning, match="energy_reward_coeff"):  # VMAS's name here is energy_rew_coeff
        make(2, energy_reward_coeff=1)
    for bad in ({"u_range": 0}, {"dt_delay": -1}, {"pos_shaping_factor": -1}, {"time_rew_coeff": "x"}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            make(2, **bad)


@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream(mode):
    harness.check_spaces(make(4, **SPACE_MODES[mode]), harness.make_upstream(NAME, 4, **SPACE_MODES[mode]), 3)


@pytest.mark.parametrize("kwargs", [{}, CUSTOM], ids=["default", "custom"])
def test_matches_upstream_vmas(kwargs):
    """Random actions from upstream's start; then from goals moved next to the agents, on the
    heuristic, so the goal is reached (reward terms switched off) in some envs."""
    up, ours = harness.make_upstream(NAME, 6, **kwargs), make(6, **kwargs)
    harness.copy_start(up, ours, vmas_states.goal)
    seen = run_lockstep(up, ours, seed=0, actions=lockstep_actions(up, ours), steps=30)
    assert seen.largest_reward > 0.01

    def goal_nearby(up, ours) -> None:
        offset = torch.linspace(-0.3, 0.3, 6).unsqueeze(-1) * torch.tensor([1.0, 0.5])
        target = up.world.agents[0].state.pos + offset
        up.scenario.goal.set_pos(target.clone(), batch_index=None)
        ours.scenario.goal.set_pos(target.clone(), batch_index=None)
        for env in (up, ours):  # both rewards move on from the new goal
            env.get_from_scenario(False, True, False, False)
        vmas_states.goal(up, ours)

    harness.copy_start(up, ours, goal_nearby)
    policy = scenario.HeuristicPolicy(**kwargs)
    run_lockstep(up, ours, seed=1, actions=lockstep_actions(up, ours, policy=lambda obs: [policy.compute_action(
        obs[0], kwargs.get("u_range", 1.0))]), steps=40)
    assert 0 < int(ours.scenario.goal_reached.sum()) and (ours.get_from_scenario(False, False, True, False)[0][0]
                                                          ["time_rew"] == 0).any()


@pytest.mark.parametrize("index", [0, [2, 3], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(6, dt_delay=2)
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        env.step([torch.rand(6, 2, generator=gen) * 2 - 1])
    state = lambda e: {"shaping": e.scenario.shaping, "accum": e.agents[0].controller.accum_errs}  # noqa: E731
    check = harness.check_reset_at(env, index, mask_rows=[1, 4], scenario_state=state, bound=3.0)
    chosen = check.chosen
    distance = torch.linalg.vector_norm(env.world.landmarks[0].state.pos - env.agents[0].state.pos, dim=-1)
    torch.testing.assert_close(check.after["shaping"][chosen], distance[chosen])
    assert (check.after["accum"][chosen] == 0).all() and (env.scenario.commands.pending[chosen] == 0).all()


def test_heuristic():
    """8 envs x 100 steps each way (seed 0). Measured: heuristic ~0.64 (it reaches the goal), random ~-0.96."""
    policy = scenario.HeuristicPolicy()
    action = policy.compute_action(torch.tensor([[0, 0, 0, 0, 2.0, 0.0], [0, 0, 0, 0, 0.1, 0.0]]), 1.0)
    torch.testing.assert_close(action, torch.tensor([[-1.0, 0.0], [-0.2, 0.0]]))
    slow = scenario.HeuristicPolicy(min_input_norm=0.3).compute_action(torch.tensor([[0, 0, 0, 0, 0.1, 0.0]]), 1.0)
    torch.testing.assert_close(slow, torch.tensor([[-0.315, 0.0]]))
    torch.manual_seed(0)
    env = make(16, seed=0)
    returns = harness.play_lineups(env, [[policy.compute_action], [None]], steps=100)
    heuristic, random = returns[0].tolist()
    assert heuristic > random + 1.0, returns
