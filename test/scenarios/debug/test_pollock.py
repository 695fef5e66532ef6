"""``pollock`` (debug): API, parity with VMAS 1.5.2 (contacts, lidar), reset, heuristic.

The task pays 0 always, so the heuristic cannot beat random play on reward;
it is checked on clearance instead (distance to the nearest lidar hit).
Upstream is slow here (many contacts, an unbatched lidar): small crowds, few steps.
"""
from __future__ import annotations

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios.debug import pollock as scenario

NAME = "pollock"
SMALL = {"n_agents": 3, "n_lines": 3, "n_boxes": 3}


def make(num_envs: int = 4, **kwargs):
    return harness.make(scenario.Scenario(), num_envs, **kwargs)


def test_construction_and_kwargs():
    env = make(2)
    names = [e.name for e in env.world.entities]
    expected = [f"line {i}" for i in range(15)] + [f"box {i}" for i in range(15)] + [f"agent_{i}" for i in range(15)]
    assert names == expected
    world = env.world
    assert (world.dt, world._substeps, world._drag, world._collision_force) == (0.1, 5, 0.25, 500)
    assert (world.x_semidim, world.y_semidim) == (1, 1)
    assert all(a.shape.radius == 0.05 and a.u_multiplier == 0.7 and a.rotatable and not a.sensors for a in env.agents)
    assert env.get_from_scenario(True, False, False, False)[0][0].shape == (2, 1)
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1, **SMALL)
    for bad in ({"n_agents": 0}, {"n_boxes": -1}, {"n_lines": 1.5}, {"lidar": "yes"}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            make(2, **dict(SMALL, **bad))


@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream(mode):
    kwargs = dict(SPACE_MODES[mode], **SMALL, lidar=mode == "dict")
    harness.check_spaces(make(2, **kwargs), harness.make_upstream(NAME, 2, **kwargs), 2)


@pytest.mark.parametrize("kwargs, steps", [(SMALL, 30), (dict(SMALL, n_agents=2, lidar=True), 4)],
                         ids=["contacts", "lidar"])
def test_matches_upstream_vmas(kwargs, steps):
    """Free-running from a crowded start (every entity within 0.35 of the origin, in both envs):
    agents, rods and boxes push each other about."""
    up, ours = harness.make_upstream(NAME, 4, **kwargs), make(4, **kwargs)

    def crowd(up, ours) -> None:
        gen = torch.Generator().manual_seed(5)
        for e_up, e_ours in zip(up.world.entities, ours.world.entities):
            pos = (torch.rand(4, 2, generator=gen) * 2 - 1) * 0.35
            e_up.set_pos(pos.clone(), batch_index=None)
            e_ours.set_pos(pos.clone(), batch_index=None)

    harness.copy_start(up, ours, crowd)
    start = [e.state.pos.clone() for e in ours.world.landmarks]
    seen = run_lockstep(up, ours, seed=0, steps=steps)
    assert seen.fastest > 0.1 and seen.largest_reward == 0
    assert any((e.state.pos != p).any() for e, p in zip(ours.world.landmarks, start))  # something was pushed
    if kwargs.get("lidar"):
        obs = ours.get_from_scenario(True, False, False, False)[0][0]
        assert obs.shape == (4, 16) and (obs < 0.5).any()  # some ray hit something


@pytest.mark.parametrize("index", [1, [0, 3], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(4, **SMALL)
    for e in env.world.entities:  # off the spawn square, so a reset must visibly redraw everything
        e.set_pos(e.state.pos + 3.0, batch_index=None)
    harness.check_reset_at(env, index, mask_rows=[1, 2], bound=1.0)


def test_heuristic_keeps_clear():
    """8 envs x 40 steps each way with the lidar (seed 0). Returns are 0 for both; measured mean
    clearance (nearest lidar hit, 0.5 when none): heuristic ~0.45, random ~0.29."""
    policy = scenario.HeuristicPolicy(lidar=True, **SMALL)
    obs = torch.full((1, 16), 0.5)
    obs[0, 0] = 0.1  # something close along +x
    action = policy.compute_action(obs, 1.0)
    assert action[0, 0] < 0 and action.abs().max() <= 1
    assert (scenario.HeuristicPolicy().compute_action(torch.zeros(3, 1), 1.0) == 0).all()
    torch.manual_seed(0)
    env = make(16, seed=0, lidar=True, **SMALL)
    clearance = {"heuristic": [], "random": []}

    def watched(kind, act):
        def policy_fn(o, u_range):
            clearance[kind].append(o.min(dim=-1).values.mean())
            return act(o, u_range)
        return policy_fn

    random = lambda o, u: torch.rand(o.shape[0], 2) * 2 - 1  # noqa: E731
    lineups = [[watched("heuristic", policy.compute_action)] * 3, [watched("random", random)] * 3]
    returns = harness.play_lineups(env, lineups, steps=40)
    assert (returns == 0).all()
    heuristic, rand = (float(torch.stack(clearance[k]).mean()) for k in ("heuristic", "random"))
    assert heuristic > rand + 0.08, (heuristic, rand)
