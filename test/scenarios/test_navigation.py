"""``navigation``: API, parity with VMAS 1.5.2 (lidar, rewards, dones, infos), resets, heuristic.

Oracle: ``vmas`` 1.5.2. Same start -> same states, observations (lidar
included), rewards, dones and infos, free-running, for the default task and
for kwargs that change the observation layout, the goals and the rewards.
"""
from __future__ import annotations

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import parity, vmas_states
from vmas_ros.scenarios import navigation

NAME = "navigation"


def make(num_envs: int = 8, **kwargs):
    return harness.make(navigation.Scenario(), num_envs, **kwargs)


def positions(entities) -> torch.Tensor:
    return torch.stack([e.state.pos for e in entities], dim=1)  # [B, n, 2]


# ------------------------------------------------------------------- construction
def test_construction_defaults():
    env = make(4)
    world = env.world
    assert [a.name for a in env.agents] == [f"agent_{i}" for i in range(4)]
    assert [l.name for l in world.landmarks] == [f"goal {i}" for i in range(4)]
    assert (world.dt, world._substeps, world._drag, world.x_semidim, world.y_semidim) == (0.1, 2, 0.25, None, None)
    for agent in env.agents:
        assert agent.shape.radius == 0.1 and agent.collide and agent.u_range == 1.0 and agent.u_multiplier == 1.0
        (lidar,) = agent.sensors
        assert (lidar.n_rays, lidar.max_range) == (12, 0.35)
        assert not agent.goal.collide and agent.goal.shape.radius == 0.05
    scenario = env.scenario
    assert {k: getattr(scenario, k) for k in navigation.DEFAULTS} == navigation.DEFAULTS
    obs = env.get_from_scenario(True, False, False, False)[0]
    assert [o.shape for o in obs] == [(4, 4 + 2 + 12)] * 4


def test_construction_variants():
    env = make(2, n_agents=9, collisions=False, enforce_bounds=True, world_spawning_x=2, world_spawning_y=1.5,
               agent_radius=0.05, observe_all_goals=True)
    assert (env.world.x_semidim, env.world.y_semidim) == (2, 1.5)
    assert all(not a.collide and not a.sensors and a.shape.radius == 0.05 for a in env.agents)
    assert len({a.color for a in env.agents}) == 9  # distinct colours past the palette too
    assert env.get_from_scenario(True, False, False, False)[0][0].shape == (2, 4 + 18)
    assert navigation.goal_slots(6, 3, True) == [0, 0, 0, 1, 1, 1]
    assert navigation.goal_slots(4, 2, False) == [0, 0, 2, 3]


def test_unknown_kwargs_warn_and_bad_values_raise():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    bad_values = [
        ({"n_agents": 0}, "n_agents"), ({"n_agents": 2.5}, "n_agents"), ({"n_lidar_rays": 0}, "n_lidar_rays"),
        ({"lidar_range": 0}, "lidar_range"), ({"agent_radius": -0.1}, "agent_radius"),
        ({"world_spawning_x": 0}, "world_spawning_x"), ({"comms_range": -1}, "comms_range"),
        ({"final_reward": "x"}, "final_reward"),
        ({"agents_with_same_goal": 5}, "agents_with_same_goal"),
        ({"agents_with_same_goal": 2}, "collisions=False"),  # shared goals with collisions on
        ({"split_goals": True, "collisions": False}, "split_goals"),  # needs agents_with_same_goal = 2
        ({"n_agents": 3, "split_goals": True, "agents_with_same_goal": 1}, "split_goals"),
    ]
    for kwargs, message in bad_values:
        with pytest.raises(ValueError, match=message):
            make(2, **kwargs)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode):
    options = dict(SPACE_MODES[mode])
    if mode == "dict":
        options.update(n_agents=3, observe_all_goals=True, n_lidar_rays=5)
    if mode == "discrete":
        options.update(collisions=False)
    obs, _ = harness.check_spaces(make(4, **options), harness.make_upstream(NAME, 4, **options), steps=3)
    values = list(obs.values()) if isinstance(obs, dict) else obs
    expected = {"dict": 4 + 6 + 5, "discrete": 6}.get(mode, 18)
    assert [v.shape[1] for v in values] == [expected] * len(values)


