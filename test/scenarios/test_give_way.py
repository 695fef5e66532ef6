"""``give_way``: API, parity with VMAS 1.5.2, map and reset, safety of long rollouts, heuristic.

Oracle: ``vmas`` 1.5.2 (same start -> same obs, rewards and states, with the
velocity controller, contacts and every reward term switched on).
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import vmas_states
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios import give_way
from vmas_ros.simulator.heuristic_policy import RandomPolicy

NAME = "give_way"
#: every reward term on, so that parity covers them
PENALTIES = {
    "agent_collision_penalty": -1.0, "passage_collision_penalty": -0.5,
    "obstacle_collision_penalty": -0.25, "energy_rew_coeff": 0.1,
}


def make(num_envs: int = 8, **kwargs):
    return harness.make(give_way.Scenario(), num_envs, **kwargs)


def wall_clearance(env) -> torch.Tensor:
    """Surface distance of every agent to every wall, [B, 2, W] (negative: penetration)."""
    scenario = env.scenario
    pos = torch.stack([a.state.pos for a in env.agents], dim=1)
    rot = torch.stack([a.state.rot[:, 0] for a in env.agents], dim=1)
    return scenario._wall_clearance(pos, rot)


# ------------------------------------------------------------------- construction
def test_construction_defaults():
    env = make(4)
    world = env.world
    assert [a.name for a in env.agents] == ["agent_0", "agent_1"]
    walls = ["wall 0", "wall 1", "ceil 1 0", "ceil 1 1", "ceil 2 0", "ceil 2 1", "ceil 2 2", "floor"]
    assert [l.name for l in world.landmarks] == ["goal_0", "goal_1", *walls]
    assert (world.dt, world._substeps, world._drag, world._collision_force) == (0.05, 5, 0.0, 500)
    for agent in env.agents:
        assert agent.shape.radius == 0.16 and not agent.rotatable and agent.collide
        assert (agent.u_range, agent.f_range, agent.v_range) == (0.5, 1.1, 0.5)
        assert agent.linear_friction == 0.1 and isinstance(agent.controller, give_way.VelocityController)
    assert not any(l.collide for l in world.landmarks[:2]) and all(l.collide for l in world.landmarks[2:])
    # the map: corridor y in [-0.2, 0.2], ends at x = +-2.5, nook x in [-0.2, 0.2] up to y = 0.68
    expected = {
        "wall 0": (-2.5, 0.0, math.pi / 2), "wall 1": (2.5, 0.0, math.pi / 2),
        "ceil 1 0": (1.35, 0.2, 0.0), "ceil 1 1": (-1.35, 0.2, 0.0),
        "ceil 2 0": (-0.2, 0.44, math.pi / 2), "ceil 2 1": (0.2, 0.44, math.pi / 2),
        "ceil 2 2": (0.0, 0.68, 0.0), "floor": (0.0, -0.2, 0.0),
        "goal_0": (2.29, 0.0, 0.0), "goal_1": (-2.29, 0.0, 0.0),
    }
    for landmark in world.landmarks:
        x, y, rot = expected[landmark.name]
        torch.testing.assert_close(landmark.state.pos, torch.tensor([[x, y]] * 4))
        torch.testing.assert_close(landmark.state.rot, torch.full((4, 1), rot))
    starts = torch.stack([a.state.pos for a in env.agents], dim=1)
    assert ((starts - torch.tensor([[-2.0, 0.0], [2.0, 0.0]])).abs() <= 0.02).all()
    assert starts[:, 0].std(dim=0).min() > 0  # noise drawn per env


def test_construction_variants():
    env = make(2, mirror_passage=True, box_agents=True, use_velocity_controller=False, observe_rel_pos=True)
    names = [l.name for l in env.world.landmarks]
    assert names[-5:] == ["ceil 12 0", "ceil 12 1", "ceil 22 0", "ceil 22 1", "ceil 22 2"] and "floor" not in names
    assert (env.world._substeps, env.world._collision_force) == (16, 10000)
    for agent in env.agents:
        assert isinstance(agent.shape, give_way.Box) and (agent.shape.length, agent.shape.width) == (0.32, 0.24)
        assert agent.u_range == 1.1 and not hasattr(agent, "controller")
    torch.testing.assert_close(env.world.landmarks[-1].state.pos, torch.tensor([[0.0, -0.68]] * 2))
    assert env.get_from_scenario(True, False, False, False)[0][0].shape == (2, 6)


def test_unknown_kwargs_warn_and_bad_values_raise():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for bad in ({"v_range": 0}, {"dt_delay": -1}, {"dt_delay": 1.5}, {"obs_noise": -0.1}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            make(2, **bad)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode):
    options = dict(SPACE_MODES[mode], observe_rel_pos=mode == "dict")
    obs, _ = harness.check_spaces(make(4, **options), harness.make_upstream(NAME, 4, **options), steps=3)
    values = list(obs.values()) if isinstance(obs, dict) else obs
    assert [v.shape[1] for v in values] == [6 if mode == "dict" else 4] * 2


# -------------------------------------------------------------------------- reset
def scenario_state(env) -> dict:
    state = {"shaping": env.scenario.shaping, "goal_reached": env.scenario.goal_reached}
    for agent in env.agents:
        state[f"{agent.name}.pid"] = agent.controller.accum_errs
    return state


@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(8, dt_delay=1)
    gen = torch.Generator().manual_seed(1)
    for _ in range(8):
        env.step([torch.rand(8, 2, generator=gen) - 0.5 for _ in env.agents])
    for landmark in env.world.landmarks:  # knock the map about, so a reset must put it back
        landmark.set_pos(landmark.state.pos + torch.rand(8, 2, generator=gen) * 0.1 + 0.01, batch_index=None)
    check = harness.check_reset_at(env, index, mask_rows=slice(None, None, 3), scenario_state=scenario_state, bound=2.5)
    chosen = check.chosen
    fresh = make(1)
    for mine, new in zip(env.world.landmarks, fresh.world.landmarks):
        torch.testing.assert_close(mine.state.pos[chosen], new.state.pos.expand(int(chosen.sum()), 2))
    pos = torch.stack([a.state.pos for a in env.agents], dim=1)[chosen]
    goals = torch.tensor([[2.29, 0.0], [-2.29, 0.0]])
    torch.testing.assert_close(check.after["shaping"][chosen], torch.linalg.vector_norm(pos - goals, dim=-1))
    assert not check.after["goal_reached"][chosen].any()
    assert all((check.after[f"{a.name}.pid"][chosen] == 0).all() for a in env.agents)
    assert (env.scenario._delay_line[chosen] == 0).all() and (env.scenario._delay_line[~chosen] != 0).any()


# ------------------------------------------------------------------------- parity
def test_matches_upstream_vmas():
    up, ours = harness.make_upstream(NAME, 8), make(8)
    harness.copy_start(up, ours, vmas_states.give_way)
    seen = run_lockstep(up, ours, seed=0, steps=40)
    assert seen.fastest > 0.1  # the velocity controller did drive them


@pytest.mark.parametrize("options, steps", [
    ({"mirror_passage": True, "observe_rel_pos": True, "dt_delay": 2}, 40),
    ({"use_velocity_controller": False}, 40),
    ({"box_agents": True}, 6),  # 16 substeps: upstream is slow
], ids=["mirror-relpos-delay", "force-actions", "box-agents"])
def test_matches_upstream_vmas_in_contact(options, steps):
    """Agents start together near the nook, so they hit each other and the walls:
    every penalty, the energy term and the info dict must agree too."""
    batch = 6
    kwargs = dict(PENALTIES, **options)
    up, ours = harness.make_upstream(NAME, batch, **kwargs), make(batch, **kwargs)

    def crowd(up, ours) -> None:
        gen = torch.Generator().manual_seed(3)
        for a_up, a_ours in zip(up.world.agents, ours.world.agents):
            pos = (torch.rand(batch, 2, generator=gen) - 0.5) * torch.tensor([0.8, 0.3])
            a_up.set_pos(pos, batch_index=None)
            a_ours.set_pos(pos, batch_index=None)
            a_up.shaping = torch.linalg.vector_norm(pos - a_up.goal.state.pos, dim=-1)
        vmas_states.give_way(up, ours)

    harness.copy_start(up, ours, crowd)
    seen = run_lockstep(up, ours, seed=1, steps=steps)
    assert seen.largest_reward >= 0.25  # some penalty was paid
    _, _, _, info_up = up.step([torch.zeros(batch, 2)] * 2)
    _, _, _, info_ours = ours.step([torch.zeros(batch, 2)] * 2)
    for mine, theirs in zip(info_ours, info_up, strict=True):
        assert list(mine) == list(theirs)
        for key in theirs:
            torch.testing.assert_close(mine[key], theirs[key], atol=1e-4, rtol=0)


def test_done_on_completion_and_final_reward():
    env = make(3, done_on_completion=True)
    goals = torch.tensor([[2.29, 0.0], [-2.29, 0.0]])
    for i, agent in enumerate(env.agents):
        inward = torch.tensor([[-0.05, 0.0], [-0.05, 0.0], [-0.1 if i else -0.05, 0.0]])
        on_goal = goals[i] + inward * goals[i].sign()
        agent.set_pos(on_goal, batch_index=None)  # env 2: agent 1 is off its goal (radius 0.08)
    _, _, dones, infos = env.step([torch.zeros(3, 2)] * 2)
    assert dones.tolist() == [True, True, False]
    torch.testing.assert_close(infos[0]["final_rew"], torch.tensor([0.01, 0.01, 0.0]))
    assert not make(1).done().any()


# ------------------------------------------------------------------------ safety
def test_long_rollouts_stay_finite_and_out_of_the_walls():
    """300 steps: random, heuristic against random, heuristic pair; random
    velocity commands ram the walls at full speed, yet no agent sinks more
    than 1.5 cm into a wall or leaves the corridor and nook."""
    torch.manual_seed(0)
    env = make(6)
    heuristic, rand = give_way.HeuristicPolicy().compute_action, RandomPolicy().compute_action
    lineups = [[rand, rand], [heuristic, rand], [heuristic, heuristic]]
    worst = torch.tensor(1.0)

    def watched(obs, u_range):  # the first agent's policy of the first line-up: looks once per step
        nonlocal worst
        worst = torch.minimum(worst, wall_clearance(env).min())
        pos = torch.stack([a.state.pos for a in env.agents], dim=1)
        assert (pos[..., 0].abs() < 2.5).all() and (pos[..., 1] > -0.2).all() and (pos[..., 1] < 0.68).all()
        return rand(obs, u_range)

    lineups[0][0] = watched
    harness.play_lineups(env, lineups, steps=300)
    assert -0.015 < worst < 0.005, worst  # contacts happened, shallow ones


# --------------------------------------------------------------------- heuristic
def test_heuristic_tells_the_agents_apart():
    policy = give_way.HeuristicPolicy()
    #           start left   start right   upper lane   lower lane    in the nook   moving right
    obs = torch.tensor([
        [-2.0, -0.015, 0, 0], [2.0, 0.015, 0, 0], [1.0, 0.03, 0, 0], [-1.0, -0.03, 0, 0],
        [0.03, 0.4, 0, 0], [0.5, 0.0, 0.3, 0],
    ])
    assert policy._is_blue(obs[:, :2], obs[:, 2:]).tolist() == [True, False, True, False, True, True]
    action = policy.compute_action(obs, 0.5)
    assert action[0, 0] > 0.3 and action[1, 0] < -0.2  # blue heads right, green left (slowly)
    assert (torch.linalg.vector_norm(action, dim=-1) <= 0.5 + 1e-6).all()
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 6), 0.5)


def test_heuristic_gives_way_and_both_reach_their_goals():
    """16 envs x 330 steps (seed 0), half heuristic pairs, half random pairs.

    The heuristic pair never touches, and both agents are on their goals at the
    end in every env (measured: all envs by step ~305, return ~8.97 each: 2 x
    4.29 of shaping plus the final rewards). Random pairs stay near their starts
    (measured return ~0.1). Required: every heuristic env done, a gain of 8.
    """
    torch.manual_seed(0)
    env = make(16, seed=0)
    heuristic = give_way.HeuristicPolicy().compute_action
    closest = torch.tensor(1.0)

    def watched(obs, u_range):
        nonlocal closest
        closest = torch.minimum(closest, env.world.get_distance(env.agents[0], env.agents[1])[:8].min())
        return heuristic(obs, u_range)

    returns = harness.play_lineups(env, [[watched, heuristic], [None, None]], steps=330)
    heuristic_return, random_return = returns[0].tolist()
    assert env.scenario.goal_reached[:8].all() and closest > 0.1
    assert heuristic_return > random_return + 8, returns
