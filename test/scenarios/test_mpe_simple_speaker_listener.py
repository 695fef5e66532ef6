"""simple_speaker_listener: construction, spaces, resets, parity with VMAS 1.5.2, semantics vs MPE, heuristic."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from test.scenarios import harness
from vmas_ros.testing import vmas_states
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios.mpe import simple_speaker_listener

NAME = "simple_speaker_listener"


def make(num_envs=8, **kwargs):
    return harness.make(simple_speaker_listener.Scenario(), num_envs, **kwargs)




# ------------------------------------------------------------------ construction
def test_construction_and_unknown_kwargs_warn():
    env = make()
    assert [a.name for a in env.agents] == ["speaker_0", "listener_0"]
    assert [l.name for l in env.world.landmarks] == ["landmark 0", "landmark 1", "landmark 2"]
    assert env.world.dim_c == 3 and not env.agents[0].movable and env.agents[1].silent
    with pytest.warns(UserWarning, match="not used"):
        make(n_agents=4)  # upstream has no kwargs at all


@pytest.mark.parametrize("mode", harness.SPACE_MODES.values(), ids=harness.SPACE_MODES.keys())
def test_spaces_match_upstream_and_random_rollout_is_finite(mode):
    ours, up = make(**mode), harness.make_upstream(NAME, 8, **mode)
    steps = 200 if not mode else 30  # the long run in the default mode, short ones in the others
    harness.check_spaces(ours, up, steps, gen=torch.Generator().manual_seed(0), as_dict=mode.get("dict_spaces", False))


def test_heuristic_rollout_is_finite():
    env = make(num_envs=16)
    policy = simple_speaker_listener.HeuristicPolicy(continuous_action=True)
    harness.play_lineups(env, [[policy.compute_action] * env.n_agents], steps=200)


# ------------------------------------------------------------------------ resets
def scenario_state(env):
    """The per-env scenario state a reset clears (the speaker's message) or redraws (the goal)."""
    return {"speaker.c": env.scenario.speaker.state.c, "goal": env.scenario.goal}


@pytest.mark.parametrize("index", [3, [1, 5], "mask"], ids=["int", "list", "mask"])
def test_reset_at_resets_exactly_the_selected_envs(index):
    env = make(num_envs=8)
    harness.random_steps(env, 5, torch.Generator().manual_seed(1))
    seen = harness.check_reset_at(env, index, mask_rows=[0, 3, 4], scenario_state=scenario_state, bound=1)
    assert (env.scenario.speaker.state.c[seen.chosen] == 0).all()
    # the speaker is told the colour of its own env's goal
    torch.testing.assert_close(seen.obs[0], env.scenario.palette[env.scenario.goal])


def test_every_env_draws_its_own_goal():
    env = make(num_envs=64)
    assert len(env.scenario.goal.unique()) == 3


# ------------------------------------------------------------------------ parity
@pytest.mark.parametrize("mode", [dict(), dict(continuous_actions=False)], ids=["continuous", "discrete"])
def test_parity_with_upstream_vmas(mode):
    up, ours = harness.make_upstream(NAME, 16, **mode), make(16, **mode)
    harness.copy_start(up, ours, vmas_states.simple_speaker_listener)
    seen = run_lockstep(up, ours, seed=2, actions=lambda gen: harness.space_actions(ours, gen), speakers=[0])
    assert seen.loudest_message > 0.5  # the message channel was exercised


# --------------------------------------------------------------------- semantics
def test_rewards_and_observations_agree_with_mpe():
    """MPE (mpe2) is the reference for what the task means.

    Observations are the same. Rewards differ on purpose, as in VMAS 1.5:
    MPE gives each agent ``-d^2`` (d = listener-to-goal distance), VMAS gives
    both agents ``-2 d``, so ours must equal ``-2 * sqrt(-r_mpe)``.
    """
    from mpe2 import simple_speaker_listener_v4

    ours = make(num_envs=8)
    mpe, world, scenario = harness.make_mpe(simple_speaker_listener_v4.parallel_env, ours, continuous_actions=True)
    gen = torch.Generator().manual_seed(3)
    for _ in range(3):
        obs, rews, _, _ = ours.step(harness.space_actions(ours, gen))
    for b in range(ours.num_envs):
        harness.copy_env_to_mpe(ours, world, b, velocities=True)
        world.agents[0].state.c = ours.agents[0].state.c[b].double().numpy()
        world.agents[0].goal_b = world.landmarks[int(ours.scenario.goal[b])]
        for i, agent in enumerate(world.agents):
            np.testing.assert_allclose(obs[i][b].numpy(), scenario.observation(agent, world), atol=1e-5)
            expected = -2 * np.sqrt(-scenario.reward(agent, world))
            assert float(rews[i][b]) == pytest.approx(expected, abs=1e-5)


# --------------------------------------------------------------------- heuristic
def mean_return(env, policy, steps=100):
    """The shared return (agent 0's), mean over envs, every agent on ``policy`` (random if None)."""
    return harness.team_returns(env, policy, lambda a: policy is not None, steps)[0]


def test_heuristic_beats_random():
    """64 envs x 100 steps of the shared reward -2 d.

    A random listener drifts around its start, about 1 from the goal: roughly
    -2 x 1 x 100 = -200. The heuristic listener is told the goal after one
    step and reaches it in about 20, so it should lose under a third of that
    (measured about -42 vs -200).
    """
    env = make(num_envs=64)
    heuristic = mean_return(env, simple_speaker_listener.HeuristicPolicy())
    random = mean_return(env, None)
    assert heuristic > random / 3, (heuristic, random)
    assert float(env.scenario._goal_distance().mean()) > 0.3  # random leaves the listener away from the goal
    mean_return(env, simple_speaker_listener.HeuristicPolicy())
    assert float(env.scenario._goal_distance().max()) < 0.05  # the heuristic parks every listener on its goal


def test_heuristic_message_is_the_goal_index():
    policy = simple_speaker_listener.HeuristicPolicy()
    colours = torch.tensor(simple_speaker_listener.LANDMARK_COLORS)
    action = policy.compute_action(colours, u_range=1.0)
    assert torch.equal(action, torch.cat([torch.zeros(3, 2), torch.eye(3)], dim=1))
    with pytest.raises(ValueError, match="continuous"):
        simple_speaker_listener.HeuristicPolicy(continuous_action=False)
