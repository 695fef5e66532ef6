"""The compiled physics path (World.compile_physics / make_env(compile_physics=True)) equals the eager one.

torch.compile may fuse and reorder float ops, so the two paths agree to float
rounding, not bit for bit; over a short horizon (before contacts could amplify a
last-bit difference) states must match closely. Each case compiles once (~10 s).
"""
from __future__ import annotations

import pytest
import torch

import vmas_ros
from vmas_ros.simulator import physics

STEPS = 8


def _rollout(env, actions):
    states = []
    for step_actions in actions:
        env.step(step_actions)
        states.append(torch.cat([env.world.stacked_state(f) for f in ("pos", "vel", "rot", "ang_vel")], dim=-1).clone())
    return torch.stack(states)


# transport: sphere-sphere and box-sphere contacts; balance: lines, boxes and gravity
@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["transport", "balance"])
def test_compiled_step_equals_eager(device, scenario):
    eager = vmas_ros.make_env(scenario, num_envs=16, device=device, seed=3)
    compiled = vmas_ros.make_env(scenario, num_envs=16, device=device, seed=3, compile_physics=True)
    assert compiled.world.physics_compiled and not eager.world.physics_compiled
    gen = torch.Generator(device="cpu").manual_seed(0)
    actions = [
        [(torch.rand(16, eager.get_agent_action_size(a), generator=gen) * 2 - 1).to(device) for a in eager.agents]
        for _ in range(STEPS)
    ]
    from torch._dynamo.utils import counters

    compiled_frames = counters["stats"]["unique_graphs"]
    expected, got = _rollout(eager, actions), _rollout(compiled, actions)
    # the compiled world really ran a compiled graph (a no-op flag would pass the comparison)
    assert counters["stats"]["unique_graphs"] > compiled_frames
    assert torch.isfinite(got).all()
    # the agents moved, so the comparison is not between two resting worlds
    assert (expected[-1] - expected[0]).abs().max() > 1e-3
    torch.testing.assert_close(got, expected, atol=1e-5, rtol=1e-4)


def test_compile_physics_can_be_turned_off(device):
    env = vmas_ros.make_env("simple_spread", num_envs=2, device=device)
    env.world.compile_physics()
    assert env.world.physics_compiled
    env.world.compile_physics(enabled=False)
    assert env.world._physics_step is physics.step_planar


@pytest.mark.slow
def test_compiled_lidar_equals_eager(device):
    """flocking's LIDAR through the compiled ray kernels reads the same distances as the eager ones."""
    eager = vmas_ros.make_env("flocking", num_envs=16, device=device, seed=5)
    compiled = vmas_ros.make_env("flocking", num_envs=16, device=device, seed=5, compile_physics=True)
    for agent_e, agent_c in zip(eager.agents, compiled.agents):
        got, expected = agent_c.sensors[0].measure(), agent_e.sensors[0].measure()
        torch.testing.assert_close(got, expected, atol=1e-5, rtol=1e-5)
    # some rays hit an obstacle, so the comparison is not between two all-max readings
    assert (expected < agent_e.sensors[0].max_range).any()
    assert compiled.world._ray_kernels["sphere"] is not eager.world._ray_kernels["sphere"]