# -------------------------------------------------------------------------- reset
def scenario_state(env) -> dict:
    return {"pos_shaping": env.scenario.pos_shaping}


@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(8, n_agents=6, collisions=False, split_goals=True, agents_with_same_goal=3)
    gen = torch.Generator().manual_seed(1)
    for _ in range(5):
        env.step([torch.rand(8, 2, generator=gen) * 2 - 1 for _ in env.agents])
    check = harness.check_reset_at(env, index, mask_rows=slice(None, None, 3), scenario_state=scenario_state, bound=1.0)
    chosen = check.chosen
    agents, goals = positions(env.agents)[chosen], positions([a.goal for a in env.agents])[chosen]
    torch.testing.assert_close(check.after["pos_shaping"][chosen], torch.linalg.vector_norm(agents - goals, dim=-1))
    assert (goals[:, :3] == goals[:, :1]).all() and (goals[:, 3:] == goals[:, 3:4]).all()
    everything = torch.cat([agents, goals[:, [0, 3]]], dim=1)
    gaps = torch.cdist(everything, everything) + torch.eye(everything.shape[1]) * 9
    assert (gaps >= 0.25 - 1e-6).all()  # spawned 2 radii + 0.05 apart


def test_starting_state_spreads_and_shares_goals():
    env = make(64, n_agents=4, collisions=False, agents_with_same_goal=2, world_spawning_x=2, world_spawning_y=0.5)
    agents, goals = positions(env.agents), positions([a.goal for a in env.agents])
    assert (agents[..., 0].abs() <= 2).all() and (agents[..., 1].abs() <= 0.5).all()
    assert agents[..., 0].abs().max() > 1.5  # the x range is used
    assert (goals[:, 0] == goals[:, 1]).all() and (goals[:, 1] != goals[:, 2]).all()
    assert (env.world.agents[0].state.vel == 0).all()


# ------------------------------------------------------------------------- parity
def crowd(spread: float):
    """Start every agent within ``spread`` of the origin, in both envs, so that they meet."""
    def place(up, ours) -> None:
        gen = torch.Generator().manual_seed(7)
        for a_up, a_ours in zip(up.world.agents, ours.world.agents):
            pos = (torch.rand(up.world.batch_dim, 2, generator=gen) * 2 - 1) * spread
            a_up.set_pos(pos.clone(), batch_index=None)
            a_ours.set_pos(pos.clone(), batch_index=None)
            distance = torch.linalg.vector_norm(pos - a_up.goal.state.pos, dim=-1)
            a_up.pos_shaping = distance * up.scenario.pos_shaping_factor
        vmas_states.navigation(up, ours)
    return place


def goal_seeking(up, noise: float):
    """Actions pointing each agent at its goal, plus uniform noise: agents cross paths and arrive."""
    def draw(gen: torch.Generator):
        actions = []
        for agent in up.agents:
            to_goal = agent.goal.state.pos - agent.state.pos
            jitter = (torch.rand(up.num_envs, 2, generator=gen) * 2 - 1) * noise
            actions.append((3 * to_goal + jitter).clamp(-1, 1))
        return actions
    return draw


