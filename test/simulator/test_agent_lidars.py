"""AgentLidars (scenario observations cast every agent's lidar once per state) against Lidar.measure()."""
from __future__ import annotations

import pytest
import torch

from vmas_ros import make_env
from vmas_ros.simulator import lidar_batch


@pytest.mark.parametrize("num_envs", [3, 1000])  # batched cast, and one lidar at a time
@pytest.mark.parametrize("name", ["flocking", "discovery"])
def test_readings_equal_measure_and_follow_the_state(name, num_envs, device):
    kwargs = {"use_agent_lidar": True} if name == "discovery" else {}
    env = make_env(name, num_envs=num_envs, device=device, seed=3, **kwargs)
    env.reset()
    scenario = env.scenario
    slots = scenario._lidars if isinstance(scenario._lidars, list) else [scenario._lidars]
    agents = [a for a in env.agents if a.sensors]
    small = num_envs * agents[0].sensors[0].n_rays <= lidar_batch.BATCH_BELOW_ELEMENTS
    assert small == (num_envs == 3)
    for step in range(4):
        env.step([torch.rand(num_envs, 2, device=device) * 2 - 1 for _ in env.agents])
        # move a lidar target next to agent 0 so some rays hit, then read again: never stale
        target = next(e for e in env.world.landmarks)
        target.set_pos(agents[0].state.pos + torch.tensor([0.12, 0.0], device=device), batch_index=None)
        first_slot = None
        for slot, lidars in enumerate(slots):
            readings = [lidars.reading(agent) for agent in agents]
            first_slot = readings if first_slot is None else first_slot
            for agent, reading in zip(agents, readings):
                expected = agent.sensors[slot].measure()
                assert torch.equal(reading, expected), (step, agent.name, slot)
                assert torch.equal(agent.sensors[slot].last_measurement, expected)
        hits = first_slot[0] < agents[0].sensors[0].max_range  # slot 0 sees the landmarks
        assert hits.any(), "the moved target should be seen"


def test_one_cast_per_state(monkeypatch):
    env = make_env("flocking", num_envs=2, device="cpu", seed=0)
    env.reset()
    calls = []
    original = lidar_batch.BatchedLidars.cast
    monkeypatch.setattr(lidar_batch.BatchedLidars, "cast", lambda *a, **k: calls.append(1) or original(*a, **k))
    env.step([torch.zeros(2, 2) for _ in env.agents])
    assert len(calls) == 1, "all agents' observations of one step should share one cast"
    env.get_from_scenario(True, False, False, False)  # same state: cached
    assert len(calls) == 1
    env.agents[1].set_pos(torch.zeros(2, 2), batch_index=None)
    env.get_from_scenario(True, False, False, False)
    assert len(calls) == 2


def test_readings_follow_targets_moved_by_set_positions(device):
    """discovery moves its targets with World.set_positions between steps; readings taken before and
    after the move must each match the state they were taken in."""
    env = make_env("discovery", num_envs=3, device=device, seed=3)
    env.step([torch.zeros(3, 2, device=device) for _ in env.agents])
    lidars, agent = env.scenario._lidars[0], env.agents[0]
    before = lidars.reading(agent).clone()
    targets = env.scenario.targets
    ahead = agent.state.pos + torch.tensor([0.1, 0.0], device=device)
    x = torch.stack([ahead[:, 0]] + [torch.full((3,), 50.0, device=device)] * (len(targets) - 1))
    y = torch.stack([ahead[:, 1]] + [torch.full((3,), 50.0, device=device)] * (len(targets) - 1))
    env.world.set_positions(targets, x, y)
    after = lidars.reading(agent)
    assert torch.equal(after, agent.sensors[0].measure())
    assert not torch.equal(after, before)
    assert (after < agent.sensors[0].max_range).any(), "the target placed next to the agent is seen"


@pytest.mark.slow
def test_compiled_worlds_cast_all_lidars_in_one_graph_close_to_measure(device):
    """A compiled world's AgentLidars read all lidars from one compiled kernel: the same distances as
    each Lidar.measure() to float rounding, some of them hits."""
    env = make_env("discovery", num_envs=5, device=device, seed=2, compile_physics=True)
    env.step([torch.zeros(5, 2, device=device) for _ in env.agents])
    lidars, agents = env.scenario._lidars[0], env.agents
    target = env.scenario.targets[0]
    target.set_pos(agents[1].state.pos + torch.tensor([0.0, 0.1], device=device), batch_index=None)
    readings = [lidars.reading(agent) for agent in agents]
    assert lidars._compiled._plan is not None and lidars._compiled._plan[1] is not None, "the compiled cast ran"
    for agent, reading in zip(agents, readings):
        torch.testing.assert_close(reading, agent.sensors[0].measure(), rtol=1e-5, atol=1e-5)
    assert (readings[1] < agents[1].sensors[0].max_range).any()
