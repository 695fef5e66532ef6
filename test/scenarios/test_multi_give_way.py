"""``multi_give_way``: API, parity with VMAS 1.5.2, map and reset, heuristic.

Oracle: ``vmas`` 1.5.2 (same start -> same obs, rewards, infos and states, with
the velocity controller, contacts between agents and walls, and every reward
term switched on). Upstream is slow on this 20-entity world, so the runs are short.
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import parity, vmas_states
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios import multi_give_way

NAME = "multi_give_way"
GOALS = torch.tensor([[0.0, -2.29], [-2.29, 0.0], [0.0, 2.29], [2.29, 0.0]])
STARTS = torch.tensor([[-2.0, 0.0], [0.0, 2.0], [2.0, 0.0], [0.0, -2.0]])


def make(num_envs: int = 4, **kwargs):
    return harness.make(multi_give_way.Scenario(), num_envs, **kwargs)


# ------------------------------------------------------------------- construction
def test_construction_defaults():
    env = make(2)
    world = env.world
    assert [a.name for a in env.agents] == [f"agent_{i}" for i in range(4)]
    walls = [f"wall {i}" for i in range(8)] + [f"short wall {i}" for i in range(4)]
    assert [l.name for l in world.landmarks] == [f"goal {i}" for i in range(4)] + walls
    assert (world.dt, world.substeps, world.drag, world.collision_force) == (0.1, 5, 0.0, 500)
    for agent in env.agents:
        assert agent.shape.radius == 0.16 and not agent.rotatable and agent.collide
        assert (agent.u_range, agent.f_range, agent.v_range, agent.linear_friction) == (0.5, 1.1, None, 0.1)
        assert isinstance(agent.controller, multi_give_way.VelocityController)
    assert not any(l.collide for l in world.landmarks[:4]) and all(l.collide for l in world.landmarks[4:])
    # the cross: side walls 2.3 long at +-0.2 off each axis, end caps 0.4 long at +-2.5
    c, h, v = 1.35, 0.2, math.pi / 2
    expected = [
        (-c, -h, 0), (-c, h, 0), (c, -h, 0), (c, h, 0), (-h, -c, v), (h, -c, v), (-h, c, v), (h, c, v),
        (-2.5, 0, v), (2.5, 0, v), (0, -2.5, 0), (0, 2.5, 0),
    ]
    for wall, (x, y, rot) in zip(world.landmarks[4:], expected, strict=True):
        assert wall.shape.length == pytest.approx(0.4 if "short" in wall.name else 2.3)
        torch.testing.assert_close(wall.state.pos, torch.tensor([[x, y]] * 2))
        torch.testing.assert_close(wall.state.rot, torch.full((2, 1), float(rot)))
    for i, agent in enumerate(env.agents):
        torch.testing.assert_close(agent.state.pos, STARTS[i].expand(2, 2))
        torch.testing.assert_close(agent.goal.state.pos, GOALS[i].expand(2, 2))
    assert env.observation_space.spaces[0].shape == (7,)


def test_construction_box_agents():
    env = make(2, box_agents=True, a_range=2.0, linear_friction=0.2, u_range=0.3)
    assert (env.world.substeps, env.world.collision_force) == (16, 10000)
    for agent in env.agents:
        assert (agent.shape.length, agent.shape.width) == (0.32, 0.24)
        assert (agent.u_range, agent.f_range, agent.linear_friction) == (0.3, pytest.approx(2.2), 0.2)


def test_unknown_kwargs_warn_and_bad_values_raise():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for bad in ({"u_range": 0}, {"a_range": -1}, {"obs_noise": -0.1}, {"min_input_norm": -1}, {"n_agents": 5}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            make(2, **bad)
    with pytest.raises(TypeError, match="v_range"):
        multi_give_way.HeuristicPolicy(v_range=1)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode):
    options = SPACE_MODES[mode]
    harness.check_spaces(make(2, **options), harness.make_upstream(NAME, 2, **options), steps=2)


def test_observation_layout_and_noise():
    env = make(3)
    obs = env.reset()
    for i, o in enumerate(obs):
        expected = torch.cat([STARTS[i], torch.zeros(2), STARTS[i] - GOALS[i], (STARTS[i] - GOALS[i]).norm().view(1)])
        torch.testing.assert_close(o, expected.expand(3, 7))
    noisy = make(3, obs_noise=0.05).reset()
    deviation = torch.stack([n - o for n, o in zip(noisy, obs)])
    assert (deviation.abs() <= 0.05).all() and deviation.std() > 0.01


# ------------------------------------------------------------------------- parity
def crowd(batch: int):
    """A copy_start hook: agents near the crossing (so they touch each other and the walls);
    in env 0 instead all of them on their goals, so ``final_rew`` is paid there."""

    def place(up, ours) -> None:
        gen = torch.Generator().manual_seed(5)
        for i, (a_up, a_ours) in enumerate(zip(up.world.agents, ours.world.agents)):
            arm = STARTS[i] / 2.0
            pos = arm * (0.12 + 0.15 * torch.rand(batch, 1, generator=gen)) + (torch.rand(batch, 2, generator=gen) - 0.5) * 0.06
            pos[0] = GOALS[i] + 0.02
            for a in (a_up, a_ours):
                a.set_pos(pos.clone(), batch_index=None)
            a_up.shaping = torch.linalg.vector_norm(pos - a_up.goal.state.pos, dim=-1) * up.scenario.pos_shaping_factor
        vmas_states.multi_give_way(up, ours)

    return place


def compare_infos(up, ours, batch: int) -> None:
    """One more step with zero commands: same infos, same (never) done."""
    _, _, dones_up, info_up = up.step([torch.zeros(batch, 2)] * 4)
    _, _, dones, info = ours.step([torch.zeros(batch, 2)] * 4)
    assert torch.equal(dones, dones_up) and not dones.any()
    parity.assert_same_infos(info, info_up)


def test_matches_upstream_vmas():
    up, ours = harness.make_upstream(NAME, 4), make(4)
    harness.copy_start(up, ours, vmas_states.multi_give_way)
    seen = run_lockstep(up, ours, seed=0, steps=30)
    assert seen.fastest > 0.2 and seen.largest_reward > 0.02
    compare_infos(up, ours, 4)


@pytest.mark.parametrize("options, steps", [
    ({"shared_rew": False, "agent_collision_penalty": -1.0, "final_reward": 0.05}, 20),
    ({"pos_shaping_factor": 0, "min_input_norm": 0.3, "u_range": 0.8, "a_range": 2}, 20),
    ({"box_agents": True}, 4),  # 16 substeps: upstream is slow
], ids=["per-agent-rew", "no-shaping", "box-agents"])
def test_matches_upstream_vmas_in_contact(options, steps):
    """Agents start crowded at the crossing (env 0: on their goals): contacts between agents
    and with the wall corners, the collision penalty, the final reward and the infos must agree."""
    batch = 4
    up, ours = harness.make_upstream(NAME, batch, **options), make(batch, **options)
    harness.copy_start(up, ours, crowd(batch))
    seen = run_lockstep(up, ours, seed=1, steps=steps)
    # a collision penalty was paid: no other term comes near its size here
    assert seen.largest_reward >= 0.9 * abs(options.get("agent_collision_penalty", -0.1))
    compare_infos(up, ours, batch)
    if not options.get("box_agents"):
        assert ours.scenario.reached_goal[0] and not ours.scenario.reached_goal[1:].any()


# -------------------------------------------------------------------------- reset
def scenario_state(env) -> dict:
    state = {"shaping": env.scenario.shaping, "reached_goal": env.scenario.reached_goal}
    for agent in env.agents:
        state[f"{agent.name}.pid"] = agent.controller.accum_errs
    return state


@pytest.mark.parametrize("index", [2, [0, 3], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(5)
    gen = torch.Generator().manual_seed(1)
    for _ in range(3):
        env.step([torch.rand(5, 2, generator=gen) - 0.5 for _ in env.agents])
    env.scenario.reached_goal[:] = True
    for e in env.world.entities:  # knock everything off its start, so that a reset must visibly put it back
        e.set_pos(e.state.pos + torch.rand(5, 2, generator=gen) * 0.1 + 0.01, batch_index=None)
    check = harness.check_reset_at(env, index, mask_rows=[1, 4], scenario_state=scenario_state, bound=2.5)
    chosen = check.chosen
    fresh = make(1)
    for mine, new in zip(env.world.entities, fresh.world.entities, strict=True):
        torch.testing.assert_close(mine.state.pos[chosen], new.state.pos.expand(int(chosen.sum()), 2))
    expected = torch.linalg.vector_norm(STARTS - GOALS, dim=-1)
    torch.testing.assert_close(check.after["shaping"][chosen], expected.expand(int(chosen.sum()), 4))
    assert not check.after["reached_goal"][chosen].any()
    assert all((check.after[f"{a.name}.pid"][chosen] == 0).all() for a in env.agents)


# --------------------------------------------------------------------- heuristic
def test_heuristic_roles_and_action_range():
    policy = multi_give_way.HeuristicPolicy()
    env = make(1)
    obs = torch.cat(env.reset())  # the four agents at their starts
    action = policy.compute_action(obs, 0.5)
    assert action.shape == (4, 2) and (torch.linalg.vector_norm(action, dim=-1) <= 0.5 + 1e-6).all()
    inward = -(action * STARTS / 2).sum(-1)  # speed towards the centre
    torch.testing.assert_close(inward, torch.tensor([0.25, 0.17, 0.5, 0.5]))  # agent 1 waits longest
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 6), 0.5)


def test_heuristic_beats_random():
    """4 envs x 150 steps (seed 0), two of heuristic line-ups, two random.

    The heuristic agents never touch, and agent 0 ends on its goal (agent 1
    reaches its own by step ~170, for a return of ~7.9). Measured returns
    (shared, each agent): heuristic 6.8, random -0.02. Required: the
    heuristic ahead by 5.
    """
    torch.manual_seed(0)
    env = make(4, seed=0)
    heuristic = multi_give_way.HeuristicPolicy().compute_action
    closest = torch.tensor(1.0)

    def watched(obs, u_range):
        nonlocal closest
        agents = env.agents
        gaps = [env.world.get_distance(a, b)[:2].min() for i, a in enumerate(agents) for b in agents[i + 1:]]
        closest = torch.minimum(closest, torch.stack(gaps).min())
        return heuristic(obs, u_range)

    returns = harness.play_lineups(env, [[watched, heuristic, heuristic, heuristic], [None] * 4], steps=150)
    heuristic_return, random_return = returns[0].tolist()
    assert closest > 0.02
    assert (torch.linalg.vector_norm(env.agents[0].state.pos[:2] - GOALS[0], dim=-1) < 0.08).all()
    assert heuristic_return > random_return + 5, returns
