"""``road_traffic``: API, parity with VMAS 1.5.2, resets, heuristic.

Oracle: ``vmas`` 1.5.2 (same start -> same states, observations, rewards,
infos and dones). Upstream's road_traffic is slow (Python loops over envs and
agents in every step), so the parity runs use few envs, few agents and a few
dozen steps; random speed and steering commands drive the cars into the lane
boundaries and into each other within those steps, so collisions (and the
dones and penalties they bring) are compared too.
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import parity, vmas_states
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios import road_traffic
from vmas_ros.scenarios.road_traffic import map_data

NAME = "road_traffic"
SMALL = dict(n_agents=4, is_add_noise=False)


def make(num_envs: int = 2, **kwargs):
    return harness.make(road_traffic.Scenario(), num_envs, **kwargs)


# ------------------------------------------------------------------- construction
def test_construction_defaults():
    env = make(2)
    world, scenario = env.world, env.scenario
    assert [a.name for a in env.agents] == [f"agent_{i}" for i in range(20)] and not world.landmarks
    assert (world.dt, world.x_semidim, world.y_semidim) == (0.05, 4.5, 4.0)
    for agent in env.agents:
        assert (agent.shape.length, agent.shape.width) == (0.16, 0.08) and not agent.collide
        assert agent.u_range[0] == 1.0 and agent.u_range[1] == pytest.approx(math.radians(35))
        assert agent.max_speed == 1.0 and agent.dynamics.l_f == agent.dynamics.l_r == 0.08
    assert scenario.routes.centre.shape[0] == 40 and bool(scenario.routes.is_loop.all())
    assert scenario.noise_level == pytest.approx(0.016) and scenario.threshold_near_boundary_high == pytest.approx(0.0315)
    assert scenario.mean_lane_width == pytest.approx(0.15, abs=0.01)
    obs = env.reset()
    assert [o.shape for o in obs] == [(2, 32)] * 20


def test_unknown_kwargs_warn_and_bad_values_raise(tmp_path):
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(1, n_agents=3, not_a_kwarg=1)
    bad_values = [
        {"map_type": "3"}, {"is_testing_mode": True}, {"n_agents": 1}, {"n_nearing_agents_observed": 20},
        {"dt": 0}, {"is_ego_view": 1}, {"scenario_probabilities": [1, 0]}, {"max_speed": -1.0},
        {"threshold_near_boundary_high": -0.1}, {"map_file_path": str(tmp_path / "missing.xml")},
        {"parameters": object()},
    ]
    for bad in bad_values:
        name = next(iter(bad))
        with pytest.raises(ValueError, match=name):
            make(1, **{"n_agents": 3, **bad}) if name != "n_agents" else make(1, **bad)
    with pytest.raises(ValueError, match="is_partial_observation"):
        make(1, n_agents=3, is_partial_observation=False, is_ego_view=False)


def test_map_is_read_from_the_installed_vmas_or_a_given_path():
    path = map_data.locate_map()
    assert path.endswith("road_traffic_cpm_lab.xml") and map_data.locate_map(path) == path
    env = make(1, n_agents=3, map_file_path=path)
    torch.testing.assert_close(env.scenario.routes.centre, make(1, n_agents=3).scenario.routes.centre)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode):
    options = dict(SPACE_MODES[mode], n_agents=3)
    harness.check_spaces(make(2, **options), harness.make_upstream(NAME, 2, **options), steps=2)


# ------------------------------------------------------------------------- parity
def lockstep(options: dict, steps: int, batch: int = 2, seed: int = 0):
    up, ours = harness.make_upstream(NAME, batch, **options), make(batch, **options)
    harness.copy_start(up, ours, vmas_states.road_traffic)
    obs_up = up.get_from_scenario(True, False, False, False)[0]
    obs = ours.get_from_scenario(True, False, False, False)[0]
    for mine, theirs in zip(obs, obs_up, strict=True):
        torch.testing.assert_close(mine, theirs, atol=1e-4, rtol=0)
    seen = run_lockstep(up, ours, seed=seed, steps=steps)
    actions = [torch.stack([torch.full((batch,), 0.5), torch.full((batch,), 0.2)], dim=1)] * len(up.agents)
    _, _, done_up, info_up = up.step([a.clone() for a in actions])
    _, _, done, info = ours.step([a.clone() for a in actions])
    assert torch.equal(done, done_up)
    parity.assert_same_infos(info, info_up)
    return up, ours, seen


def test_matches_upstream_vmas():
    """Default observation design (ego view, 2 nearest neighbours, masks, distances)."""
    up, ours, seen = lockstep(SMALL, steps=40)
    assert seen.largest_reward >= 1.0  # a collision penalty was paid
    assert seen.fastest > 0.5


def test_matches_upstream_vmas_with_twenty_cars():
    """The default configuration (20 cars, noise off): one env, a few steps, as upstream takes ~0.5 s a step."""
    _, ours, seen = lockstep(dict(is_add_noise=False), steps=5, batch=1, seed=2)
    assert len(ours.agents) == 20 and seen.fastest > 0.5


@pytest.mark.parametrize("options", [
    dict(is_ego_view=False, is_observe_distance_to_boundaries=False, is_observe_vertices=False,
         is_observe_ref_path_other_agents=True, is_apply_mask=False, n_nearing_agents_observed=3,
         is_observe_distance_to_center_line=False),
    dict(is_partial_observation=False, is_observe_distance_to_agents=False, n_points_short_term=4,
         sample_interval_ref_path=3, reward_progress=20, threshold_change_steering=5, scenario_probabilities=[0.5, 0.5, 0]),
], ids=["bird-view-boundary-points", "full-observation-rewards"])
def test_matches_upstream_vmas_other_designs(options):
    _, ours, seen = lockstep(dict(SMALL, **options), steps=15, seed=1)
    assert seen.largest_reward > 0.1


def test_observation_noise_is_bounded_and_fresh():
    env = make(2, n_agents=3)
    clean = road_traffic.scenario.observe_all(env.scenario)
    first, second = env.get_from_scenario(True, False, False, False)[0][0], env.get_from_scenario(True, False, False, False)[0][0]
    noise = first - clean[:, 0]
    assert (noise >= 0).all() and (noise < 0.016).all() and noise.std() > 0.002 and not torch.equal(first, second)


# -------------------------------------------------------------------------- reset
def scenario_state(env) -> dict:
    s = env.scenario
    names = ("route_id", "start_point", "short_term", "prev_pos", "dist_ref", "dist_boundary", "mutual", "hit_boundary")
    return {name: getattr(s, name) for name in names}


@pytest.mark.parametrize("index", [1, [0, 2], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    """Hand-made check: road_traffic starts cars moving, so ``harness.check_reset_at`` (at rest) does not apply."""
    env = make(4, n_agents=5)
    gen = torch.Generator().manual_seed(2)
    for _ in range(4):
        env.step([torch.rand(4, 2, generator=gen) * torch.tensor([1.0, 0.6]) for _ in env.agents])
    chosen = torch.zeros(4, dtype=torch.bool)
    chosen[torch.tensor([True, False, False, True]) if index == "mask" else torch.as_tensor(index)] = True
    before = {f"{a.name}.{f}": getattr(a.state, f).clone() for a in env.agents for f in ("pos", "vel", "rot")}
    before.update({k: v.clone() for k, v in scenario_state(env).items()})
    env.reset_at(torch.tensor([True, False, False, True]) if index == "mask" else index)
    after = {f"{a.name}.{f}": getattr(a.state, f) for a in env.agents for f in ("pos", "vel", "rot")}
    after.update(scenario_state(env))
    for key in before:
        assert torch.equal(after[key][~chosen], before[key][~chosen]), key
    s, routes = env.scenario, env.scenario.routes
    pos = torch.stack([a.state.pos for a in env.agents], dim=1)[chosen]
    rot = torch.stack([a.state.rot[:, 0] for a in env.agents], dim=1)[chosen]
    vel = torch.stack([a.state.vel for a in env.agents], dim=1)[chosen]
    route, point = s.route_id[chosen], s.start_point[chosen]
    torch.testing.assert_close(pos, routes.centre[route, point])
    torch.testing.assert_close(rot, routes.yaw[route, point])
    assert (point >= 6).all() and (point < routes.n_centre[route] // 2).all()
    assert (torch.linalg.vector_norm(vel, dim=-1) <= 1.0).all()
    gaps = torch.linalg.vector_norm(pos.unsqueeze(1) - pos.unsqueeze(2), dim=-1) + torch.eye(5) * 10
    assert (gaps >= s.spawn_distance - 1e-6).all()
    assert not s.hit_agents[chosen].any() and not s.hit_boundary[chosen].any()
    torch.testing.assert_close(s.prev_pos[chosen], pos)


@pytest.mark.parametrize("clear", [False, True])
def test_steering_history_survives_a_reset_as_in_vmas_unless_cleared(clear):
    """VMAS keeps the last two steering commands across a reset, so the first reward after a seeded reset
    depends on the episode before; ``reset_steering_history=True`` (what gymnasium's ids pass) clears
    them for the envs reset, and a seeded reset then repeats its episode."""
    env = make(2, n_agents=4, is_add_noise=False, reset_steering_history=clear)
    straight, hard_left = torch.tensor([0.5, 0.0]), torch.tensor([0.5, 0.6])

    def first_rewards(before):
        env.step([before.expand(2, 2)] * 4)
        env.reset(seed=5)
        _, rewards, _, _ = env.step([straight.expand(2, 2)] * 4)
        return torch.stack(rewards)

    after_straight, after_left = first_rewards(straight), first_rewards(hard_left)
    assert torch.equal(after_straight, after_left) == clear
    assert not env.scenario._history_cleared.any(), "the reset's observation took it into account"


# --------------------------------------------------------------------- heuristic
def test_heuristic_action_shape_and_range():
    policy = road_traffic.HeuristicPolicy(n_agents=4)
    obs = torch.zeros(3, policy.width)
    obs[:, 1:7] = torch.tensor([[0.1, 0.0, 0.2, 0.0, 0.3, 0.0], [0.1, 0.1, 0.2, 0.2, 0.3, 0.3], [0.1, -0.1, 0.1, -0.2, 0, -0.3]])
    obs[:, 10:] = 1.0  # neighbours masked (far away)
    action = policy.compute_action(obs, [1.0, math.radians(35)])
    assert action.shape == (3, 2) and (action[:, 0] > 0).all() and (action[:, 0] <= 1).all()
    assert action[0, 1] == 0 and action[1, 1] > 0 and action[2, 1] < 0
    assert (action[:, 1].abs() <= math.radians(35) + 1e-6).all()
    obs[0, 10:18] = torch.tensor([0.1, 0.02, 0.1, -0.02, 0.2, -0.02, 0.2, 0.02])  # a car right ahead
    assert policy.compute_action(obs, [1.0, 0.6])[0, 0] == 0
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 5), [1.0, 0.6])


def test_heuristic_beats_random_play():
    """8 envs x 60 steps (seed 0), 6 cars: half the envs heuristic, half random.

    Measured: heuristic ~ +1.0 per car, random ~ -11.3 (boundary collisions
    every step once off the road). Required: a gain of 5.
    """
    torch.manual_seed(0)
    kwargs = dict(n_agents=6)
    env = make(8, **kwargs)
    heuristic = road_traffic.HeuristicPolicy(**kwargs).compute_action
    returns = harness.play_lineups(env, [[heuristic] * 6, [None] * 6], steps=60)
    heuristic_return, random_return = returns.mean(dim=0).tolist()
    assert heuristic_return > random_return + 5, returns
    assert heuristic_return > 0
