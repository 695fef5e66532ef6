"""``sampling``: API, parity with VMAS 1.5.2, the field and spent cells, resets, heuristic.

Oracle: ``vmas`` (same start, same hidden field -> same obs, rewards, infos,
states and spent cells). Each env's field is drawn at reset (Gaussian centres,
and the normaliser computed from them), so the parity tests copy upstream's
centres, normaliser and spent-cell grid into ours along with the entities.
Upstream is slow here (its full reset evaluates the field point by point over
the grid), so batches are small.
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from vmas_ros.testing import parity, vmas_states
from vmas_ros.scenarios import sampling
from vmas_ros.simulator.heuristic_policy import RandomPolicy

NAME = "sampling"
#: upstream kwargs away from their defaults (behaviour-changing ones: private rewards, raw values, a
#: rectangular arena with coarser cells, per-Gaussian variances, a longer lidar)
CUSTOM = {
    "n_agents": 4, "shared_rew": False, "norm": False, "lidar_range": 0.35, "agent_radius": 0.04, "xdim": 1.5,
    "ydim": 0.5, "grid_spacing": 0.1, "n_gaussians": 2, "cov": [0.03, 0.1], "comms_range": 0.2,
}


def make(num_envs: int, **kwargs):
    return harness.make(sampling.Scenario(), num_envs, **kwargs)


# ------------------------------------------------------------------- construction
def test_default_construction():
    env = make(2)
    world, scenario = env.world, env.scenario
    assert [a.name for a in world.agents] == ["agent_0", "agent_1", "agent_2"] and world.landmarks == []
    assert all(a.collide and a.shape.radius == 0.025 for a in world.agents)
    for agent in world.agents:
        (lidar,) = agent.sensors
        assert (lidar.n_rays, lidar.max_range) == (12, 0.2)
        torch.testing.assert_close(lidar.angles[0, :2], torch.tensor([0.05, 0.05 + math.pi / 6]))
        assert [e.name for e in world.entities if lidar.entity_filter(e)] == [a.name for a in world.agents]
    assert (world.x_semidim, world.y_semidim) == pytest.approx((0.975, 0.975))
    assert (world.dt, world.substeps, world.drag) == (0.1, 1, 0.25)
    assert (scenario.n_x_cells, scenario.n_y_cells, scenario.variances) == (40, 40, [0.05] * 3)
    assert scenario.sampled.shape == (2, 40, 40) and scenario.locs.shape == (2, 3, 2)
    assert [tuple(o.shape) for o in env.reset()] == [(2, 24)] * 3
    assert env.scenario.shared_rew and env.scenario.norm


def test_custom_construction():
    env = make(2, **CUSTOM)
    scenario = env.scenario
    assert [a.name for a in env.agents] == [f"agent_{i}" for i in range(4)]
    assert (scenario.n_x_cells, scenario.n_y_cells, scenario.variances) == (30, 10, [0.03, 0.1])
    assert (env.world.x_semidim, env.world.y_semidim) == pytest.approx((1.46, 0.46))
    assert all(a.sensors[0].max_range == 0.35 and a.shape.radius == 0.04 for a in env.agents)


def test_without_collisions_and_from_one_spot():
    """VMAS cannot build this observation (its lidar needs colliding agents); ours drops the lidar."""
    env = make(3, collisions=False, spawn_same_pos=True)
    assert all(not a.collide and a.sensors == [] for a in env.agents)
    obs = env.reset()
    assert [tuple(o.shape) for o in obs] == [(3, 12)] * 3
    assert all((a.state.pos == 0).all() for a in env.agents)
    _, rews, _, infos = env.step([torch.zeros(3, 2)] * 3)
    # all three stand in one cell: agent 0 collects it, the others find it spent
    first = infos[0]["agent_sample"]
    assert (first > 0).all() and all((i["agent_sample"] == 0).all() for i in infos[1:])
    assert all(torch.equal(r, first) for r in rews)
    with pytest.raises(Exception):  # upstream's observation reads a lidar the agents do not have
        harness.make_upstream(NAME, 1, collisions=False, **COARSE)


def test_bad_and_unknown_kwargs():
    bad = [
        {"n_agents": 0}, {"n_gaussians": 1.5}, {"lidar_range": 0}, {"agent_radius": -0.1}, {"xdim": 0},
        {"grid_spacing": 0.3}, {"cov": [0.1]}, {"cov": -1.0}, {"comms_range": -1}, {"norm": "yes"},
        {"spawn_same_pos": True}, {"agent_radius": 1.0},
    ]
    harness.check_kwargs_refused(make, 1, bad)
    with pytest.raises(ValueError, match="ydim"):
        make(1, ydim=0.525, grid_spacing=0.05 * 2)
    with pytest.raises(TypeError, match="wind"):
        sampling.HeuristicPolicy(wind=1)
    with pytest.raises(ValueError, match="continuous"):
        sampling.HeuristicPolicy(continuous_action=False)


# ------------------------------------------------------------------------- spaces
#: the spaces do not depend on the grid; a coarse one keeps upstream's reset (point by point) cheap
COARSE = {"grid_spacing": 0.25}


@pytest.mark.parametrize("kwargs", [COARSE, CUSTOM], ids=["coarse", "custom"])
@pytest.mark.parametrize("mode", list(harness.SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode, kwargs):
    options = dict(harness.SPACE_MODES[mode], **kwargs)
    harness.check_spaces(make(2, **options), harness.make_upstream(NAME, 2, **options), steps=3)


# ------------------------------------------------------------------------- parity
def compare_infos_and_cells(up, ours, seen: dict) -> None:
    """Between steps: the same ``agent_sample`` infos and the same spent cells (both side-effect free)."""
    (info_up,) = up.get_from_scenario(False, False, True, False)
    (info,) = ours.get_from_scenario(False, False, True, False)
    for mine, theirs in zip(info, info_up, strict=True):
        torch.testing.assert_close(mine["agent_sample"], theirs["agent_sample"], atol=parity.ATOL, rtol=0)
    assert torch.equal(ours.scenario.sampled, up.scenario.sampled)
    seen["spent"] = int(ours.scenario.sampled.sum())


@pytest.mark.parametrize("kwargs", [{}, CUSTOM], ids=["default", "custom"])
def test_matches_upstream_vmas(kwargs):
    up, ours = harness.make_upstream(NAME, 4, **kwargs), make(4, **kwargs)
    # the normaliser is ours to compute too: from upstream's centres it must match upstream's
    torch.testing.assert_close(ours.scenario.grid_maximum(torch.stack(up.scenario.locs, dim=1)), up.scenario.max_pdf)
    harness.copy_start(up, ours, vmas_states.sampling)
    seen_cells: dict = {}

    def actions(gen):
        compare_infos_and_cells(up, ours, seen_cells)
        return parity.uniform_actions(up, gen)

    seen = parity.run_lockstep(up, ours, seed=0, actions=actions, steps=30)
    compare_infos_and_cells(up, ours, seen_cells)
    assert seen.largest_reward > 0.1 and seen_cells["spent"] > 4 * len(ours.agents)


def test_matches_upstream_vmas_sweeping_and_crowded():
    """Agents packed near the centre (lidar hits, collisions, shared cells) and driven by the
    heuristic plus noise, so they sweep over fresh and spent cells and along the walls. Coarser
    cells and wider Gaussians than the default (a cheaper upstream reset)."""
    kwargs = {"grid_spacing": 0.1, "cov": 0.08}
    up, ours = harness.make_upstream(NAME, 3, **kwargs), make(3, **kwargs)
    harness.copy_start(up, ours, vmas_states.sampling)
    parity.copy_random_state(up, ours, seed=2, spread=0.08, agents_only=True)
    policy = sampling.HeuristicPolicy(**kwargs)
    seen_cells, lidar_hits = {}, []

    def actions(gen):
        compare_infos_and_cells(up, ours, seen_cells)
        obs = ours.get_from_scenario(True, False, False, False)[0]
        lidar_hits.append(min(float(o[:, 4:16].min()) for o in obs))
        noise = [0.3 * torch.randn(o.shape[0], 2, generator=gen) for o in obs]
        return [(policy.compute_action(o, 1.0) + n).clamp(-1, 1) for o, n in zip(obs, noise)]

    seen = parity.run_lockstep(up, ours, seed=1, actions=actions, steps=30)
    assert min(lidar_hits) < 0.1 and seen_cells["spent"] > 30 and seen.fastest > 0.2


# -------------------------------------------------------------------------- reset
def field_state(env) -> dict:
    s = env.scenario
    return {"locs": s.locs, "max_pdf": s.max_pdf, "sampled": s.sampled, "samples": s.samples}


@pytest.mark.parametrize("index", [1, [0, 3], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(5)
    env.reset()
    for _ in range(4):
        env.step([torch.ones(5, 2)] * 3)
    check = harness.check_reset_at(env, index, mask_rows=[2, 4], scenario_state=field_state, bound=0.975)
    chosen, scenario = check.chosen, env.scenario
    assert not scenario.sampled[chosen].any() and scenario.sampled[~chosen].any(dim=(1, 2)).all()
    torch.testing.assert_close(scenario.max_pdf[chosen], scenario.grid_maximum(scenario.locs[chosen]))
    assert not torch.equal(check.before["locs"][chosen], scenario.locs[chosen])
    # a reset env's samples are those of its new start, nothing spent yet
    pos = torch.stack([a.state.pos for a in env.agents], dim=1)[chosen]
    expected = scenario.density(pos, scenario.locs[chosen]) / scenario.max_pdf[chosen].unsqueeze(-1)
    torch.testing.assert_close(scenario.samples[chosen], expected)


# ---------------------------------------------------------------------- semantics
def test_field_reward_and_observation():
    """One Gaussian at a known spot: samples pay field / grid maximum once per cell; the
    neighbour observation reads the cells around, 0 where spent or outside."""
    env = make(1, n_gaussians=1, n_agents=2)
    env.reset()
    scenario = env.scenario
    scenario.locs = torch.tensor([[[0.3, -0.2]]])
    scenario.max_pdf = scenario.grid_maximum(scenario.locs)
    torch.testing.assert_close(scenario.max_pdf, torch.tensor([1 / (2 * math.pi * 0.05)]))  # the centre is a grid point
    a0, a1 = env.agents
    a0.set_pos(torch.tensor([[0.3, -0.2]]), batch_index=None)
    a1.set_pos(torch.tensor([[0.974, 0.974]]), batch_index=None)  # the top-right corner cell
    _, rews, _, infos = env.step([torch.zeros(1, 2)] * 2)
    corner = math.exp(-0.5 * (0.674**2 + 1.174**2) / 0.05)
    torch.testing.assert_close(infos[0]["agent_sample"], torch.tensor([1.0]), atol=1e-5, rtol=0)
    torch.testing.assert_close(infos[1]["agent_sample"], torch.tensor([corner]), atol=1e-6, rtol=1e-4)
    torch.testing.assert_close(rews[0], torch.tensor([1.0 + corner]))
    assert scenario.sampled.sum() == 2 and scenario.sampled[0, 26, 16] and scenario.sampled[0, 39, 39]
    obs, rews, _, _ = env.step([torch.zeros(1, 2)] * 2)
    assert (rews[0] == 0).all()  # both cells spent
    neighbours = obs[0][0, 16:]
    expected = torch.tensor([math.exp(-0.5 * d2 / 0.05) for d2 in [0.0025] * 4 + [0.005] * 4])
    torch.testing.assert_close(neighbours, expected)
    # the corner agent: +x and +y (and the diagonals with them) lie outside the square
    corner_obs = obs[1][0, 16:]
    assert corner_obs[[0, 2, 5, 6, 7]].eq(0).all() and corner_obs[[1, 3, 4]].gt(0).all()


# ---------------------------------------------------------------------- heuristic
def test_heuristic_follows_the_richest_neighbour():
    policy = sampling.HeuristicPolicy()
    obs = torch.zeros(2, 24)
    obs[:, 4:16] = 0.2  # lidar: nothing in range
    obs[0, 16 + 2] = 0.8  # +y is richest
    obs[0, 16 + 0] = 0.1
    obs[1, 2:4] = torch.tensor([0.0, -0.3])  # nothing around: keep going (down)
    action = policy.compute_action(obs, 1.0)
    assert action.shape == (2, 2) and (action.abs() <= 1).all()
    assert action[0, 1] > 0.9 and 0 < action[0, 0] < action[0, 1]
    assert action[1, 1] < -0.5 and action[1, 0] == 0
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 12), 1.0)
    assert sampling.HeuristicPolicy(collisions=False).compute_action(torch.zeros(1, 12), 1.0).shape == (1, 2)


@pytest.mark.parametrize("kwargs", [{}, {"shared_rew": False, "n_agents": 4}], ids=["shared", "private"])
def test_heuristic_beats_random(kwargs):
    """16 envs x 100 steps, 8 per side, seed 0. Measured mean team return (shared), heuristic vs
    random: 61.8 vs 12.8; private rewards, per agent: 19-24 vs 0.6-6.4."""
    torch.manual_seed(0)
    env = make(16, **kwargs)
    n = env.n_agents
    returns = harness.play_lineups(
        env, [[RandomPolicy().compute_action] * n, [sampling.HeuristicPolicy(**kwargs).compute_action] * n], steps=100
    )
    random, heuristic = returns[:, 0], returns[:, 1]
    assert (heuristic > 2 * random + 5).all(), returns
