"""``diff_drive`` (debug): API, lock-step parity with VMAS 1.5.2, resets, heuristic.

Oracle: ``vmas`` 1.5.2 (same start -> same states, observations and rewards).
The reward is identically zero, so the heuristic is judged on the task it
sets itself (going home to the origin): ``home_distances`` here is shared
with the other dynamics debug scenarios' tests.
"""
from __future__ import annotations

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.scenarios.debug import diff_drive
from vmas_ros.simulator.dynamics.diff_drive import DiffDrive
from vmas_ros.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation

NAME = "diff_drive"


def make(num_envs: int = 8, **kwargs):
    return harness.make(diff_drive.Scenario(), num_envs, **kwargs)


# ------------------------------------------------------------------- helpers
def crowd_start(up, ours, spread: float = 0.12, seed: int = 0) -> None:
    """Every agent of both envs within ``spread`` of the origin, at rest: they bump into each other."""
    gen = torch.Generator().manual_seed(seed)
    for a_up, a_ours in zip(up.agents, ours.agents, strict=True):
        pos = (torch.rand(up.num_envs, 2, generator=gen) * 2 - 1) * spread
        a_up.set_pos(pos.clone(), batch_index=None)
        a_ours.set_pos(pos.clone(), batch_index=None)


def home_distances(env, policy, steps: int = 100) -> torch.Tensor:
    """Mean distance of every agent to the origin over the second half of a rollout from
    ``env.reset()``: the first half of the envs play ``policy``, the second half at random.
    Returns [2] (heuristic, random); every observation must stay finite."""
    half = env.num_envs // 2
    obs = env.reset()
    distances = []
    for _ in range(steps):
        rand = env.get_random_actions()
        actions = [
            torch.cat([policy.compute_action(o[:half], a.u_range), r[half:]])
            for o, r, a in zip(obs, rand, env.agents, strict=True)
        ]
        obs, _, _, _ = env.step(actions)
        assert all(torch.isfinite(o).all() for o in obs)
        distances.append(torch.stack([o[:, :2].norm(dim=-1) for o in obs], dim=1))  # [B, n_agents]
    late = torch.stack(distances[steps // 2:]).mean(dim=(0, 2))  # [B]
    return torch.stack([late[:half].mean(), late[half:].mean()])


# ------------------------------------------------------------------- construction
def test_construction_defaults_and_kwargs():
    env = make(2)
    assert [a.name for a in env.agents] == ["diff_drive_0", "holo_rot_1"] and env.world.landmarks == []
    assert (env.world.dt, env.world._substeps, env.world._drag) == (0.1, 10, 0.25)
    robot, holo = env.agents
    assert isinstance(robot.dynamics, DiffDrive) and robot.dynamics.integration == "rk4"
    assert isinstance(holo.dynamics, HolonomicWithRotation)
    assert (list(robot.u_range), list(holo.u_range), list(holo.action.u_multiplier)) == ([1, 1], [1, 1, 1], [1, 1, 0.001])
    assert all(a.collide and a.shape.radius == 0.05 for a in env.agents)
    assert [a.name for a in make(2, n_agents=4).agents] == ["diff_drive_0", "holo_rot_1", "holo_rot_2", "holo_rot_3"]
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="n_agents"):
            make(2, n_agents=bad)
    with pytest.raises(TypeError, match="width"):
        diff_drive.HeuristicPolicy(width=1)


@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream(mode):
    harness.check_spaces(make(4, **SPACE_MODES[mode]), harness.make_upstream(NAME, 4, **SPACE_MODES[mode]), steps=3)


# ------------------------------------------------------------------------- parity
@pytest.mark.parametrize("n_agents", [2, 3])
def test_matches_upstream_vmas(n_agents):
    up, ours = harness.make_upstream(NAME, 6, n_agents=n_agents), make(6, n_agents=n_agents)
    harness.copy_start(up, ours)
    seen = run_lockstep(up, ours, seed=n_agents, steps=50)
    assert seen.fastest > 0.5
    assert ours.agents[0].state.rot.abs().max() > 0.1  # the robot turned


def test_matches_upstream_vmas_in_contact():
    """Agents start packed around the origin, so the discs collide from the first steps."""
    up, ours = harness.make_upstream(NAME, 6, n_agents=3), make(6, n_agents=3)
    crowd_start(up, ours)
    harness.copy_start(up, ours)
    before = torch.stack([a.state.pos for a in ours.agents]).clone()
    run_lockstep(up, ours, seed=1, steps=10, actions=lambda g: [torch.zeros(6, a.action_size) for a in up.agents])
    assert (torch.stack([a.state.pos for a in ours.agents]) - before).norm(dim=-1).max() > 0.01  # pushed apart
    run_lockstep(up, ours, seed=2, steps=30)


# -------------------------------------------------------------------------- reset
@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(8, n_agents=3)
    for _ in range(5):
        env.step(env.get_random_actions())
    for agent in env.agents:  # out of the spawn square, so a reset must visibly redraw
        agent.set_pos(agent.state.pos + 3.0, batch_index=None)
    check = harness.check_reset_at(env, index, mask_rows=[0, 5, 6], bound=1.0)
    chosen = check.chosen
    assert all((a.state.rot[chosen] == 0).all() and (a.state.ang_vel[chosen] == 0).all() for a in env.agents)
    pos = torch.stack([a.state.pos for a in env.agents], dim=1)[chosen]
    assert (torch.cdist(pos, pos) + 9 * torch.eye(3) >= 0.1).all()


# ---------------------------------------------------------------------- heuristic
def test_heuristic_action_shapes_and_ranges():
    env = make(4)
    policy = diff_drive.HeuristicPolicy()
    obs = env.reset()
    for o, agent in zip(obs, env.agents):
        action = policy.compute_action(o * 50, agent.u_range)  # far away and fast: saturates
        assert action.shape == (4, agent.action_size)
        assert (action.abs() <= torch.tensor(agent.u_range)).all()
    with pytest.raises(ValueError, match="continuous"):
        diff_drive.HeuristicPolicy(continuous_action=False)


@pytest.mark.parametrize("n_agents", [2, 3])
def test_heuristic_goes_home_and_beats_random(n_agents):
    """Mean distance to the origin over steps 50-100, heuristic vs random (8 envs each).
    Measured: 0.07 vs 0.89 (n_agents=2), 0.07 vs 0.76 (n_agents=3)."""
    torch.manual_seed(0)
    heuristic, random = home_distances(make(16, n_agents=n_agents), diff_drive.HeuristicPolicy(n_agents=n_agents))
    assert heuristic < 0.2 and random > 3 * heuristic, (heuristic, random)
