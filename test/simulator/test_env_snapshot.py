"""EnvSnapshot: the published env's state and lidar ranges as one host vector, computed by a compiled step
(riding along as a state kernel) or gathered after it, and the same either way."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import vmas_ros
from vmas_ros.simulator.env_snapshot import EnvSnapshot, gather
from vmas_ros.simulator.sensors import CollidesWith, Lidar, world_lidars
from vmas_ros.simulator.threads import limit_threads_for_small_batches
from vmas_ros.simulator.thresholds import RIDE_ALONG_MAX_ELEMENTS, SMALL_BATCH_MAX_ENVS


def _env(device, num_envs: int = 2, rays: int = 9, entity_filter=CollidesWith, compiled: bool = True):
    env = vmas_ros.make_env("simple_spread", num_envs=num_envs, device=device, seed=3, n_agents=3)
    world = env.world
    for agent in world.agents:
        agent.add_sensor(Lidar(world, n_rays=rays, max_range=2.0, entity_filter=entity_filter(agent)))
    if compiled:
        world.compile_physics()
    return env, world_lidars(world)


def _step(env, seed: int) -> None:
    g = torch.Generator().manual_seed(seed)
    env.step([(torch.rand(env.num_envs, 2, generator=g) * 2 - 1).to(env.device) for _ in env.agents])


def _assert_same(taken: np.ndarray, gathered: np.ndarray, n_entities: int) -> None:
    """The state bit for bit; the ranges to float rounding (a compiled cast against the eager one)."""
    assert taken.shape == gathered.shape
    np.testing.assert_array_equal(taken[: 6 * n_entities], gathered[: 6 * n_entities])
    np.testing.assert_allclose(taken[6 * n_entities:], gathered[6 * n_entities:], rtol=1e-5, atol=1e-5)


def test_gather_lays_out_the_state_then_every_lidar(device):
    env, lidars = _env(device, num_envs=3, compiled=False)
    _step(env, 0)
    world, n = env.world, len(env.world.entities)
    values = gather(world, 2, lidars)
    assert values.shape == (6 * n + sum(s.n_rays for s in lidars),)
    state = values[: 6 * n].reshape(6, n)
    for k, entity in enumerate(world.entities):
        np.testing.assert_array_equal(state[0:2, k], entity.state.pos[2].cpu().numpy())
        np.testing.assert_array_equal(state[3:5, k], entity.state.vel[2].cpu().numpy())
        assert state[2, k] == entity.state.rot[2, 0].item() and state[5, k] == entity.state.ang_vel[2, 0].item()
    ranges = np.split(values[6 * n:], len(lidars))
    for lidar, scan in zip(lidars, ranges):
        np.testing.assert_array_equal(scan, lidar.cast_alone()[2].cpu().numpy())


def test_eager_worlds_and_many_envs_gather(device):
    env, lidars = _env(device, compiled=False)
    snapshot = EnvSnapshot(env.world, lidars)
    assert not snapshot.rides_along
    _step(env, 1)
    taken = snapshot.take(1)
    assert taken.finite is None
    np.testing.assert_array_equal(taken.values, gather(env.world, 1, lidars))
    many = vmas_ros.make_env("simple_spread", num_envs=RIDE_ALONG_MAX_ELEMENTS + 1, device=device, seed=0)
    many.world.compile_physics()
    assert not EnvSnapshot(many.world, []).rides_along
    assert EnvSnapshot(env.world, []).rides_along is False
    env.world.compile_physics()
    assert EnvSnapshot(env.world, []).rides_along


@pytest.mark.slow  # compiles the step (a few seconds each)
def test_the_step_computes_the_snapshot_of_the_published_env(device, monkeypatch):
    env, lidars = _env(device)
    world, n = env.world, len(env.world.entities)
    snapshot = EnvSnapshot(world, lidars)
    assert snapshot.rides_along
    assert snapshot.take(1).finite is None, "the first take plans: the current state was computed without it"
    assert snapshot.computed_by_step
    moved_into_view = False
    for step in range(3):
        _step(env, step)
        taken = snapshot.take(1)
        assert taken.finite is True, "right after a compiled step: the step's own output"
        _assert_same(taken.values, gather(world, 1, lidars), n)
        moved_into_view |= bool((taken.values[6 * n:] < 2.0).any())
        again = snapshot.take(1)
        assert again.finite is None, "handed out once: then gathered"
        _assert_same(again.values, taken.values, n)
    assert moved_into_view, "some ray hits something (the scans are not all max_range)"
    # the published env changes: gathered once, then that env's from the same kernel (the env is a
    # tensor the compiled step reads: no new kernel, no new compile)
    registered = []
    for name in ("add_state_kernel", "replace_state_kernel"):
        monkeypatch.setattr(world, name, lambda *args, name=name: registered.append(name))
    assert snapshot.take(0).finite is None
    _step(env, 7)
    taken = snapshot.take(0)
    assert taken.finite is True
    _assert_same(taken.values, gather(world, 0, lidars), n)
    assert not registered, "the same kernel gathers the other env"
    # the state changed after the step (a setter): not the step's snapshot any more
    _step(env, 8)
    world.agents[0].set_pos(torch.zeros(env.num_envs, 2, device=env.device), batch_index=None)
    assert snapshot.take(0).finite is None


@pytest.mark.slow
def test_a_non_finite_state_is_flagged_by_the_step(device):
    env, lidars = _env(device, num_envs=1)
    world = env.world
    snapshot = EnvSnapshot(world, lidars)
    snapshot.take(0)
    _step(env, 0)
    assert snapshot.take(0).finite is True
    world.agents[1].state.pos[0, 0] = float("nan")  # diverged dynamics (setters refuse NaN)
    _step(env, 1)
    taken = snapshot.take(0)
    assert taken.finite is False
    gathered = gather(world, 0, lidars)
    n = len(world.entities)
    assert not np.isfinite(gathered[: 6 * n]).all()
    np.testing.assert_array_equal(taken.values[: 6 * n], gathered[: 6 * n])


@pytest.mark.slow
def test_filters_that_read_the_state_are_gathered(device):
    """A filter without ``layout_static`` may pick other targets every step: the planned lidar constants
    could go stale, so such snapshots are gathered after the step."""
    def state_filter(agent):
        return lambda other: other.collides(agent) and agent.collides(other)

    env, lidars = _env(device, entity_filter=state_filter)
    snapshot = EnvSnapshot(env.world, lidars)
    for step in range(2):
        taken = snapshot.take(0)
        assert taken.finite is None
        _step(env, step)
    assert not snapshot.computed_by_step
    np.testing.assert_array_equal(snapshot.take(0).values, gather(env.world, 0, lidars))


@pytest.mark.slow
def test_no_lidars_rides_along_the_state_alone(device):
    env = vmas_ros.make_env("simple_spread", num_envs=3, device=device, seed=1, n_agents=2)
    world = env.world
    world.compile_physics()
    snapshot = EnvSnapshot(world, [])
    snapshot.take(2)
    _step(env, 0)
    taken = snapshot.take(2)
    assert taken.finite is True
    np.testing.assert_array_equal(taken.values, gather(world, 2, []))


def test_small_batches_step_on_one_thread():
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        assert limit_threads_for_small_batches(SMALL_BATCH_MAX_ENVS + 1) == 2, "large batches keep torch's threads"
        assert limit_threads_for_small_batches(SMALL_BATCH_MAX_ENVS) == 1
        with pytest.raises(ValueError, match="num_envs must be an int >= 1, got 0"):
            limit_threads_for_small_batches(0)
    finally:
        torch.set_num_threads(before)
