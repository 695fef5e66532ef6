"""``het_mass`` (debug): API, parity with VMAS 1.5.2, mass draws and resets, heuristic.

Oracle: ``vmas`` 1.5.2. Its masses come from NumPy's global generator, ours
from torch's, so the parity test copies upstream's masses (and start) into ours.
"""
from __future__ import annotations

import math

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import parity, vmas_states
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios.debug import het_mass

NAME = "het_mass"


def make(num_envs: int = 8, **kwargs):
    return harness.make(het_mass.Scenario(), num_envs, **kwargs)


def masses(env) -> list:
    return [a.mass for a in env.agents]


# ------------------------------------------------------------------- construction
def test_construction_defaults():
    env = make(4)
    world = env.world
    assert [a.name for a in env.agents] == ["agent 0", "agent 1"] and world.landmarks == []
    assert (world.dt, world.substeps, world.drag) == (0.1, 1, 0.25)
    assert all(not a.collide and a.f_range == 1 and a.u_range == 1 for a in env.agents)
    green, blue = masses(env)
    assert 3 <= green <= 5 and 1 <= blue <= 3
    assert all((a.state.pos.abs() <= 1).all() and (a.state.vel == 0).all() for a in env.agents)
    assert env.agents[0].state.pos.std(dim=0).min() > 0  # drawn per env


def test_kwargs_set_the_mass_ranges():
    env = make(2, green_mass=10, blue_mass=0.5, mass_noise=0.25)
    green, blue = masses(env)
    assert 9.75 <= green <= 10.25 and 0.25 <= blue <= 0.75
    env = make(2, mass_noise=0)
    assert masses(env) == [4.0, 2.0]


def test_unknown_kwargs_warn_and_bad_values_raise():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for bad in ({"mass_noise": -1}, {"blue_mass": 1}, {"green_mass": 0.5}, {"blue_mass": "2"}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            make(2, **bad)
    with pytest.raises(ValueError, match="blue_mass"):
        het_mass.HeuristicPolicy(blue_mass=-1)
    with pytest.raises(TypeError, match="n_agents"):
        het_mass.HeuristicPolicy(n_agents=2)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode):
    options = SPACE_MODES[mode]
    obs, _ = harness.check_spaces(make(4, **options), harness.make_upstream(NAME, 4, **options), steps=3)
    values = list(obs.values()) if isinstance(obs, dict) else obs
    assert [v.shape[1] for v in values] == [4, 4]


# ------------------------------------------------------------------------- parity
@pytest.mark.parametrize("kwargs", [{}, {"green_mass": 1.5, "blue_mass": 6, "mass_noise": 0.5}], ids=["default", "swapped"])
def test_matches_upstream_vmas(kwargs):
    up, ours = harness.make_upstream(NAME, 8, **kwargs), make(8, **kwargs)
    harness.copy_start(up, ours, vmas_states.het_mass)
    assert masses(ours) != [4.0, 2.0]
    seen = run_lockstep(up, ours, seed=0, steps=50)
    assert seen.fastest > 0.05 and seen.largest_reward > 0.1
    _, _, dones_up, info_up = up.step([torch.ones(8, 2)] * 2)
    _, _, dones, info = ours.step([torch.ones(8, 2)] * 2)
    assert torch.equal(dones, dones_up) and not dones.any()
    parity.assert_same_infos(info, info_up)


def test_only_x_acts_and_reward_terms():
    """A pure y push does nothing and costs nothing; an x push is charged |u| / sqrt(2) x 0.17."""
    env = make(3, mass_noise=0)
    _, rews, _, info = env.step([torch.tensor([[0.0, 1.0]] * 3), torch.tensor([[0.5, -1.0]] * 3)])
    assert (env.agents[0].state.vel == 0).all() and (env.agents[1].state.vel[:, 1] == 0).all()
    torch.testing.assert_close(env.agents[1].state.vel[:, 0], torch.full((3,), 0.5 / 2 * 0.1))
    torch.testing.assert_close(info[0]["energy_expenditure"], torch.full((3,), -0.17 * 0.5 / math.sqrt(2)))
    torch.testing.assert_close(info[1]["max_speed"], torch.full((3,), 0.025))
    torch.testing.assert_close(rews[0], rews[1])


# -------------------------------------------------------------------------- reset
@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    """A partial reset redraws the chosen envs' positions and keeps the batch's masses."""
    env = make(8)
    for _ in range(3):
        env.step([torch.rand(8, 2) * 2 - 1 for _ in env.agents])
    before = masses(env)
    harness.check_reset_at(env, index, mask_rows=[0, 5, 6], bound=1.0)
    assert masses(env) == before


def test_full_resets_redraw_the_masses():
    env = make(4)
    seen = {tuple(masses(env))}
    for _ in range(3):
        env.reset()
        seen.add(tuple(masses(env)))
    assert len(seen) == 4
    env.reset_at(list(range(4)))  # every env selected: a full restart
    assert tuple(masses(env)) not in seen


# ---------------------------------------------------------------------- heuristic
def test_heuristic_action_shape_and_choice():
    policy = het_mass.HeuristicPolicy()
    # at rest; fast (the light agent); slow (the heavy one, coasting); moving left fast
    obs = torch.tensor([[0.3, 0.2, 0.0, 0.0], [0, 0, 0.2, 0.0], [0, 0, 0.02, 0.0], [0, 0, -0.1, 0.0]])
    action = policy.compute_action(obs, 1.0)
    assert action.shape == (4, 2) and (action[:, 1] == 0).all()
    assert action[:, 0].tolist() == [1.0, 1.0, 0.0, -1.0]
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(2, 6), 1.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_heuristic_beats_random(seed):
    """32 envs x 100 steps, half heuristic pairs and half random pairs (masses drawn once per seed).

    Measured team returns (heuristic / random): seed 0: 4.9 / -8.3, seed 1:
    4.9 / -8.2, seed 2: 4.2 / -8.5 (the heuristic's grows as the light
    agent's mass falls). Required: the heuristic positive, and ahead by 10.
    """
    torch.manual_seed(seed)
    env = make(32, seed=seed)
    policy = het_mass.HeuristicPolicy().compute_action
    returns = harness.play_lineups(env, [[policy, policy], [None, None]], steps=100)
    heuristic, random = returns[0].tolist()
    assert heuristic > 0 and heuristic > random + 10, (masses(env), returns)
