"""``vel_control`` (debug): API, lock-step parity with VMAS 1.5.2 (info and controllers too), resets, heuristic.

Oracle: ``vmas`` 1.5.2 (same start -> same states, observations, rewards,
``energy_expenditure`` info and PID memory).
"""
from __future__ import annotations

import functools

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing.parity import run_lockstep, uniform_actions
from vmas_ros.scenarios.debug import vel_control
from vmas_ros.simulator.controllers.velocity_controller import VelocityController

NAME = "vel_control"


def make(num_envs: int = 8, **kwargs):
    return harness.make(vel_control.Scenario(), num_envs, **kwargs)


# ------------------------------------------------------------------- construction
def test_construction_defaults_and_kwargs():
    env = make(2)
    world = env.world
    assert [a.name for a in env.agents] == ["agent 0", "agent 1", "agent 2"]
    assert [l.name for l in world.landmarks] == ["landmark 0"]
    assert (world.dt, world._substeps, world._drag, world._linear_friction) == (0.05, 4, 0.0, 0.1)
    assert [a.f_range for a in env.agents] == [1.1, None, 30.0] and [a.mass for a in env.agents] == [1, 1, 1]
    assert all(a.u_range == 1 and not a.collide for a in env.agents)
    for agent in env.agents:
        ctrl = agent.controller
        assert isinstance(ctrl, VelocityController) and (ctrl.ctrl_gain, ctrl.integralTs, ctrl.derivativeTs) == (2, 6, 0.002)
    landmark = world.landmarks[0]
    assert landmark.movable and not landmark.collide
    assert (torch.stack([a.state.pos for a in env.agents]) == torch.tensor([-1.0, 0.0])).all()
    assert make(2, green_mass=3.5).agents[0].mass == 3.5


def test_unknown_kwargs_warn_and_bad_values_raise():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for bad in (0, -1.0, "heavy", float("inf")):
        with pytest.raises(ValueError, match="green_mass"):
            make(2, green_mass=bad)
    with pytest.raises(ValueError, match="green_mass"):
        vel_control.HeuristicPolicy(green_mass=0)


@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream(mode):
    harness.check_spaces(make(4, **SPACE_MODES[mode]), harness.make_upstream(NAME, 4, **SPACE_MODES[mode]), steps=3)


# ------------------------------------------------------------------------- parity
def compare_extras(up, ours, seen: list, gen: torch.Generator):
    """Actions for the next lock-step; first checks the state ``run_lockstep`` does not: every
    agent's info and the PID memory (integrated and last error) after the previous step."""
    for a_up, a_ours in zip(up.agents, ours.agents, strict=True):
        info_up, info = up.scenario.info(a_up), ours.scenario.info(a_ours)
        assert list(info) == list(info_up) == ["energy_expenditure"]
        torch.testing.assert_close(info["energy_expenditure"], info_up["energy_expenditure"], atol=1e-4, rtol=0)
        for name in ("accum_errs", "prev_err"):
            torch.testing.assert_close(getattr(a_ours.controller, name), getattr(a_up.controller, name),
                                       atol=1e-4, rtol=0)
    seen.append(float(ours.agents[1].controller.accum_errs.abs().max()))
    return uniform_actions(up, gen)


@pytest.mark.parametrize("kwargs", [{}, {"green_mass": 3}], ids=["default", "heavy-green"])
def test_matches_upstream_vmas(kwargs):
    up, ours = harness.make_upstream(NAME, 6, **kwargs), make(6, **kwargs)
    harness.copy_start(up, ours)
    integrals: list = []
    seen = run_lockstep(up, ours, seed=0, steps=50, actions=functools.partial(compare_extras, up, ours, integrals))
    assert seen.largest_reward > 1 and seen.fastest > 0.2 and max(integrals) > 0.01
    assert not any(ours.done()) and not any(up.done())


def test_matches_upstream_vmas_with_small_and_saturating_commands():
    """Commands inside the dead band (zeroed), and long ones (clipped to the unit disc, and
    rate-limited in x for agent 1)."""
    up, ours = harness.make_upstream(NAME, 6), make(6)
    harness.copy_start(up, ours)
    small = torch.tensor([True, True, True, False, False, False]).unsqueeze(-1)  # per env

    def actions(g: torch.Generator):
        draws = [torch.rand(6, 2, generator=g) * 2 - 1 for _ in up.agents]
        # small: norm < 0.08; large: a corner of the action box (norm sqrt(2), clipped to 1)
        return [torch.where(small, 0.05 * d, d.sign()) for d in draws]

    run_lockstep(up, ours, seed=1, steps=30, actions=actions)
    assert (ours.agents[0].state.vel[:3] == 0).all() and (ours.agents[0].state.vel[3:] != 0).all()


# -------------------------------------------------------------------------- reset
def controller_state(env) -> dict:
    state = {"energy": env.scenario.energy_expenditure}
    for agent in env.agents:
        state[f"{agent.name}.accum"] = agent.controller.accum_errs
        state[f"{agent.name}.prev"] = agent.controller.prev_err
    return state


@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(8)
    for _ in range(5):
        env.step(env.get_random_actions())
    for entity in env.world.entities:  # away from the start (and the landmark off the origin)
        entity.set_pos(entity.state.pos + 0.5, batch_index=None)
    check = harness.check_reset_at(env, index, mask_rows=[0, 5, 6], scenario_state=controller_state)
    chosen = check.chosen
    assert all((a.state.pos[chosen] == torch.tensor([-1.0, 0.0])).all() for a in env.agents)
    assert (env.world.landmarks[0].state.pos[chosen] == 0).all()
    for agent in env.agents:
        assert (agent.controller.accum_errs[chosen] == 0).all() and (agent.controller.prev_err[chosen] == 0).all()
        assert (agent.controller.accum_errs[~chosen] != 0).any()


# ---------------------------------------------------------------------- heuristic
def test_heuristic_action_shape_range_and_braking():
    policy = vel_control.HeuristicPolicy()
    obs = torch.tensor([[0.0, 0.0, 0.0, 0.0], [0.3, 0.1, 2.0, -2.0], [0.0, 0.0, 0.5, 0.0]])
    action = policy.compute_action(obs, 1.0)
    assert action.shape == (3, 2) and (action.norm(dim=-1) <= 1.0 + 1e-6).all()
    assert (action[0] == 0).all() and action[2, 0] == pytest.approx(0.45)  # at rest: nothing; moving: coast
    with pytest.raises(ValueError, match="continuous"):
        vel_control.HeuristicPolicy(continuous_action=False)


def test_heuristic_beats_random():
    """Returns over 100 steps (8 envs each way). Measured: heuristic 0.0 (agents never leave their
    start, the controllers output no force), random about -2.5e3 per agent (shared reward)."""
    torch.manual_seed(0)
    policy = vel_control.HeuristicPolicy()
    returns = harness.play_lineups(make(16), [[policy.compute_action] * 3, [None] * 3])
    heuristic, random = returns[:, 0], returns[:, 1]
    assert (heuristic > -1.0).all() and (random < -1000).all(), returns
    assert torch.equal(returns[0], returns[1]) and torch.equal(returns[1], returns[2])  # one shared reward
