"""``navigation`` with ``dynamics="diff_drive"``: unicycle agents, random headings, a lidar that turns with them.

VMAS 1.5 has no such variant, so there is no oracle: the checks are the
layout of the observation, the heading in it against the state, the lidar
seeing a neighbour on the ray that points at it in the agent's own frame,
resets, refusals, and the heuristic reaching the goals.
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from vmas_ros.scenarios import navigation
from vmas_ros.simulator.dynamics.diff_drive import DiffDrive
from vmas_ros.simulator.dynamics.holonomic import Holonomic

STEERED = {"dynamics": "diff_drive"}


def make(num_envs: int = 8, seed: int = 0, **kwargs):
    return harness.make(navigation.Scenario(), num_envs, seed=seed, **kwargs)


def observations(env):
    return env.get_from_scenario(True, False, False, False)[0]


def headings(env) -> torch.Tensor:
    return torch.cat([a.state.rot for a in env.agents], dim=1)  # [B, n]


# ------------------------------------------------------------------- construction
def test_diff_drive_agents_and_observation_layout():
    env = make(16, **STEERED, max_speed=0.3, max_turn_rate=1.5)
    for agent in env.agents:
        assert isinstance(agent.dynamics, DiffDrive) and list(agent.u_range) == [0.3, 1.5]
    obs = observations(env)
    assert [o.shape for o in obs] == [(16, 4 + 2 + 2 + 12)] * 4
    rot = headings(env)
    assert (rot >= -math.pi).all() and (rot < math.pi).all() and rot.std() > 1.0  # spread round the circle
    for i, (agent, o) in enumerate(zip(env.agents, obs)):
        torch.testing.assert_close(o[:, 0:2], agent.state.pos)
        torch.testing.assert_close(o[:, 4], torch.cos(rot[:, i]))
        torch.testing.assert_close(o[:, 5], torch.sin(rot[:, i]))
        torch.testing.assert_close(o[:, 6:8], agent.state.pos - agent.goal.state.pos)
    all_goals = observations(make(2, **STEERED, collisions=False, observe_all_goals=True))
    assert all_goals[0].shape == (2, 4 + 2 + 2 * 4)


def test_holonomic_is_the_default_and_never_turns():
    default, explicit = make(4, seed=3), make(4, seed=3, dynamics="holonomic", max_speed=9.0)
    assert all(isinstance(a.dynamics, Holonomic) and a.u_range == 1.0 for a in explicit.agents)
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        actions = [torch.rand(4, 2, generator=gen) * 2 - 1 for _ in default.agents]
        ours, theirs = default.step([a.clone() for a in actions]), explicit.step([a.clone() for a in actions])
        for mine, other in zip(ours[0], theirs[0]):
            assert torch.equal(mine, other)
    assert (headings(explicit) == 0).all()


@pytest.mark.parametrize("kwargs, fragment", [
    ({"dynamics": "tank"}, "'tank'"), ({"dynamics": None}, "dynamics must be one of holonomic, diff_drive"),
    ({"max_speed": 0}, "max_speed"), ({"max_turn_rate": -1.0}, "max_turn_rate"),
    ({"max_speed": "fast"}, "'fast'"), ({"max_turn_rate": math.inf, **STEERED}, "max_turn_rate"),
])
def test_bad_dynamics_kwargs_raise(kwargs, fragment):
    with pytest.raises(ValueError, match=fragment):
        make(2, **kwargs)


def test_actions_are_speed_and_turn_rate():
    env = make(3, **STEERED, collisions=False, n_agents=2)
    for _ in range(10):
        start = headings(env)[:, 0].clone()
        env.step([torch.tensor([[0.5, 1.0]] * 3), torch.zeros(3, 2)])
    agent = env.agents[0]
    torch.testing.assert_close(agent.state.vel.norm(dim=-1), torch.full((3,), 0.5), atol=2e-3, rtol=0)
    torch.testing.assert_close(agent.state.ang_vel[:, 0], torch.ones(3), atol=1e-4, rtol=0)
    turned = torch.remainder(headings(env)[:, 0] - start, 2 * math.pi)
    torch.testing.assert_close(turned, torch.full((3,), 0.1), atol=1e-4, rtol=0)  # a step of 0.1 s at 1 rad/s
    # no sliding: the velocity is along the heading, up to the half step's turn of the arc it follows
    drift = torch.atan2(agent.state.vel[:, 1], agent.state.vel[:, 0]) - agent.state.rot[:, 0]
    assert (torch.cos(drift) > math.cos(0.05 + 1e-3)).all()


# ---------------------------------------------------------------------- the lidar
@pytest.mark.parametrize("dynamics, ray", [("holonomic", 3), ("diff_drive", 0)])
def test_the_lidar_turns_with_a_diff_drive_agent(dynamics, ray):
    """A neighbour straight up (+y) from an agent facing +y: on the ray at 90 degrees of the world when
    holonomic (the agent cannot turn), on the ray straight ahead (ray 0) with diff_drive."""
    env = make(1, n_agents=2, dynamics=dynamics)
    first, second = env.agents
    first.set_pos(torch.tensor([[0.0, 0.0]]), batch_index=None)
    second.set_pos(torch.tensor([[0.0, 0.3]]), batch_index=None)
    if dynamics == "diff_drive":
        first.set_rot(torch.tensor([[math.pi / 2]]), batch_index=None)
    lidar = observations(env)[0][0, -12:]
    assert lidar[ray] == pytest.approx(0.35 - (0.3 - 0.1), abs=1e-5)  # range minus the distance to the surface
    assert (lidar[torch.arange(12) != ray] < lidar[ray]).all()


# --------------------------------------------------------------------------- reset
@pytest.mark.parametrize("index", [2, [0, 5], "mask"])
def test_reset_at_redraws_headings_only_there(index):
    env = make(6, **STEERED)
    for _ in range(3):
        env.step([torch.tensor([[0.3, 1.0]] * 6) for _ in env.agents])
    check = harness.check_reset_at(env, index, mask_rows=[1, 4], bound=1.0,
                                   scenario_state=lambda e: {"rot": headings(e), "ang_vel": e.agents[0].state.ang_vel})
    chosen = check.chosen
    assert (check.after["rot"][chosen] != check.before["rot"][chosen]).all()
    assert (check.after["ang_vel"][chosen] == 0).all()


# ----------------------------------------------------------------------- heuristic
def test_heuristic_steers_towards_the_goal_from_its_heading():
    policy = navigation.HeuristicPolicy(**STEERED)
    obs = torch.zeros(3, 20)
    obs[:, 4] = 1.0  # facing +x
    obs[0, 6:8] = torch.tensor([-1.0, 0.0])  # goal ahead
    obs[1, 6:8] = torch.tensor([0.0, -1.0])  # goal to the left (+y)
    obs[2, 6:8] = torch.tensor([1.0, 0.0])  # goal behind
    action = policy.compute_action(obs, [0.5, 2.0])
    assert action[0].tolist() == pytest.approx([0.5, 0.0], abs=1e-6)
    assert abs(action[1, 0]) < 1e-6 and action[1, 1] == pytest.approx(2.0)
    assert action[2, 0] == pytest.approx(-0.5) and abs(action[2, 1]) == pytest.approx(2.0)
    # facing +y, a neighbour on ray 0 is ahead in the world's +y: the agent backs away from it
    blocked = torch.zeros(1, 20)
    blocked[0, 5] = 1.0
    blocked[0, 6:8] = torch.tensor([0.0, -1.0])  # the goal is beyond it
    blocked[0, 8] = 0.3
    assert policy.compute_action(blocked, [0.5, 2.0])[0, 0] < 0
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 18), [0.5, 2.0])
    with pytest.raises(ValueError, match=r"u_range \(max_speed, max_turn_rate\), got 1.0"):
        policy.compute_action(obs, 1.0)
    with pytest.raises(ValueError, match="dynamics"):
        navigation.HeuristicPolicy(dynamics="hover")


@pytest.mark.parametrize("options", [{}, {"collisions": False}], ids=["lidar", "no-collisions"])
def test_diff_drive_heuristic_reaches_goals(options):
    """32 envs x 200 steps (seed 0), half heuristic teams, half random: at least 14 of the 16 heuristic
    teams all on their goals at some point (the holonomic heuristic's rate), random teams never, and a
    return per agent at least 3 above random play's."""
    torch.manual_seed(0)
    env = make(32, seed=0, **STEERED, **options)
    heuristic = navigation.HeuristicPolicy(**STEERED, **options).compute_action
    done_ever = torch.zeros(32, dtype=torch.bool)

    def watched(obs, u_range):
        nonlocal done_ever
        done_ever = done_ever | env.done()
        return heuristic(obs, u_range)

    returns = harness.play_lineups(env, [[watched] + [heuristic] * 3, [None] * 4], steps=200)
    heuristic_return, random_return = returns.mean(dim=0).tolist()
    assert int(done_ever[:16].sum()) >= 14 and not done_ever[16:].any(), done_ever
    assert heuristic_return > random_return + 3, returns