def lockstep_with_infos(up, ours, steps: int, actions) -> dict:
    """``parity.run_lockstep``'s checks plus dones and infos at every step; returns what was seen."""
    gen = torch.Generator().manual_seed(0)
    seen = {"reward": 0.0, "penalty": 0.0, "final": 0.0, "done": 0, "lidar": 0.0}
    parity.assert_same_state(up, ours, 0)
    for step in range(1, steps + 1):
        chosen = actions(gen)
        obs_up, rew_up, done_up, info_up = up.step([a.clone() for a in chosen])
        obs, rew, done, info = ours.step([a.clone() for a in chosen])
        parity.assert_same_state(up, ours, step)
        parity.assert_same_outputs(step, (obs, rew, done, info), (obs_up, rew_up, done_up, info_up))
        seen["reward"] = max(seen["reward"], max(float(r.abs().max()) for r in rew))
        seen["penalty"] = min(seen["penalty"], min(float(i["agent_collisions"].min()) for i in info))
        seen["final"] = max(seen["final"], float(info[0]["final_rew"].max()))
        seen["done"] += int(done.sum())
        if ours.scenario.collisions:
            seen["lidar"] = max(seen["lidar"], max(float(o[:, -ours.scenario.n_lidar_rays:].max()) for o in obs))
    return seen


def test_matches_upstream_vmas_random_play():
    """The plain run: upstream's own reset, uniform random forces, 50 steps."""
    up, ours = harness.make_upstream(NAME, 6), make(6)
    harness.copy_start(up, ours, vmas_states.navigation)
    seen = parity.run_lockstep(up, ours, seed=0, steps=50)
    assert seen.fastest > 0.2 and seen.largest_reward > 0


@pytest.mark.parametrize("options, steps", [
    ({}, 40),
    ({"n_agents": 3, "n_lidar_rays": 7, "lidar_range": 0.5, "agent_radius": 0.07, "shared_rew": False,
      "pos_shaping_factor": 2.5, "final_reward": 0.5, "agent_collision_penalty": -0.3, "enforce_bounds": True,
      "world_spawning_x": 0.6, "world_spawning_y": 0.4, "observe_all_goals": True}, 40),
], ids=["default", "lidar-bounds-rewards"])
def test_matches_upstream_vmas_in_contact(options, steps):
    """Agents start crowded and head for their goals: they collide (penalties),
    see each other on the lidar, arrive (final reward) and finish (done)."""
    batch = 6
    up, ours = harness.make_upstream(NAME, batch, **options), make(batch, **options)
    harness.copy_start(up, ours, crowd(0.25))
    seen = lockstep_with_infos(up, ours, steps, goal_seeking(up, noise=0.6))
    assert seen["penalty"] < 0 and seen["lidar"] > 0.1, seen
    assert seen["final"] > 0 and seen["done"] > 0, seen


@pytest.mark.parametrize("options", [
    {"collisions": False, "agents_with_same_goal": 3, "observe_all_goals": True, "shared_rew": False},
    {"n_agents": 6, "collisions": False, "split_goals": True, "agents_with_same_goal": 3, "final_reward": 1.0},
], ids=["shared-goal", "split-goals"])
def test_matches_upstream_vmas_without_collisions(options):
    batch = 6
    up, ours = harness.make_upstream(NAME, batch, **options), make(batch, **options)
    harness.copy_start(up, ours, vmas_states.navigation)
    ours_goals = positions([a.goal for a in ours.agents])
    torch.testing.assert_close(ours_goals, positions([a.goal for a in up.agents]))  # shared goals copied
    seen = lockstep_with_infos(up, ours, 40, goal_seeking(up, noise=0.3))
    assert seen["final"] > 0 and seen["done"] > 0 and seen["penalty"] == 0, seen


def test_collision_penalty_is_gated_batch_wide_as_upstream():
    """Agents 0 and 1 touch (gap 0.003, not overlapping) in env 0. VMAS charges
    the penalty only while the pair overlaps in some env of the batch: not with
    the pair apart in env 1, yes with it overlapping there."""
    for overlap_env1, charged in ((False, 0.0), (True, -1.0)):
        up, ours = harness.make_upstream(NAME, 2, n_agents=2), make(2, n_agents=2)
        harness.copy_start(up, ours, vmas_states.navigation)
        second_x = torch.tensor([0.203, 0.15 if overlap_env1 else 0.6])
        for env in (up, ours):
            env.agents[0].set_pos(torch.zeros(2, 2), batch_index=None)
            env.agents[1].set_pos(torch.stack([second_x, torch.zeros(2)], dim=1), batch_index=None)
        for a_up, a_ours in zip(up.agents, ours.agents):
            mine, theirs = ours.scenario.reward(a_ours), up.scenario.reward(a_up)
            torch.testing.assert_close(mine, theirs, atol=parity.ATOL, rtol=0)
            collisions = ours.scenario.info(a_ours)["agent_collisions"]
            assert collisions.tolist() == [charged, charged]


