"""``buzz_wire``: API, parity with VMAS 1.5.2 (states, observations, rewards, info, done), resets, heuristic.

Oracle: ``vmas`` 1.5.2, free-running from upstream's own start (its rods'
states copied last: placing an agent re-places its rod).
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import parity, vmas_states
from vmas_ros.scenarios import buzz_wire

NAME = "buzz_wire"
CUSTOM = {"random_start_angle": False, "pos_shaping_factor": 2.0, "collision_reward": -3.0, "max_speed_1": 0.05}


def make(num_envs: int = 4, **kwargs):
    return harness.make(buzz_wire.Scenario(), num_envs, **kwargs)


# ------------------------------------------------------------------- construction
def test_construction():
    env = make(2)
    world = env.world
    landmarks = ["goal", "ball", "joint agent_0 ball", "joint agent_1 ball", "wall 0", "wall 1", "floor 0", "floor 1"]
    assert [e.name for e in world.entities] == landmarks + ["agent_0", "agent_1"]
    assert (world.dt, world.substeps, world.drag, world.joint_force, world.collision_force) == (0.1, 15, 0.25, 900.0, 1500.0)
    assert all(a.shape.radius == 0.03 and a.mass == 1 and a.u_multiplier == 1 for a in env.agents)
    assert env.agents[0].max_speed is None and env.agents[1].max_speed is None
    assert all(j.dist == 0.25 and not j.landmark.collide for j in env.scenario.joints)
    lines = env.scenario.lines
    assert [l.shape.length for l in lines] == [2.0, 2.0, 0.25, 0.25] and all(l.collide for l in lines)
    torch.testing.assert_close(torch.stack([l.state.pos[0] for l in lines]), torch.tensor([[-0.125, 0.0], [0.125, 0.0], [0.0, -1.0], [0.0, 1.0]]))
    s = env.scenario
    assert (s.random_start_angle, s.pos_shaping_factor, s.collision_reward, s.max_speed_1) == (True, 1, -10, None)
    assert make(2, max_speed_1=0.05).agents[1].max_speed == 0.05


def test_unknown_kwargs_warn_and_bad_values_raise():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for name, bad in (("random_start_angle", 1), ("pos_shaping_factor", "x"), ("collision_reward", math.inf), ("max_speed_1", 0)):
        with pytest.raises(ValueError, match=name):
            make(2, **{name: bad})
    with pytest.raises(ValueError, match="max_speed_1"):
        buzz_wire.HeuristicPolicy(max_speed_1=-1.0)


@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream(mode):
    harness.check_spaces(make(2, **SPACE_MODES[mode]), harness.make_upstream(NAME, 2, **SPACE_MODES[mode]), steps=2)


# ------------------------------------------------------------------------- parity
@pytest.mark.parametrize("kwargs", [{}, CUSTOM], ids=["default", "custom"])
def test_matches_upstream_vmas(kwargs):
    """Random actions biased to the right: the ball hits the wall, so collisions and done are exercised."""
    up, ours = harness.make_upstream(NAME, 4, **kwargs), make(4, **kwargs)
    harness.copy_start(up, ours, vmas_states.buzz_wire)
    parity.assert_same_state(up, ours, 0)
    gen, penalties, dones = torch.Generator().manual_seed(0), 0.0, 0
    for step in range(1, 31):
        actions = [(a + torch.tensor([0.5, 0.0])).clamp(-1, 1) for a in parity.uniform_actions(up, gen)]
        obs_up, rew_up, done_up, info_up = up.step([a.clone() for a in actions])
        obs, rew, done, info = ours.step([a.clone() for a in actions])
        parity.assert_same_state(up, ours, step)
        parity.assert_same_outputs(step, (obs, rew, done, info), (obs_up, rew_up, done_up, info_up))
        penalties, dones = min(penalties, float(info[0]["collision_rew"].min())), dones + int(done.sum())
    assert penalties <= kwargs.get("collision_reward", -10) and dones > 0


def test_done_when_the_ball_is_on_the_goal():
    env = make(2, random_start_angle=False)
    goal = env.scenario.goal.state.pos
    env.scenario.ball.set_pos(goal + torch.tensor([[0.0, 0.005], [0.0, 0.02]]), batch_index=None)
    assert env.done().tolist() == [True, False]


# ------------------------------------------------------------------------- resets
def test_start_geometry():
    env = make(64)
    ball, goal = env.scenario.ball.state.pos, env.scenario.goal.state.pos
    assert (ball[:, 0].abs() <= 0.03).all() and (ball[:, 1] >= -0.94).all() and (ball[:, 1] <= -0.03).all()
    assert (goal[:, 0].abs() <= 0.03).all() and (goal[:, 1] >= -0.03).all() and (goal[:, 1] <= 0.94).all()
    a0, a1 = (a.state.pos - ball for a in env.agents)
    torch.testing.assert_close(a0, -a1)
    torch.testing.assert_close(a0.norm(dim=-1), torch.full((64,), 0.25))
    angle = torch.atan2(a1[:, 1], a1[:, 0])
    assert angle.abs().max() <= math.pi / 6 + 1e-5 and angle.abs().max() > 0.4  # drawn in [-pi/6, pi/6]
    rods = [j.landmark for j in env.scenario.joints]
    torch.testing.assert_close(rods[0].state.pos, ball + a0 / 2)
    torch.testing.assert_close(rods[1].state.rot[:, 0], angle + math.pi)
    torch.testing.assert_close(env.scenario.pos_shaping, (ball - goal).norm(dim=-1))
    level = make(8, random_start_angle=False)
    offsets = level.agents[1].state.pos - level.scenario.ball.state.pos
    torch.testing.assert_close(offsets, torch.tensor([[0.25, 0.0]]).expand(8, 2))


@pytest.mark.parametrize("index", [1, [0, 3], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(6)
    gen = torch.Generator().manual_seed(1)
    for _ in range(3):
        env.step([torch.rand(6, 2, generator=gen) * 2 - 1 for _ in env.agents])
    env.scenario.collided[:] = True  # as if all had touched a wall: a reset must clear the chosen
    for line in env.scenario.lines:  # off their places, so a reset must put every one back
        line.set_pos(line.state.pos + 0.01, batch_index=None)
    state = lambda env: {"shaping": env.scenario.pos_shaping, "collided": env.scenario.collided}  # noqa: E731
    check = harness.check_reset_at(env, index, mask_rows=slice(None, None, 2), scenario_state=state, bound=1.07)
    chosen = check.chosen
    assert not check.after["collided"][chosen].any()
    ball, goal = env.scenario.ball.state.pos[chosen], env.scenario.goal.state.pos[chosen]
    torch.testing.assert_close(check.after["shaping"][chosen], (ball - goal).norm(dim=-1))


# --------------------------------------------------------------------- heuristic
def test_heuristic_heads_for_its_side_of_the_goal():
    policy = buzz_wire.HeuristicPolicy()
    #             pos          vel       pos - goal
    left = [-0.25, -0.5, 0.0, 0.0, -0.25, -0.6]  # in place sideways, below the goal: straight up
    right_far = [0.4, 0.3, 0.0, 0.0, 0.4, 0.0]  # level, too far out: inwards
    action = policy.compute_action(torch.tensor([left, right_far]), 1.0)
    assert action.shape == (2, 2) and (action.abs() <= 1).all()
    assert action[0, 1] > 0.5 and action[0, 0].abs() < 1e-6
    assert action[1, 0] < -0.3 and action[1, 1].abs() < 1e-6
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 8), 1.0)


def test_heuristic_beats_random():
    """16 envs x 150 steps (seed 0), 8 heuristic, 8 random.

    Measured: heuristic ~ +0.66 per agent (the ball carried up the channel
    without touching it), random ~ -66 (rods swing the ball and agents into
    the walls, -10 per touch and step).
    """
    torch.manual_seed(0)
    env = make(16)
    heuristic = buzz_wire.HeuristicPolicy().compute_action
    returns = harness.play_lineups(env, [[heuristic, heuristic], [None, None]], steps=150)
    heuristic_return, random_return = returns.mean(dim=0).tolist()
    assert heuristic_return > 0.3 and heuristic_return > random_return + 20, returns
