"""MPE ``simple_push``: API, parity with VMAS 1.5.2, semantics against MPE (mpe2), heuristic.

Oracles: ``vmas`` (same start and goal -> same obs, rewards and states) and
``mpe2.simple_push_v3`` (reward and observation definitions, goal colours).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch
from mpe2 import simple_push_v3

from test.scenarios import harness
from test.scenarios.harness import ACTION_MODES
from vmas_ros.testing import vmas_states
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios.mpe import simple_push
from vmas_ros.simulator.heuristic_policy import RandomPolicy

NAME = "simple_push"
BATCH = 16


def make(num_envs: int = BATCH, **kwargs):
    return harness.make(simple_push.Scenario(), num_envs, **kwargs)


def expected_agent_color(goal: torch.Tensor) -> torch.Tensor:
    """MPE's rule: grey 0.25 with +0.5 on the goal landmark's channel (goal + 1)."""
    color = torch.full((len(goal), 3), 0.25)
    color[torch.arange(len(goal)), goal + 1] += 0.5
    return color


# ------------------------------------------------------------------- construction
def test_construction():
    env = make(64)
    assert [a.name for a in env.agents] == ["adversary_0", "agent_0"]
    assert [a.adversary for a in env.agents] == [True, False] and all(a.collide for a in env.agents)
    assert [l.name for l in env.world.landmarks] == ["landmark 0", "landmark 1"]
    assert not any(l.collide for l in env.world.landmarks)
    torch.testing.assert_close(env.world.landmarks[0].color, torch.tensor([0.1, 0.9, 0.1]))
    torch.testing.assert_close(env.world.landmarks[1].color, torch.tensor([0.1, 0.1, 0.9]))
    torch.testing.assert_close(env.agents[0].color, torch.tensor([0.75, 0.25, 0.25]))
    goal = env.scenario.goal_index
    assert goal.shape == (64,) and set(goal.tolist()) == {0, 1}  # drawn per env
    torch.testing.assert_close(env.agents[1].color, expected_agent_color(goal))


def test_unknown_kwargs_warn():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("dict_spaces", [False, True])
@pytest.mark.parametrize("mode", list(ACTION_MODES))
def test_spaces_match_upstream_and_actions_work(mode, dict_spaces):
    options = dict(ACTION_MODES[mode], dict_spaces=dict_spaces)
    obs, _ = harness.check_spaces(make(4, **options), harness.make_upstream(NAME, 4, **options), steps=3)
    values = list(obs.values()) if dict_spaces else obs
    assert [tuple(v.shape) for v in values] == [(4, 8), (4, 19)] and all(torch.isfinite(v).all() for v in values)


# -------------------------------------------------------------------------- reset
@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(32)
    for _ in range(5):
        env.step([torch.ones(32, 2)] * 2)
    goal_of = lambda env: {"goal": env.scenario.goal_index}  # noqa: E731 (kept in the other envs)
    chosen = harness.check_reset_at(env, index, mask_rows=slice(None, None, 2), scenario_state=goal_of).chosen
    goal = env.scenario.goal_index
    torch.testing.assert_close(env.agents[1].color, expected_agent_color(goal))
    if chosen.sum() > 8:
        assert set(goal[chosen].tolist()) == {0, 1}  # redrawn, not copied


def test_long_rollouts_stay_finite():
    """200 steps, half the envs on random actions, half on the heuristic."""
    random, heuristic = RandomPolicy().compute_action, simple_push.HeuristicPolicy().compute_action
    harness.play_lineups(make(8), [[random, random], [heuristic, heuristic]], steps=200)


# ------------------------------------------------------------------------- parity
def test_matches_upstream_vmas():
    up, ours = harness.make_upstream(NAME, BATCH), make()
    harness.copy_start(up, ours, vmas_states.simple_push)
    torch.testing.assert_close(ours.agents[1].color[0], up.world.agents[1].color)
    run_lockstep(up, ours, seed=0)


def test_set_goal_selected_envs():
    env = make(6)
    env.scenario.set_goal(torch.tensor(0))
    env.scenario.set_goal(torch.tensor([1, 1]), env_index=torch.tensor([2, 4]))
    assert env.scenario.goal_index.tolist() == [0, 0, 1, 0, 1, 0]
    torch.testing.assert_close(env.agents[1].color, expected_agent_color(env.scenario.goal_index))
    env.scenario.set_goal(1, env_index=0)
    assert env.scenario.goal_index.tolist() == [1, 0, 1, 0, 1, 0]
    with pytest.raises(ValueError, match="goal_index"):
        env.scenario.set_goal(2)


# ---------------------------------------------------------------------- semantics
def test_rewards_and_observations_match_mpe():
    """Same state and goal -> MPE's rewards (through PettingZoo's parallel API) and observations.

    Each configuration comes from a seeded MPE reset (so MPE picks the goal and
    colours itself); we then move the agents (some onto the goal) and copy the
    state and the goal into one env of ours. With everything at rest and no-op
    actions MPE's explicit Euler step leaves positions unchanged, so the rewards
    it returns are those of the state we set.
    """
    n = 24
    gen = torch.Generator().manual_seed(5)
    ours = make(n)
    mpe, world, scenario = harness.make_mpe(simple_push_v3.parallel_env, ours, continuous_actions=True, max_cycles=10)
    names = [a.name for a in world.agents]
    goals, states, rew_mpe, obs_mpe = [], [], [], []
    for k in range(n):
        mpe.reset(seed=k)
        goal = world.landmarks.index(world.agents[1].goal_a)
        agents = torch.rand(2, 2, generator=gen) * 2 - 1
        if k % 3 == 0:  # put the good agent near its goal
            agents[1] = torch.as_tensor(world.landmarks[goal].state.p_pos) + 0.05
        vel = torch.rand(2, 2, generator=gen) - 0.5
        landmarks = torch.tensor(np.stack([l.state.p_pos for l in world.landmarks]), dtype=torch.float32)
        for i, a in enumerate(world.agents):
            a.state.p_pos, a.state.p_vel = agents[i].double().numpy(), vel[i].double().numpy()
        obs_mpe.append([scenario.observation(a, world) for a in world.agents])
        for a in world.agents:
            a.state.p_vel = np.zeros(2)
        _, rewards, _, _, _ = mpe.step({name: np.zeros(5, dtype=np.float32) for name in names})
        rew_mpe.append([rewards[name] for name in names])
        goals.append(goal)
        states.append((agents, vel, landmarks))
    assert set(goals) == {0, 1}
    ours.scenario.set_goal(torch.tensor(goals))
    for i, a in enumerate(ours.agents):
        a.set_pos(torch.stack([s[0][i] for s in states]), batch_index=None)
    for j, l in enumerate(ours.world.landmarks):
        l.set_pos(torch.stack([s[2][j] for s in states]), batch_index=None)
    rew_ours = ours.get_from_scenario(False, True, False, False)[0]
    for i, a in enumerate(ours.agents):
        a.set_vel(torch.stack([s[1][i] for s in states]), batch_index=None)
    obs_ours = ours.get_from_scenario(True, False, False, False)[0]
    for i in range(2):
        np.testing.assert_allclose(rew_ours[i].numpy(), [r[i] for r in rew_mpe], atol=1e-5)
        np.testing.assert_allclose(obs_ours[i].numpy(), np.stack([o[i] for o in obs_mpe]), atol=1e-5)


# ---------------------------------------------------------------------- heuristic
def test_heuristic_adversary_guards_the_likely_goal():
    env = make(1)
    env.scenario.set_goal(torch.tensor(1))
    for e, xy in zip(env.world.entities, [(-0.8, 0.0), (0.8, 0.0), (0.0, 0.5), (0.4, 0.0)]):
        e.set_pos(torch.tensor([xy]), batch_index=None)  # landmarks, adversary, good agent
    obs = env.get_from_scenario(True, False, False, False)[0]
    policy = simple_push.HeuristicPolicy()
    adversary, good = (policy.compute_action(o, 1.0)[0] for o in obs)
    assert good[0] > 0.9  # the good agent heads right, to landmark 1
    assert adversary[0] > 0.5 and adversary[1] < -0.5  # the adversary heads for (0.7, 0), before landmark 1
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 5), 1.0)


def test_heuristic_beats_random():
    """64 envs x 100 steps per line-up; agents are [adversary, good agent].

    * Good agent, against a random adversary: random actions keep it about one
      unit from its goal (measured return ~-104); the heuristic gets there in
      ~2 s (~-18). Require a 3x smaller cost.
    * Adversary, against the heuristic good agent: a random adversary wanders
      off the goal (measured ~-90); guarding the landmark nearest the good agent
      keeps its own distance small and the good agent off the goal (~-8).
      Require a gain of 40.
    """
    torch.manual_seed(0)
    heuristic, rand = simple_push.HeuristicPolicy().compute_action, RandomPolicy().compute_action
    lineups = [[rand, heuristic], [rand, rand], [heuristic, heuristic]]
    returns = torch.cat([harness.play_lineups(make(64), [lineup]) for lineup in lineups], dim=1)
    (adv_random, _, adv_heuristic), (good_heuristic, good_random, _) = returns.tolist()
    assert good_heuristic > good_random / 3, returns
    assert adv_heuristic > adv_random + 40, returns