# --------------------------------------------------------------------- heuristic
def test_heuristic_heads_for_the_goal_and_away_from_neighbours():
    policy = navigation.HeuristicPolicy()
    free = torch.zeros(2, 18)
    free[0, 4:6] = torch.tensor([1.0, 0.0])  # goal 1 m to the left (obs holds pos - goal)
    free[1, 4:6] = torch.tensor([0.0, -0.5])  # goal above
    action = policy.compute_action(free, 1.0)
    assert action[0, 0] < -0.9 and action[0, 1].abs() < 1e-6 and action[1, 1] > 0.9
    blocked = free[:1].clone()
    blocked[0, 4:6] = torch.tensor([-1.0, 0.0])  # goal to the right ...
    blocked[0, 6] = 0.3  # ... and a neighbour close along ray 0 (pointing right)
    action = policy.compute_action(blocked, 1.0)
    assert action[0, 0] < 0 and action[0, 1].abs() > 0.1  # backs off and swerves
    assert (policy.compute_action(torch.randn(50, 18), 0.5).abs() <= 0.5).all()
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 6), 1.0)
    shared = navigation.HeuristicPolicy(n_agents=3, collisions=False, observe_all_goals=True, goal_slot=2)
    obs = torch.zeros(1, 10)
    obs[0, 8:10] = torch.tensor([0.0, 1.0])  # only the third goal block is this agent's
    assert shared.compute_action(obs, 1.0)[0, 1] < -0.9
    with pytest.raises(ValueError, match="goal_slot"):
        navigation.HeuristicPolicy(goal_slot=1)
    with pytest.raises(TypeError, match="nope"):
        navigation.HeuristicPolicy(nope=1)


@pytest.mark.parametrize("options", [{}, {"collisions": False}], ids=["lidar", "no-collisions"])
def test_heuristic_reaches_goals_and_beats_random(options):
    """32 envs x 150 steps (seed 0), half heuristic teams, half random.

    Measured: with lidar, every team return ~ +4.75 per agent against ~ -1.46
    for random play (random agents bump into each other and drift), 15 of 16
    teams all on their goals (done) at some point; without collisions +5.06
    against -0.16, 16 of 16. Required: a gain of 4 and 13 of 16 teams done.
    """
    torch.manual_seed(0)
    env = make(32, seed=0, **options)
    heuristic = navigation.HeuristicPolicy(**options).compute_action
    done_ever = torch.zeros(32, dtype=torch.bool)

    def watched(obs, u_range):
        nonlocal done_ever
        done_ever = done_ever | env.done()
        return heuristic(obs, u_range)

    returns = harness.play_lineups(env, [[watched] + [heuristic] * 3, [None] * 4], steps=150)
    heuristic_return, random_return = returns.mean(dim=0).tolist()
    assert int(done_ever[:16].sum()) >= 13 and not done_ever[16:].any(), done_ever
    assert heuristic_return > random_return + 4, returns


def test_heuristic_takes_vmas_qp_parameters():
    """VMAS's heuristic is built with its QP's clf_epsilon and clf_slack; ours accepts and checks them."""
    policy = navigation.HeuristicPolicy(True, clf_epsilon=0.4, clf_slack=100.0)
    assert policy.compute_action(torch.zeros(3, 4 + 2 + 12), 1.0).shape == (3, 2)
    with pytest.raises(ValueError, match="clf_epsilon"):
        navigation.HeuristicPolicy(True, clf_epsilon=0)
