"""RideAlongSnapshot: the published env's snapshot computed by the compiled step equals the one gathered after it."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import vmas_ros
from vmas_ros.ros import convert
from vmas_ros.ros.ride_along import RideAlongSnapshot
from vmas_ros.simulator.sensors import CollidesWith, Lidar

pytestmark = pytest.mark.slow  # compiles the step (a few seconds each)


def _compiled_env(device, num_envs: int = 2, rays: int = 9, entity_filter=CollidesWith):
    env = vmas_ros.make_env("simple_spread", num_envs=num_envs, device=device, seed=3, n_agents=3)
    world = env.world
    for agent in world.agents:
        agent.add_sensor(Lidar(world, n_rays=rays, max_range=2.0, entity_filter=entity_filter(agent)))
    world.compile_physics()
    return env, convert.agent_lidars(world)


def _step(env, seed: int) -> None:
    g = torch.Generator().manual_seed(seed)
    env.step([(torch.rand(env.num_envs, 2, generator=g) * 2 - 1).to(env.device) for _ in env.agents])


def _assert_same(ride: convert.Snapshot, gathered: convert.Snapshot) -> None:
    for name in ("pos", "vel", "rot", "ang_vel"):
        np.testing.assert_array_equal(getattr(ride, name), getattr(gathered, name), err_msg=name)
    assert ride.scans.keys() == gathered.scans.keys()
    for i in gathered.scans:
        for a, b in zip(ride.scans[i], gathered.scans[i], strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
    assert ride.all_finite() == gathered.all_finite()


def test_the_step_computes_the_snapshot_of_the_published_env(device):
    env, lidars = _compiled_env(device)
    world = env.world
    assert RideAlongSnapshot.suits(world, lidars)
    ride = RideAlongSnapshot(lidars)
    assert ride.take(world, 1) is None, "the first take plans: the current state was computed without it"
    assert ride.active
    moved_into_view = False
    for step in range(3):
        _step(env, step)
        snap = ride.take(world, 1)
        assert snap is not None and snap.finite is True, "right after a compiled step: the step's own output"
        _assert_same(snap, convert.Snapshot.take(world, 1, lidars))
        moved_into_view |= any((s < 2.0).any() for ss in snap.scans.values() for s in ss)
        assert ride.take(world, 1) is None, "handed out once"
    assert moved_into_view, "some ray hits something (the scans are not all max_range)"
    # the published env changes: gathered by the caller once, then that env's snapshot from the same
    # kernel (the env is a tensor the compiled step reads: no new kernel, no new compile)
    kernel = world._state_kernels[ride._handle]
    assert ride.take(world, 0) is None
    _step(env, 7)
    _assert_same(ride.take(world, 0), convert.Snapshot.take(world, 0, lidars))
    assert world._state_kernels[ride._handle] is kernel
    # the state changed after the step (a setter): not the step's snapshot any more
    _step(env, 8)
    world.agents[0].set_pos(torch.zeros(env.num_envs, 2, device=env.device), batch_index=None)
    assert ride.take(world, 0) is None


def test_a_non_finite_state_is_flagged_by_the_step(device):
    env, lidars = _compiled_env(device, num_envs=1)
    world = env.world
    ride = RideAlongSnapshot(lidars)
    ride.take(world, 0)
    _step(env, 0)
    assert ride.take(world, 0).all_finite()
    world.agents[1].state.pos[0, 0] = float("nan")  # diverged dynamics (setters refuse NaN)
    _step(env, 1)
    snap = ride.take(world, 0)
    assert snap is not None and snap.finite is False
    gathered = convert.Snapshot.take(world, 0, lidars)
    assert not gathered.all_finite()
    np.testing.assert_array_equal(snap.pos, gathered.pos)


def test_filters_that_read_the_state_are_not_ridden_along(device):
    """A filter without ``layout_static`` may pick other targets every step: the planned lidar constants
    could go stale, so the node gathers such snapshots after the step (take: None)."""
    def state_filter(agent):
        return lambda other: other.collides(agent) and agent.collides(other)

    env, lidars = _compiled_env(device, entity_filter=state_filter)
    world = env.world
    ride = RideAlongSnapshot(lidars)
    for step in range(2):
        assert ride.take(world, 0) is None
        _step(env, step)
    assert not ride.active


def test_no_lidars_rides_along_the_state_alone(device):
    env = vmas_ros.make_env("simple_spread", num_envs=3, device=device, seed=1, n_agents=2)
    world = env.world
    world.compile_physics()
    ride = RideAlongSnapshot({})
    ride.take(world, 2)
    _step(env, 0)
    snap = ride.take(world, 2)
    assert snap is not None and snap.scans == {}
    _assert_same(snap, convert.Snapshot.take(world, 2, {}))


def test_eager_worlds_and_many_envs_do_not_suit(device):
    env = vmas_ros.make_env("simple_spread", num_envs=2, device=device, seed=0)
    assert not RideAlongSnapshot.suits(env.world, {})
    env.world.compile_physics()
    assert RideAlongSnapshot.suits(env.world, {})
    many = vmas_ros.make_env("simple_spread", num_envs=5000, device=device, seed=0)
    many.world.compile_physics()
    assert not RideAlongSnapshot.suits(many.world, {})
