"""The Environment's own randomness (seeding), headless rendering and observation hand-out.

On the two shipped scenarios of test_environment.py (test/envs/environment_cases.py).
"""
from __future__ import annotations

import random

import numpy as np
import pytest
import torch

import vmas_ros
from test.envs.environment_cases import N_ENVS, SCENARIOS, make

# ----------------------------------------------------------------------- seeding


def _current_obs(env):
    return torch.cat(env.get_from_scenario(True, False, False, False)[0], dim=-1)


def _trajectory(env, steps=4, interleave=None):
    """Observations of a run mixing random actions and partial resets (both draw from the env's RNG)."""
    out = [torch.cat(env.reset(), dim=-1)]
    for step in range(steps):
        if interleave:
            interleave()
        obs, _, _, _ = env.step(env.get_random_actions())
        out.append(torch.cat(obs, dim=-1))
        if step == 1:
            out.append(torch.cat(env.reset_at([0, 2]), dim=-1))
    return torch.stack(out)


def test_same_seed_same_start_and_trajectory_under_same_actions():
    a, b = make("simple_spread", seed=7), make("simple_spread", seed=7)
    assert torch.equal(_current_obs(a), _current_obs(b))
    for o_a, o_b in zip(a.reset(), b.reset()):
        assert torch.equal(o_a, o_b)
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        actions = [torch.rand(N_ENVS, 2, generator=gen) * 2 - 1 for _ in a.agents]
        obs_a, rew_a, _, _ = a.step([x.clone() for x in actions])
        obs_b, rew_b, _, _ = b.step([x.clone() for x in actions])
        assert all(torch.equal(x, y) for x, y in zip(obs_a, obs_b))
        assert all(torch.equal(x, y) for x, y in zip(rew_a, rew_b))


def test_same_seed_same_random_trajectory():
    assert torch.equal(_trajectory(make("simple_spread", seed=11)), _trajectory(make("simple_spread", seed=11)))


def test_different_seed_differs():
    a, b = make("simple_spread", seed=1), make("simple_spread", seed=2)
    assert not torch.equal(_current_obs(a), _current_obs(b))
    assert not torch.equal(torch.cat(a.reset(), -1), torch.cat(b.reset(), -1))
    assert not torch.equal(_trajectory(a), _trajectory(b))


def test_default_seed_is_deterministic():
    a = vmas_ros.make_env("simple_spread", num_envs=N_ENVS)
    b = vmas_ros.make_env("simple_spread", num_envs=N_ENVS)
    assert torch.equal(_trajectory(a), _trajectory(b))


def test_seeding_is_per_instance():
    reference = _trajectory(make("simple_spread", seed=5))
    env = make("simple_spread", seed=5)
    others = []

    def disturb():
        # another env created and stepped, and global RNG draws of every kind
        other = make("simple_spread", seed=123)
        other.step(other.get_random_actions())
        other.reset_at(0)
        others.append(other)
        torch.rand(1000)
        torch.manual_seed(999)
        np.random.rand(10)
        random.random()

    assert torch.equal(_trajectory(env, interleave=disturb), reference)
    assert len(others) == 4


def test_env_does_not_disturb_the_global_rng():
    torch.manual_seed(42)
    expected = torch.rand(5)
    np.random.seed(1)
    expected_np = np.random.rand(3)
    torch.manual_seed(42)
    np.random.seed(1)
    env = make("simple_spread", seed=3)
    _trajectory(env)
    assert torch.equal(torch.rand(5), expected)
    np.testing.assert_array_equal(np.random.rand(3), expected_np)


def test_reseeding_replays_a_fresh_env():
    fresh = _current_obs(make("simple_spread", seed=21))  # the constructor's own reset
    env = make("simple_spread", seed=0)
    env.step(env.get_random_actions())
    assert torch.equal(torch.cat(env.reset(seed=21), dim=-1), fresh)
    assert env.seed(4) == [4]


# ----------------------------------------------------------------------- render


@pytest.mark.parametrize("name", SCENARIOS)
def test_render_rgb_array_headless(name):
    env = make(name, num_envs=2)
    frame = env.render(mode="rgb_array")
    assert isinstance(frame, np.ndarray)
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    width, height = env.scenario.viewer_size
    assert frame.shape[:2] == (height, width)
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 2, "the frame must show something"
    # a white-ish background with coloured entities on it
    assert (frame == 255).all(axis=-1).mean() > 0.3
    assert (frame.max(axis=-1).astype(int) - frame.min(axis=-1) > 50).any(), "entities are drawn in colour"
    push = [torch.tensor([[1.0, 1.0], [0.0, 0.0]]) for _ in env.agents]
    for _ in range(10):
        env.step(push)
    moved = env.render(mode="rgb_array", env_index=0)
    assert moved.shape == frame.shape
    assert (moved != frame).any(axis=-1).sum() > 50, "the picture must follow the moving agents"
    # rendering is a pure function of the state: same state, same picture
    assert np.array_equal(env.render(mode="rgb_array", env_index=0), moved)


def test_render_rejects_bad_arguments():
    env = make("simple_spread", num_envs=2)
    with pytest.raises(ValueError, match="mode"):
        env.render(mode="bogus")
    with pytest.raises(ValueError, match="env_index"):
        env.render(env_index=2)


def test_fresh_observations_are_handed_out_without_copies_and_never_alias(device):
    """simple_spread sets fresh_observations: its observations are views of one batched result per
    collection (no defensive copy), and writing into them changes nothing the env hands out later."""
    env = vmas_ros.make_env("simple_spread", num_envs=4, device=device, seed=0)
    assert env.scenario.fresh_observations
    first = env.step(env.get_random_actions())[0]
    # the agents' observations share one storage: no per-agent copy was made
    assert first[0].untyped_storage().data_ptr() == first[1].untyped_storage().data_ptr()
    expected = [o.clone() for o in env.get_from_scenario(True, False, False, False)[0]]
    for o in first:
        o.fill_(123.0)
    again = env.get_from_scenario(True, False, False, False)[0]
    for got, want in zip(again, expected):
        torch.testing.assert_close(got, want)
