"""Every registered scenario runs inside sim_node (in-process), driven by its heuristic,
and publishes finite poses and scans."""
from __future__ import annotations

import math

import pytest

import vmas_ros
from vmas_ros.ros.sim_node import SimNode
from vmas_ros.scenarios import list_scenarios

pytestmark = pytest.mark.ros

#: scenarios whose heuristic holds still from the start, and why
STILL_BY_DESIGN = {
    "drone": "keeps level, and the drones start level and at rest",
    "vel_control": "the reward only charges force: the agents stand still",
}


@pytest.mark.parametrize("scenario", list_scenarios())
def test_scenario_steps_and_publishes_in_sim_node(scenario, on_test_context):
    node = SimNode(scenario=scenario, control="heuristic", num_envs=2, env_index=1, lidar_rays=6)
    try:
        messages = node.state_messages  # what the node published last, decoded from its bytes
        poses = [t for t in messages.topics if t.endswith("/pose")]
        start = [(p.pose.position.x, p.pose.position.y) for p in map(messages.decode, poses)]
        for _ in range(5):
            node.step_once()
        end = [(p.pose.position.x, p.pose.position.y) for p in map(messages.decode, poses)]
        assert node.steps == 5 and node.sim_time_ns == 5 * round(node.env.world.dt * 1e9)
        assert all(math.isfinite(v) for xy in end for v in xy)
        if any(a.movable for a in node.env.world.agents) and scenario not in STILL_BY_DESIGN:  # crypto: only talk
            assert start != end, "the heuristic moves someone"
        scans = [messages.decode(t) for t in messages.topics if "/scan" in t]
        # one scan per lidar: the scenario's own (their ray counts) or the node's 6-ray one
        lidars = [s for a in node.env.world.agents for s in a.sensors if hasattr(s, "n_rays")]
        assert scans and sorted(len(s.ranges) for s in scans) == sorted(lidar.n_rays for lidar in lidars)
        if not any(a.sensors for a in vmas_ros.make_env(scenario, num_envs=1).world.agents):
            assert all(len(s.ranges) == 6 for s in scans)
        assert len(node.markers.markers) == len(node.env.world.entities)
    finally:
        node.destroy_node()


@pytest.mark.slow
def test_compiled_node_publishes_what_the_eager_node_publishes(on_test_context):
    """compile_physics: true steps through torch.compile (physics, the node's lidar casts and the published
    env's snapshot); the published poses and scans equal the eager node's to float rounding."""
    nodes = [SimNode(scenario="simple_spread", scenario_kwargs='{"n_agents": 4}', control="heuristic", lidar_rays=12,
                     compile_physics=compiled) for compiled in (False, True)]
    try:
        assert nodes[1].env.world.physics_compiled and not nodes[0].env.world.physics_compiled
        for _ in range(3):
            for node in nodes:
                node.step_once()
        # the compiled node's snapshot comes from its step (simulator/env_snapshot.py), the eager one's is
        # gathered after
        eager_source, compiled_source = (node.snapshot.source for node in nodes)
        assert not eager_source.rides_along and compiled_source.rides_along and compiled_source.computed_by_step
        eager, compiled = (node.state_messages for node in nodes)
        for topic in eager.topics:
            if topic.endswith("/pose"):
                a, b = eager.decode(topic).pose.position, compiled.decode(topic).pose.position
                assert math.isclose(a.x, b.x, abs_tol=1e-5) and math.isclose(a.y, b.y, abs_tol=1e-5)
            if topic.endswith("/scan"):
                ra, rb = eager.decode(topic).ranges, compiled.decode(topic).ranges
                assert len(ra) == 12 and all(math.isclose(x, y, abs_tol=1e-4) for x, y in zip(ra, rb))
    finally:
        for node in nodes:
            node.destroy_node()
