"""BaseScenario.batched_outputs / outputs(): once per state, fresh per collection, refused when undefined."""
from __future__ import annotations

import pytest
import torch

import vmas_ros
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.scenario import BaseScenario


class Spread(BaseScenario):
    """Two agents; reward and observation both read one state-wide computation, which counts its calls."""

    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim, device, **kwargs):
        world = World(batch_dim, device)
        for i in range(2):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(0.05)))
        self.calls = 0
        return world

    def reset_world_at(self, env_index=None):
        for i, agent in enumerate(self.world.agents):
            agent.set_pos(torch.full((2,), 0.5 * i, device=self.world.device), batch_index=env_index)

    def batched_outputs(self, q, v):
        self.calls += 1
        gap = (q[:2, 1] - q[:2, 0]).norm(dim=0)  # [B]
        return -gap, q[:2].permute(1, 2, 0).clone()  # rewards [B], positions [A, B, 2] (a new tensor)

    def reward(self, agent):
        return self.outputs()[0]

    def observation(self, agent):
        return self.outputs()[1][self.world.agents.index(agent)]


class Plain(Spread):
    batched_outputs = None

    def reward(self, agent):
        return self.outputs()[0]


def test_outputs_are_computed_once_per_state_and_fresh_per_collection():
    env = vmas_ros.make_env(Spread(), num_envs=3, seed=0)
    scenario = env.scenario
    scenario.calls = 0
    obs, rews, _, _ = env.step([torch.full((3, 2), 0.3) for _ in env.agents])
    assert scenario.calls == 1  # the rewards of both agents and both observations: one computation
    torch.testing.assert_close(obs[1], env.agents[1].state.pos, rtol=0, atol=0)
    torch.testing.assert_close(rews[0], -(env.agents[1].state.pos - env.agents[0].state.pos).norm(dim=-1))
    again = env.get_from_scenario(True, False, False, False)[0]
    assert scenario.calls == 2 and again[0].data_ptr() != obs[0].data_ptr()  # never shares memory
    env.agents[0].set_pos(torch.zeros(3, 2), batch_index=None)  # a new state: computed afresh
    torch.testing.assert_close(env.get_from_scenario(True, False, False, False)[0][0], torch.zeros(3, 2))


def test_outputs_without_the_hook_is_refused_by_name():
    with pytest.raises(RuntimeError, match="Plain.outputs\\(\\): the scenario does not define batched_outputs"):
        vmas_ros.make_env(Plain(), num_envs=2, seed=0)
