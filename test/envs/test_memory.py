"""Worlds whose step needs more memory than the device has are refused up front, with the figures.

The check runs after make_world and before the first reset; the available
memory is what the machine reports, or a smaller machine's figure patched in.
"""
from __future__ import annotations

import pytest
import torch

import vmas_ros
from vmas_ros.envs import memory
from vmas_ros.simulator.core import Agent, Sphere, World


def _spheres(n: int, batch: int, own_filter: bool) -> World:
    world = World(batch_dim=batch, device="cpu")
    for i in range(n):
        kwargs = {"collision_filter": lambda e: True} if own_filter else {}
        world.add_agent(Agent(name=f"s{i}", shape=Sphere(radius=0.05), **kwargs))
    return world


def test_the_estimate_counts_pairs_and_spares_the_grid():
    every_pair = memory.estimate_step_bytes(_spheres(400, 2, own_filter=True))
    hashed = memory.estimate_step_bytes(_spheres(400, 2, own_filter=False))
    assert every_pair["contacts"] == 4 * memory.PAIR_FLOATS * (400 * 399 // 2) * 2
    assert hashed["contacts"] == 0 and hashed["grid"] > 0
    assert sum(hashed.values()) < sum(every_pair.values()) / 10


def test_the_machine_reports_what_is_available():
    room = memory.available_bytes("cpu")
    assert room is None or room > 0


def test_a_world_too_large_is_refused_before_its_first_reset(monkeypatch):
    monkeypatch.setattr(memory, "available_bytes", lambda device: 50_000_000)  # a machine with 50 MB left
    resets = []
    from vmas_ros.scenarios import navigation

    monkeypatch.setattr(navigation.Scenario, "reset_world_at", lambda self, env_index=None: resets.append(1))
    with pytest.raises(MemoryError) as error:
        vmas_ros.make_env("navigation", num_envs=64, n_agents=200, agent_radius=0.05)
    message = str(error.value)
    assert "navigation with 64 envs and 200 agents needs at least" in message
    assert "50 MB is available on cpu" in message and "VMAS_ROS_ALLOW_LARGE_WORLDS=1" in message
    assert not resets, "the check must come before anything is reset or stepped"
    # the opt-in skips the check: the same world is built and reset
    monkeypatch.setenv("VMAS_ROS_ALLOW_LARGE_WORLDS", "1")
    vmas_ros.make_env("navigation", num_envs=64, n_agents=200, agent_radius=0.05)
    assert resets


def test_worlds_that_fit_are_built(monkeypatch):
    env = vmas_ros.make_env("simple_spread", num_envs=4)
    assert sum(memory.estimate_step_bytes(env.world).values()) < 10_000_000
    monkeypatch.setattr(memory, "available_bytes", lambda device: None)  # a platform that does not say
    vmas_ros.make_env("simple_spread", num_envs=4)
    assert torch.is_tensor(env.reset()[0])
