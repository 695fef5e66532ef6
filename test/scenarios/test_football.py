"""``football``: API, parity with VMAS 1.5.2, resets, long rollouts, the scripted team.

Oracle: ``vmas`` (same start -> same obs, rewards, states and infos). Parity
runs with ``ai_red_agents=False``: upstream's scripted red team draws random
samples inside every step (its position search in ``AgentPolicy``) and ours
is a different (simpler) player, so with red scripted the two worlds diverge
after the first step by design. Everything else (physics, ball script,
kicks, observations, rewards, done) is compared step by step.
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import parity, vmas_states
from vmas_ros.scenarios import football
from vmas_ros.scenarios.football_ai import HeuristicPolicy
from vmas_ros.simulator.utils import LINE_MIN_DIST

NAME = "football"
AI_OFF = {"ai_red_agents": False}
FIXTURES = [
    "Right Top Wall", "Left Top Wall", "Right Bottom Wall", "Left Bottom Wall", "Right Goal Back",
    "Left Goal Back", "Right Goal Top", "Left Goal Top", "Right Goal Bottom", "Left Goal Bottom",
    "Blue Net", "Red Net",
]


def make(num_envs: int = 8, **kwargs):
    return harness.make(football.Scenario(), num_envs, **kwargs)


def players(env) -> list:
    return env.scenario.players


# ------------------------------------------------------------------- construction
def test_construction_defaults_match_upstream():
    env, up = make(4), harness.make_upstream(NAME, 4)
    names = [e.name for e in env.world.entities]
    assert names == [e.name for e in up.world.entities]
    assert names == FIXTURES + [f"agent_blue_{i}" for i in range(3)] + [f"agent_red_{i}" for i in range(3)] + ["Ball"]
    assert [a.name for a in env.agents] == ["agent_blue_0", "agent_blue_1", "agent_blue_2"]  # red is scripted
    world = env.world
    assert (world.dt, world.drag, world.substeps) == (0.1, 0.05, 2)
    assert world.x_semidim == pytest.approx(1.575) and world.y_semidim == pytest.approx(0.725)
    for e_ours, e_up in zip(world.entities, up.world.entities, strict=True):
        assert e_ours.collide == e_up.collide and e_ours.movable == e_up.movable, e_ours.name
        assert e_ours.mass == pytest.approx(e_up.mass) and e_ours.max_speed == e_up.max_speed, e_ours.name
        assert type(e_ours.shape).__name__ == type(e_up.shape).__name__, e_ours.name
        for field in ("pos", "rot"):  # the same RNG draws in the same order: the very same reset
            torch.testing.assert_close(getattr(e_ours.state, field), getattr(e_up.state, field), msg=e_ours.name)
    ball = env.scenario.ball
    assert ball.action_script is not None and ball.shape.radius == 0.02 and ball.mass == 0.25
    assert all(a.action_script is not None for a in env.scenario.red_agents)
    assert (env.scenario.red_agents[0].state.rot == math.pi).all()


def test_construction_custom_kwargs():
    env = make(4, ai_red_agents=False, n_blue_agents=2, n_red_agents=4, enable_shooting=True, dense_reward=False)
    assert [a.name for a in env.agents] == ["agent_blue_0", "agent_blue_1"] + [f"agent_red_{i}" for i in range(4)]
    assert all(a.action_size == 4 and a.u_multiplier == [0.1, 0.1, 0.0003, 0.6] for a in env.agents)
    obs = env.reset()
    assert [o.shape[1] for o in obs] == [17 + 8 * 5] * 6
    env = make(2, n_blue_agents=5, physically_different=True, n_traj_points=2, ai_blue_agents=True, ai_red_agents=False)
    radii = [a.shape.radius for a in env.scenario.blue_agents]
    assert radii == pytest.approx([0.02, 0.02, 0.025, 0.025, 0.035])
    assert [a.max_speed for a in env.scenario.blue_agents] == pytest.approx([0.2, 0.2, 0.15, 0.15, 0.05])
    markers = [e.name for e in env.world.landmarks[len(FIXTURES):]]
    assert markers == [f"Blue {i} Trajectory {j}" for i in range(5) for j in range(2)]
    env.step(env.get_random_actions())  # the scripted blue team moves its markers onto its plans
    first = env.scenario.blue_agents[0]
    torch.testing.assert_close(env.world.landmarks[len(FIXTURES)].state.pos, first.state.pos - first.state.vel * 0.1, atol=0.02, rtol=0)


def test_unknown_kwargs_warn():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)


@pytest.mark.parametrize("bad", [
    {"n_blue_agents": 0}, {"n_red_agents": 1.5}, {"physically_different": True}, {"pitch_width": -1.0},
    {"ai_strength": 1.5}, {"ai_decision_strength": (1.0, -0.1)}, {"shooting_angle": 0}, {"dense_reward_ratio": 0.5},
    {"goal_size": 2.0}, {"n_traj_points": -1},
])
def test_bad_kwargs_raise(bad):
    with pytest.raises(ValueError, match=next(iter(bad)).split("_ratio")[0]):
        make(2, **bad)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("kwargs", [{}, {"ai_red_agents": False, "enable_shooting": True}], ids=["default", "shooting"])
@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode, kwargs):
    options = {**SPACE_MODES[mode], **kwargs}
    harness.check_spaces(make(4, **options), harness.make_upstream(NAME, 4, **options), steps=3,
                         gen=torch.Generator().manual_seed(0), as_dict=mode == "dict")


@pytest.mark.parametrize("dict_spaces", [False, True])
def test_dict_obs_spaces_match_upstream(dict_spaces):
    """``dict_obs``: each observation is a dict of blocks (the harness's stepper takes tensors only)."""
    ours, up = make(4, dict_obs=True, dict_spaces=dict_spaces), harness.make_upstream(NAME, 4, dict_obs=True, dict_spaces=dict_spaces)
    harness.assert_same_space(ours.observation_space, up.observation_space, "observation_space")
    harness.assert_same_space(ours.action_space, up.action_space, "action_space")
    for _ in range(3):
        obs, _, _, _ = ours.step(ours.get_random_actions())
    first = obs["agent_blue_0"] if dict_spaces else obs[0]
    assert {k: tuple(v.shape) for k, v in first.items()} == {
        "obs": (4, 12), "pos": (4, 2), "vel": (4, 2), "adversaries": (4, 3, 8), "teammates": (4, 2, 8),
    }
    assert all(torch.isfinite(v).all() for v in first.values())


# -------------------------------------------------------------------------- reset
def scenario_state(env) -> dict:
    s = env.scenario
    return {"done": s.done(), "ball_shaping": s._ball_shaping, "agent_shaping": s._agent_shaping, "kick": s._kick}


@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    """The fixtures and the ball always reset to the same place, so before the reset they are
    moved in every env (and the ball sent into the net, ending those episodes): the reset must
    put them back in the chosen envs only, and leave the rest alone."""
    env = make(8, ai_red_agents=False, enable_shooting=True)
    for _ in range(3):
        env.step(env.get_random_actions())
    for e in env.scenario.fixtures:
        e.set_pos(e.state.pos + 0.01, batch_index=None)
    env.scenario.ball.set_pos(torch.tensor([1.56, 0.05]), batch_index=None)
    env.step([torch.zeros(8, 4)] * 6)
    assert env.done().all()
    seen = harness.check_reset_at(env, index, mask_rows=[0, 5, 6], scenario_state=scenario_state, bound=1.6)
    assert not env.done()[seen.chosen].any() and env.done()[~seen.chosen].all()
    for agent in env.scenario.blue_agents:  # blue spawns in its own half, red in the other
        assert (agent.state.pos[seen.chosen, 0] <= 0.025).all()
    for agent in env.scenario.red_agents:
        assert (agent.state.pos[seen.chosen, 0] >= -0.025).all()
        assert (agent.state.rot[seen.chosen] == math.pi).all()


def test_formation_spawn_matches_upstream():
    kwargs = {"spawn_in_formation": True, "only_blue_formation": False, "formation_noise": 0.0, "n_blue_agents": 5}
    ours, up = make(4, **kwargs), harness.make_upstream(NAME, 4, **kwargs)
    for a_ours, a_up in zip(players(ours), up.world.agents, strict=False):
        torch.testing.assert_close(a_ours.state.pos, a_up.state.pos, msg=a_ours.name)
    assert all((a.state.pos[:, 0] > 0).all() for a in ours.scenario.red_agents)


# ------------------------------------------------------------------------- parity
def restart_shaping(up, ours) -> None:
    """The dense reward measures progress from a baseline taken at reset; after moving things
    by hand both envs restart it from the current state (upstream's own ``reset_ball``)."""
    up.scenario.reset_ball(None)
    ours.scenario.reset_shaping()


def compare_infos(up, ours) -> None:
    for info_up, info_ours in zip(up.get_from_scenario(False, False, True, False)[0],
                                  ours.get_from_scenario(False, False, True, False)[0], strict=True):
        for key, value in info_up.items():
            torch.testing.assert_close(info_ours[key], value, atol=parity.ATOL, rtol=0, msg=key)


def test_matches_upstream_from_its_reset():
    up, ours = harness.make_upstream(NAME, 8, **AI_OFF), make(8, **AI_OFF)
    harness.copy_start(up, ours, vmas_states.football)
    seen = parity.run_lockstep(up, ours, seed=0, steps=30)
    assert seen.largest_reward > 0
    compare_infos(up, ours)


@pytest.mark.parametrize("kwargs", [AI_OFF, {**AI_OFF, "enable_shooting": True, "dict_obs": True}],
                         ids=["plain", "shooting_dict_obs"])
def test_matches_upstream_in_a_scrum(kwargs):
    """Everyone (ball included) starts within 0.15 of the centre: many contacts, and with
    shooting many players in kicking position; the ball must reach its top speed."""
    up, ours = harness.make_upstream(NAME, 16, **kwargs), make(16, **kwargs)
    parity.copy_random_state(up, ours, seed=3, spread=0.15, agents_only=True)
    restart_shaping(up, ours)
    kicks = []

    def actions(gen):
        kicks.append(ours.scenario.kick_ready.any().item())
        return parity.uniform_actions(up, gen)

    seen = parity.run_lockstep(up, ours, seed=0, steps=30, actions=actions)
    assert seen.fastest >= 0.29 and seen.largest_reward > 0.1
    assert any(kicks) == ("enable_shooting" in kwargs)
    compare_infos(up, ours)


def test_matches_upstream_on_a_kick_and_goals():
    """A blue player kicks the ball, a red one turns and kicks back; then balls roll into both
    goals: same states, rewards (+-100) and done."""
    kwargs = {**AI_OFF, "enable_shooting": True}
    up, ours = harness.make_upstream(NAME, 4, **kwargs), make(4, **kwargs)
    harness.copy_start(up, ours)
    for env in (up, ours):
        env.agents[0].set_pos(torch.tensor([-0.05, 0.0]), batch_index=None)
        env.agents[0].set_rot(torch.tensor([0.3]), batch_index=None)
        env.agents[3].set_pos(torch.tensor([0.06, 0.0]), batch_index=None)
    restart_shaping(up, ours)

    def actions(gen):
        chosen = [torch.zeros(4, 4) for _ in range(6)]
        chosen[0][:, 3] = 1.0
        chosen[3][:, 2:] = torch.rand(4, 2, generator=gen)
        return chosen

    seen = parity.run_lockstep(up, ours, seed=0, steps=6, actions=actions)
    assert seen.fastest >= 0.29
    for env in (up, ours):
        ball = env.world.agents[-1]
        ball.set_pos(torch.tensor([[1.45, 0.0], [-1.45, 0.1], [1.45, 0.3], [0.0, 0.0]]), batch_index=None)
        ball.set_vel(torch.tensor([[0.3, 0.0], [-0.3, 0.0], [0.3, 0.0], [0.0, 0.0]]), batch_index=None)
    restart_shaping(up, ours)
    seen = parity.run_lockstep(up, ours, seed=1, steps=4, actions=lambda g: [torch.zeros(4, 4)] * 6)
    assert seen.largest_reward > 100
    assert ours.done().tolist() == up.done().tolist() == [True, True, False, False]
    compare_infos(up, ours)


# ---------------------------------------------------------------------- rollouts
def penetration(env) -> float:
    """Deepest overlap of any player or the ball with the bare segment of a goal-line wall or a
    net's side or back (``get_distance`` also counts the lines' contact thickness, added back)."""
    depth = 0.0
    for wall in env.scenario.fixtures[:10]:
        for body in players(env) + [env.scenario.ball]:
            depth = max(depth, float(-(env.world.get_distance(body, wall) + LINE_MIN_DIST).min()))
    return depth


def test_long_rollouts_against_the_scripted_red_team():
    """250 steps against the in-simulator red team, with shooting: 8 envs random blue, 8 envs
    heuristic blue. Everything stays finite; nothing goes through the walls; the ball leaves the
    pitch only into a net (measured overlap with a wall's segment: ~3 mm; bound 1 cm). And the
    scripted red team beats random blue: measured 7 goals for, none against, in the 8 random
    envs; require 4 and at most 1."""
    env = make(16, enable_shooting=True)
    policy = HeuristicPolicy(enable_shooting=True)
    obs, worst, tally = env.reset(), 0.0, torch.zeros(2)
    for step in range(250):
        actions = env.get_random_actions()
        for i in range(3):
            actions[i][8:] = policy.compute_action(obs[i][8:], 1.0)
        obs, rews, dones, _ = env.step(actions)
        assert all(torch.isfinite(o).all() for o in obs) and all(torch.isfinite(r).all() for r in rews)
        ball = env.scenario.ball.state.pos
        beyond = ball[:, 0].abs() > 1.5
        assert (ball[beyond, 1].abs() < 0.175 + 0.02).all() and (ball[:, 0].abs() <= 1.575 + 1e-4).all()
        if step % 10 == 0:
            worst = max(worst, penetration(env))
        if dones.any():
            tally += torch.stack([(dones[:8] & (ball[:8, 0] > 0)).sum(), (dones[:8] & (ball[:8, 0] < 0)).sum()])
            obs = env.reset_at(dones)
    assert worst < 0.01
    blue_goals, red_goals = tally.tolist()
    assert red_goals >= 4 and blue_goals <= 1, tally


# ---------------------------------------------------------------------- heuristic
def goals(env, policies, steps: int) -> torch.Tensor:
    """Goals [blue, red] per group of envs; ``policies[g][i]`` plays agent i in group g (None: random).

    Finished envs are reset at once, so an env can score several goals.
    """
    groups = len(policies)
    size = env.num_envs // groups
    tally = torch.zeros(groups, 2)
    obs = env.reset()
    for _ in range(steps):
        rand = env.get_random_actions()
        actions = []
        for i in range(env.n_agents):
            parts = [rand[i][g * size:(g + 1) * size] if p[i] is None else p[i](obs[i][g * size:(g + 1) * size], 1.0)
                     for g, p in enumerate(policies)]
            actions.append(torch.cat(parts))
        obs, _, dones, _ = env.step(actions)
        if dones.any():
            blue = env.scenario.ball.state.pos[:, 0] > 0
            for g in range(groups):
                rows = slice(g * size, (g + 1) * size)
                tally[g, 0] += (dones[rows] & blue[rows]).sum()
                tally[g, 1] += (dones[rows] & ~blue[rows]).sum()
            obs = env.reset_at(dones)
    return tally


def test_heuristic_beats_random_for_both_colours():
    """32 envs x 250 steps, red not scripted: 16 envs heuristic blue vs random red, 16 random blue
    vs heuristic red. Measured: each heuristic side scores 15-16 goals and concedes none (random
    play almost never reaches a goal). Require 8 goals and at most 1 conceded."""
    torch.manual_seed(0)
    blue, red = HeuristicPolicy(ai_red_agents=False), HeuristicPolicy(ai_red_agents=False, team="red")
    tally = goals(make(32, **AI_OFF), [[blue.compute_action] * 3 + [None] * 3, [None] * 3 + [red.compute_action] * 3], 250)
    (blue_for, blue_against), (red_against, red_for) = tally.tolist()
    assert blue_for >= 8 and blue_against <= 1, tally
    assert red_for >= 8 and red_against <= 1, tally


def test_scripted_team_is_the_heuristic():
    """With ``ai_blue_agents`` the scenario's blue team plays exactly what the heuristic computes
    from each blue agent's observation (up to rounding), times the agent's u_multiplier."""
    env = make(8, ai_blue_agents=True, ai_red_agents=False)
    for _ in range(20):
        env.step(env.get_random_actions())
    scenario, policy = env.scenario, HeuristicPolicy(ai_blue_agents=True, ai_red_agents=False)
    scripted = scenario.blue_controller._team_actions(env.world)
    for agent, action in zip(scenario.blue_agents, scripted, strict=True):
        expected = policy.compute_action(scenario.observation(agent), 1.0) * 0.1
        torch.testing.assert_close(action, expected, atol=2e-3, rtol=0)
    assert max(float(a.abs().max()) for a in scripted) > 0.05


def test_heuristic_checks_its_input_and_reads_dict_obs():
    env = make(4, dict_obs=True, n_red_agents=2)
    flat_env = make(4, n_red_agents=2)
    policy = HeuristicPolicy(n_red_agents=2)
    flat, nested = flat_env.reset()[0], env.reset()[0]
    torch.testing.assert_close(policy.compute_action(nested, 1.0), policy.compute_action(flat, 1.0))
    with pytest.raises(ValueError, match="width"):
        HeuristicPolicy().compute_action(flat, 1.0)  # built for 3 red agents
    with pytest.raises(ValueError, match="team"):
        HeuristicPolicy(team="green")
    with pytest.raises(TypeError, match="bogus"):
        HeuristicPolicy(bogus=1)


def test_ai_options_and_one_a_side():
    """``disable_ai_red`` freezes the scripted team; weaker AIs still play (with noise) and stay
    finite; one-a-side teams observe no teammates, and the heuristic reads that layout."""
    env = make(4, disable_ai_red=True)
    start = [a.state.pos.clone() for a in env.scenario.red_agents]
    env.step([torch.zeros(4, 2)] * 3)
    assert all(torch.equal(a.state.pos, p) for a, p in zip(env.scenario.red_agents, start, strict=True))
    env = make(4, ai_strength=(1.0, 0.5), ai_decision_strength=0.3, ai_precision_strength=0.5)
    for _ in range(20):
        env.step(env.get_random_actions())
    assert all(torch.isfinite(a.state.pos).all() for a in env.scenario.red_agents)
    assert max(float(a.state.vel.norm(dim=-1).max()) for a in env.scenario.red_agents) > 0.02
    env = make(4, n_blue_agents=1, n_red_agents=1, ai_red_agents=False)
    obs = env.reset()
    assert [o.shape[1] for o in obs] == [16 + 8, 16 + 8]
    action = HeuristicPolicy(n_blue_agents=1, n_red_agents=1, team="red").compute_action(obs[1], 1.0)
    assert action.shape == (4, 2) and action.abs().max() <= 1.0


def test_render_draws_the_pitch():
    env = make(2, ai_red_agents=False, enable_shooting=True)
    frame = env.render(mode="rgb_array")
    assert frame.shape == (800, 1200, 3)
    green = (frame[..., 1] > 150) & (frame[..., 0] < 100)
    assert green.mean() > 0.3  # the grass covers much of the view
    env.scenario.render_field(False)  # lines only: the grass is gone
    bare = env.render(mode="rgb_array")
    assert ((bare[..., 1] > 150) & (bare[..., 0] < 100)).mean() < 0.05


def test_both_teams_scripted_steps_without_actions():
    """With both teams on the AI there are no policy agents: step([]) advances the match."""
    env = harness.make(football.Scenario(), 4, ai_blue_agents=True)
    assert env.agents == []
    start = [e.state.pos.clone() for e in env.world.agents]
    for _ in range(5):
        env.step([])
    assert any(not torch.equal(s, e.state.pos) for s, e in zip(start, env.world.agents))
