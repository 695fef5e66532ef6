"""``joint_passage_size``: API, parity with VMAS 1.5.2, resets, heuristic.

Oracle: ``vmas`` 1.5.2 (same start and scenario state -> same states,
observations, rewards, ``info`` and ``done``); free-running over the steps
compared, no resync (see ``test_joint_passage.py``). Two deliberate reward
differences, each pinned down here against upstream: ``pos_shaping_factor``
scales the distance to the gaps once (VMAS squares it in its steps), and the
wall contacts of every body count (VMAS counts those of the last body only).
Shared helpers come from ``test_joint_passage.py``.
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from test.scenarios.test_joint_passage import (
    compare_steps, heuristic_actions, place_upright, reset_at_check, scenario_state,
)
from vmas_ros.testing import parity, vmas_states
from vmas_ros.scenarios import joint_passage_common as common
from vmas_ros.scenarios import joint_passage_size as jps
from vmas_ros.simulator.heuristic_policy import RandomPolicy

NAME = "joint_passage_size"
LAYOUT = ("big_passage_pos", "small_passage_pos", "pass_center", "middle_angle")


def make(num_envs: int = 4, **kwargs):
    return harness.make(jps.Scenario(), num_envs, **kwargs)


def size_state(env) -> dict:
    return {**scenario_state(env), **{name: getattr(env.scenario, name) for name in LAYOUT}}


# ------------------------------------------------------------ construction
def test_construction_and_defaults():
    env = make(2)
    world, scenario = env.world, env.scenario
    names = [e.name for e in world.entities]
    expected = ["joint agent_0 agent_1", "joint_goal"] + [f"wall {i}" for i in range(4)]
    assert names == expected + [f"passage {i}" for i in range(14)] + ["agent_0", "agent_1"]
    assert (world._substeps, world._drag) == (5, 0.25)
    assert [a.shape.radius for a in env.agents] == [common.AGENT_RADIUS, jps.BIG_RADIUS]
    assert all(a.f_range == 10 and a.u_range == 1 and a.u_multiplier == 1 for a in env.agents)
    assert not scenario.rod.collide and scenario.rod.shape.length == 0.52 and scenario.package is None
    assert [b.collide for b in scenario.blocks] == [i >= 3 for i in range(14)]
    assert {k: getattr(scenario, k) for k in jps.DEFAULTS} == jps.DEFAULTS
    heavy = make(2, asym_package=True, n_passages=4)
    assert heavy.world._substeps == 10 and heavy.scenario.package.mass == 1
    assert [b.collide for b in heavy.scenario.blocks][:5] == [False] * 4 + [True]


def test_unknown_kwargs_warn_and_bad_values_raise():
    bad = [{"n_passages": 2}, {"n_passages": 5}, {"joint_length": 2.0}, {"mass_ratio": 0}, {"middle_angle_180": None},
           {"use_vel_controller": "no"}, {"joint_angle_obs_noise": 0.2}, {"pos_shaping_factor": float("nan")}]
    harness.check_kwargs_refused(make, 2, bad)
    with pytest.raises(ValueError, match="n_passages"):
        jps.HeuristicPolicy(n_passages=1)


@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream(mode):
    options = dict(SPACE_MODES[mode], observe_joint_angle=mode == "dict")
    obs, _ = harness.check_spaces(make(2, **options), harness.make_upstream(NAME, 2, **options), steps=2)
    values = list(obs.values()) if isinstance(obs, dict) else obs
    assert [v.shape[1] for v in values] == [14 if mode == "dict" else 12] * 2


# ------------------------------------------------------------------ parity
@pytest.mark.parametrize(
    "kwargs", [{}, dict(asym_package=True, fixed_passage=True, n_passages=4, middle_angle_180=True,
                        random_goal_angle=True, observe_joint_angle=True, rot_shaping_factor=2.0)],
    ids=["default", "custom"],
)
def test_matches_upstream_random_actions(kwargs):
    up, ours = harness.make_upstream(NAME, 4, **kwargs), make(4, **kwargs)
    harness.copy_start(up, ours, vmas_states.joint_passage_size)
    seen = parity.run_lockstep(up, ours, seed=0, steps=50)
    assert seen.largest_reward > 0.01 and seen.fastest > 0.1


def test_matches_upstream_through_the_big_gap():
    """The rod upright, half through the big gap, off its axis by up to 4.4 cm (the big agent touching the barrier); the heuristic (plus
    noise, and a push of the big agent against the barrier) pulls it through with velocity control: barrier contacts of the big agent, ``passed``,
    the energy term, ``info`` and ``done`` compared. ``collision_reward`` is on, with the agents
    far from the walls (where the two count alike)."""
    kwargs = dict(fixed_passage=True, use_vel_controller=True, collision_reward=-1.0, energy_reward_coeff=0.5)
    up, ours = harness.make_upstream(NAME, 4, **kwargs), make(4, **kwargs)
    harness.copy_start(up, ours, vmas_states.joint_passage_size)
    gap_x = float(ours.scenario.big_passage_pos[0, 0])
    x = gap_x + torch.tensor([0.0, 0.0435, -0.03, 0.044])
    place_upright([up, ours], x, upper_y=0.6, length=0.52, agent_1_up=torch.tensor([True, False, True, False]))
    policy = jps.HeuristicPolicy(**kwargs).compute_action
    pressed = torch.tensor([[0.0, 0.0], [0.8, 0.0], [0.0, 0.0], [0.8, 0.0]])  # the big agent against a block
    seen = compare_steps(up, ours, heuristic_actions(policy, bias=[0.0, pressed]), steps=15)
    assert seen["passed"] >= 2 and seen["collision"] >= 1 and seen["energy"] > 0.1


def test_pos_shaping_factor_applies_once():
    """Ours with factor 3 pays exactly 3 x the position shaping of factor 1 along the same run (the
    factor does not change the physics); upstream pays 9 x in the steps before the rod's centre
    passes, after its first step (whose potential comes from the reset, scaled once)."""
    runs = {}
    for factor in (1.0, 3.0):
        up, ours = harness.make_upstream(NAME, 4, pos_shaping_factor=factor), make(4, pos_shaping_factor=factor)
        harness.copy_start(up, ours, vmas_states.joint_passage_size)
        gen = torch.Generator().manual_seed(0)
        runs[factor] = []
        for _ in range(4):
            actions = [torch.rand(4, 2, generator=gen) * 2 - 1 for _ in range(2)]
            _, _, _, info_up = up.step([a.clone() for a in actions])
            _, _, _, info = ours.step([a.clone() for a in actions])
            runs[factor].append((info[0]["pos_rew"], info_up[0]["pos_rew"]))
    for step, ((ours_1, up_1), (ours_3, up_3)) in enumerate(zip(runs[1.0], runs[3.0])):
        torch.testing.assert_close(ours_1, up_1, atol=parity.ATOL, rtol=0)
        torch.testing.assert_close(ours_3, 3 * ours_1, atol=parity.ATOL, rtol=1e-4)
        if step > 0:
            torch.testing.assert_close(up_3, 9 * up_1, atol=parity.ATOL, rtol=1e-4)
    assert float(runs[1.0][1][0].abs().max()) > 1e-3


def test_wall_contacts_count_for_every_body():
    env = make(2, collision_reward=-1.0)
    env.agents[0].set_pos(torch.tensor([[0.99, -0.5], [0.5, -0.5]]), batch_index=None)  # touches wall 0 in env 0
    env.agents[1].set_pos(torch.tensor([[0.47, -0.5], [-0.02, -0.5]]), batch_index=None)
    env.get_from_scenario(False, True, False, False)
    assert env.scenario.collision_rew.tolist() == [-1.0, 0.0]  # VMAS 1.5: agent_0's wall contact unseen


# ------------------------------------------------------------------- resets
@pytest.mark.parametrize("index", [2, [1, 3], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    reset_at_check(make(4), index, size_state)


def test_starting_state_and_layout():
    env = make(32, n_passages=4)
    scenario = env.scenario
    agents = torch.stack([a.state.pos for a in env.agents], dim=1)
    torch.testing.assert_close(agents[:, 0, 0], agents[:, 1, 0])  # upright
    assert (agents[:, 0, 1] > agents[:, 1, 1]).any() and (agents[:, 0, 1] < agents[:, 1, 1]).any()
    assert (agents[..., 1] <= -0.1 - 2 * jps.BIG_RADIUS + 1e-5).all()
    torch.testing.assert_close(scenario.goal.state.rot, torch.full((32, 1), math.pi))
    gaps = torch.stack([b.state.pos[:, 0] for b in scenario.gap_blocks], dim=1)
    slots = ((gaps - common.FIRST_SLOT_X) / common.BLOCK_LENGTH).round().long()
    step = torch.sign(slots[:, 2] - slots[:, 0])
    assert (slots[:, 1] == slots[:, 0] + 1).all() and ((slots[:, 2] - slots[:, 0]).abs() == 3).all()
    assert (slots[:, 3] == slots[:, 2] + step).all() and ((slots >= 0) & (slots < 14)).all()
    torch.testing.assert_close(scenario.middle_angle[:, 0], torch.where(step > 0, math.pi, 0.0))
    torch.testing.assert_close(scenario.small_passage_pos, scenario.gap_blocks[2].state.pos)
    torch.testing.assert_close(scenario.pass_center, (scenario.big_passage_pos + scenario.small_passage_pos) / 2)
    assert len(set(slots[:, 0].tolist())) > 5


# ---------------------------------------------------------------- heuristic
def test_heuristic_unit():
    policy = jps.HeuristicPolicy()
    #          pos          vel       pos - goal    pos - big     pos - small   goal dir
    below_on = [0.0, -0.5, 0.0, 0.0, 0.0, -0.9, 0.0, -0.5, 0.4, -0.5, -1.0, 0.0]
    below_off = [0.3, -0.5, 0.0, 0.0, 0.3, -0.9, 0.3, -0.5, 0.7, -0.5, -1.0, 0.0]
    action = policy.compute_action(torch.tensor([below_on, below_off]), 1.0)
    assert action.shape == (2, 2) and (action.abs() <= 1).all()
    assert action[0, 1] > 0.5 and action[1, 0] < -0.5 and action[1, 1].abs() < 1e-6
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 14), 1.0)


def test_heuristic_beats_random():
    """4 envs each way x 60 steps (seed 0). Measured over 300 steps (16 envs each way): heuristic
    +1.35 per agent vs random -0.20; over these 60 steps +0.42 vs -0.20: required a margin of 0.2."""
    torch.manual_seed(0)
    env = make(8)
    heuristic = jps.HeuristicPolicy().compute_action
    returns = harness.play_lineups(env, [[heuristic] * 2, [RandomPolicy().compute_action] * 2], steps=60)
    heuristic_return, random_return = returns.mean(dim=0).tolist()
    assert heuristic_return > random_return + 0.2, returns
