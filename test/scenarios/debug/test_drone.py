"""``drone`` (debug): API, lock-step parity with VMAS 1.5.2 (done and model state too), resets, heuristic.

Oracle: ``vmas`` 1.5.2. Both worlds start from the same tilted, spinning
model state (after a reset every drone is level, and the +-1e-5 torques
would hardly move it), so the planar motion, contacts and the crash
``done`` are all exercised.
"""
from __future__ import annotations

import functools

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing.parity import run_lockstep, uniform_actions
from vmas_ros.scenarios.debug import drone
from vmas_ros.simulator.dynamics.drone import Drone

NAME = "drone"


def make(num_envs: int = 8, **kwargs):
    return harness.make(drone.Scenario(), num_envs, **kwargs)


def tilt_start(envs, seed: int, tilt: float, rate: float) -> None:
    """The same random roll, pitch (+-tilt) and body rates (+-rate) for every drone of every env in ``envs``."""
    gen = torch.Generator().manual_seed(seed)
    for agents in zip(*(env.agents for env in envs), strict=True):
        state = torch.zeros(envs[0].num_envs, 12)
        state[:, :2] = (torch.rand(state.shape[0], 2, generator=gen) * 2 - 1) * tilt
        state[:, 3:6] = (torch.rand(state.shape[0], 3, generator=gen) * 2 - 1) * rate
        for agent in agents:
            agent.dynamics.drone_state = state.clone()


# ------------------------------------------------------------------- construction
def test_construction_defaults_and_kwargs():
    env = make(2)
    assert [a.name for a in env.agents] == ["drone_0", "drone_1"]
    assert (env.world.dt, env.world._substeps) == (0.1, 10)
    for agent in env.agents:
        assert isinstance(agent.dynamics, Drone) and agent.dynamics.integration == "rk4" and agent.collide
        assert agent.action_size == 3 and list(agent.u_range) == [1e-5] * 3
    assert [a.name for a in make(2, n_agents=3).agents] == ["drone_0", "drone_1", "drone_2"]
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for bad in (0, 2.0):
        with pytest.raises(ValueError, match="n_agents"):
            make(2, n_agents=bad)
    with pytest.raises(TypeError, match="width"):
        drone.HeuristicPolicy(width=1)


@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream(mode):
    harness.check_spaces(make(4, **SPACE_MODES[mode]), harness.make_upstream(NAME, 4, **SPACE_MODES[mode]), steps=3)


# ------------------------------------------------------------------------- parity
def compare_done(up, ours, dones: list, gen: torch.Generator):
    """Actions for the next lock-step, after checking ``done`` and every model state agree."""
    assert torch.equal(ours.done(), up.done())
    for a_up, a_ours in zip(up.agents, ours.agents, strict=True):
        torch.testing.assert_close(a_ours.dynamics.drone_state, a_up.dynamics.drone_state, atol=1e-4, rtol=1e-4)
    dones.append(ours.done().clone())
    return uniform_actions(up, gen)


@pytest.mark.parametrize("n_agents", [2, 3])
def test_matches_upstream_vmas(n_agents):
    """Tilts up to 28 degrees spinning at up to 0.3 rad/s: some drones cross 30 degrees (done)."""
    up, ours = harness.make_upstream(NAME, 6, n_agents=n_agents), make(6, n_agents=n_agents)
    harness.copy_start(up, ours)
    tilt_start((up, ours), seed=n_agents, tilt=0.49, rate=0.3)
    dones: list = []
    seen = run_lockstep(up, ours, seed=0, steps=40, actions=functools.partial(compare_done, up, ours, dones))
    dones = torch.stack(dones)
    assert not dones[0].all() and dones[-1].sum() > dones[0].sum() and seen.fastest > 1.0


# -------------------------------------------------------------------------- reset
@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(8)
    tilt_start((env,), seed=0, tilt=0.2, rate=0.05)
    for _ in range(3):
        env.step(env.get_random_actions())
    for agent in env.agents:
        agent.set_pos(agent.state.pos + 3.0, batch_index=None)
    state = lambda e: {f"{a.name}.model": a.dynamics.drone_state for a in e.agents}  # noqa: E731
    check = harness.check_reset_at(env, index, mask_rows=[0, 5, 6], scenario_state=state, bound=1.0)
    for agent in env.agents:
        assert (agent.dynamics.drone_state[check.chosen] == 0).all()
        assert (agent.dynamics.drone_state[~check.chosen] != 0).any()


# ---------------------------------------------------------------------- heuristic
def test_heuristic_action_shape_range_and_memory():
    policy = drone.HeuristicPolicy(n_agents=1)  # one call slot: every call is the same drone's
    obs = torch.tensor([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 2.0, -1.0]])
    first = policy.compute_action(obs, [1e-5] * 3)
    assert first.shape == (2, 3) and (first[0] == 0).all() and (first[:, 2] == 0).all()
    assert (first.abs() <= 1e-5).all() and first[1, 1] < 0 and first[1, 0] < 0  # pitched forward, rolled right
    policy.compute_action(obs[:1], [1e-5] * 3)  # another batch size: memory starts afresh
    with pytest.raises(ValueError, match="continuous"):
        drone.HeuristicPolicy(continuous_action=False)


def test_heuristic_levels_the_drone():
    """From tilts up to 0.02 rad spinning at up to 0.005 rad/s (the torques are tiny), 200 steps,
    one policy instance serving every drone in agent order, as ``vmas-ros evaluate`` and sim_node use
    it (it keeps a memory per agent). Largest |roll|, |pitch| at the end, mean over 8 envs each way;
    measured: heuristic ~3e-5 rad, random ~0.07 rad (drifting further)."""
    torch.manual_seed(0)
    env = make(16)
    env.reset()
    tilt_start((env,), seed=0, tilt=0.02, rate=0.005)
    shared = drone.HeuristicPolicy()
    policies = [shared] * env.n_agents
    obs = env.get_from_scenario(True, False, False, False)[0]
    for _ in range(200):
        rand = env.get_random_actions()
        actions = [torch.cat([p.compute_action(o[:8], a.u_range), r[8:]])
                   for p, o, r, a in zip(policies, obs, rand, env.agents)]
        obs, _, dones, _ = env.step(actions)
        assert all(torch.isfinite(o).all() for o in obs)
    tilt = torch.stack([a.dynamics.drone_state[:, :2].abs().amax(-1) for a in env.agents]).amax(0)
    heuristic, random = tilt[:8].mean(), tilt[8:].mean()
    assert heuristic < 1e-3 and random > 0.02, (heuristic, random)
