"""sim_node at swarm scale: aggregated topics instead of per-agent ones.

With ``per_agent_topics`` off (the default above 100 agents) the node makes
no topics per agent: the swarm is in ``agents/poses`` and ``world/markers``,
and every lidar ray's hit in one ``sensor_msgs/PointCloud2``,
``lidar/points``, in the world frame. The cloud is checked against each
lidar cast alone, turned into points by hand; the process test runs a real
node of 1,000 agents and reads its topics from another process.
"""
from __future__ import annotations

import asyncio
import base64
import math
import signal

import numpy as np
import pytest
import torch
from geometry_msgs.msg import PoseArray, Twist
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import PointCloud2

import vmas_ros
from test.ros.test_publish import _markers
from test.simulator.lidar_setup import randomise, with_lidars
from vmas_ros.simulator import env_snapshot
from vmas_ros.ros.params import PER_AGENT_TOPICS_MAX_AGENTS, SimParams, validate
from vmas_ros.ros.publish import StateMessages
from test.foxglove_client import FoxClient
from test.ros.conftest import READY_SERVICES, SimProcess
from test.ros.test_sim_node_foxglove import _free_port
from test.viz.protobuf_decode import decode, schema_descriptors

pytestmark = pytest.mark.ros


def _cloud_points(message: PointCloud2) -> np.ndarray:
    assert [(f.name, f.offset, f.datatype, f.count) for f in message.fields] == [
        ("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1)]  # 7: FLOAT32
    assert (message.height, message.point_step, message.row_step) == (1, 12, 12 * message.width)
    assert not message.is_bigendian and not message.is_dense
    return np.frombuffer(bytes(message.data), dtype="<f4").reshape(message.width, 3)


def test_the_cloud_holds_every_rays_hit_in_the_world_frame():
    env = vmas_ros.make_env("simple_spread", num_envs=2, seed=4, n_agents=5)
    with_lidars(env, (12, 7), max_range=1.5)
    world = env.world
    names = env_snapshot.unique_names([a.name for a in world.agents])
    lidars = env_snapshot.agent_lidars(world)
    geometry = {i: [env_snapshot.ScanGeometry.of(s) for s in ls] for i, ls in lidars.items()}
    messages = StateMessages(names, len(world.landmarks), len(world.entities), geometry,
                             {i: [s.n_rays for s in ls] for i, ls in lidars.items()}, "map", _markers(world, "map"),
                             per_agent=False, cloud=True)
    assert sorted(t.lstrip("/") for t in messages.topics) == [
        "agents/poses", "clock", "landmarks/poses", "lidar/points", "world/markers"]
    rng = torch.Generator().manual_seed(2)
    hits = 0
    for trial in range(4):
        randomise(env, rng)
        env_index = trial % 2
        snap = env_snapshot.Snapshot.take(world, env_index, lidars)
        messages.fill(snap, 1_000_000_000 * trial, None)
        cloud = deserialize_message(messages.payload(messages.topics.index("lidar/points")), PointCloud2)
        assert cloud.header.frame_id == "map" and cloud.header.stamp.sec == trial
        points = _cloud_points(cloud)
        expected = []
        for agent, sensors in zip(world.agents, lidars.values()):
            x, y = (float(v) for v in agent.state.pos[env_index])
            yaw = float(agent.state.rot[env_index, 0])
            for sensor in sensors:
                ranges = sensor.cast_alone()[env_index].tolist()
                for angle, r in zip(sensor.angles[0].tolist(), ranges):
                    if r >= sensor.max_range:
                        expected.append((math.nan,) * 3)
                    else:
                        expected.append((x + r * math.cos(yaw + angle), y + r * math.sin(yaw + angle), 0.0))
        expected = np.array(expected, dtype=np.float64)
        assert points.shape == expected.shape
        np.testing.assert_array_equal(np.isnan(points), np.isnan(expected))
        np.testing.assert_allclose(points, expected, atol=2e-6, rtol=0)
        # and independently of the lidar's angle convention: every hit lies on some entity's circle
        centres = np.array([e.state.pos[env_index].tolist() for e in world.entities])
        radii = np.array([e.shape.radius for e in world.entities])
        found = points[np.isfinite(points[:, 0]), :2].astype(np.float64)
        gaps = np.abs(np.linalg.norm(found[:, None] - centres[None], axis=2) - radii[None]).min(axis=1)
        assert gaps.max() < 1e-4, gaps.max()
        hits += len(found)
    assert 0 < hits < 4 * len(expected), "some rays hit something, some nothing"


def test_per_agent_topics_are_on_for_small_teams_and_off_for_swarms():
    params = SimParams()
    assert params.per_agent_topics == "auto" and params.cmd_vel_agents == ""
    assert params.per_agent(PER_AGENT_TOPICS_MAX_AGENTS) and not params.per_agent(PER_AGENT_TOPICS_MAX_AGENTS + 1)
    params.per_agent_topics = "on"
    assert params.per_agent(100_000)
    params.per_agent_topics = "off"
    assert not params.per_agent(1)
    params.cmd_vel_agents = " agent_0, agent_7 ,"
    assert params.cmd_vel_names() == ["agent_0", "agent_7"]
    assert "one of auto, on, off" in validate("per_agent_topics", "some")


# ------------------------------------------------------------------ a swarm in a real node
N_SWARM = 1_000
HALF_SIDE = 0.25 * math.sqrt(N_SWARM)  # agents and goals spread over a square of side 0.5 * sqrt(N)
SWARM = dict(scenario="navigation", real_time_factor=0.0, cmd_vel_agents="agent_0", add_lidar=False,
             scenario_kwargs={"n_agents": N_SWARM, "agent_radius": 0.05, "lidar_range": 0.35,
                              "world_spawning_x": HALF_SIDE, "world_spawning_y": HALF_SIDE})
SWARM_TOPICS = {"/clock": "rosgraph_msgs/msg/Clock", "/agents/poses": "geometry_msgs/msg/PoseArray",
                "/world/markers": "visualization_msgs/msg/MarkerArray",
                "/lidar/points": "sensor_msgs/msg/PointCloud2", "/agent_0/cmd_vel": "geometry_msgs/msg/Twist"}


def _foxglove_scene(port: int) -> tuple:
    """(the channels a Foxglove client is offered, the entities of one /scene message it receives)."""
    async def session():
        async with FoxClient(port) as client:
            await client.wait_for(lambda: "/scene" in client.channels)
            scene = await client.subscribe("/scene")
            await client.wait_for(lambda: len(client.data.get(scene, [])) >= 1)
            channel = client.channels["/scene"]
            message = decode(schema_descriptors(base64.b64decode(channel["schema"])), channel["schemaName"],
                             client.data[scene][0][1])
            return set(client.channels), message["entities"]

    return asyncio.run(asyncio.wait_for(session(), 60))


def test_a_swarm_of_a_thousand_is_published_in_aggregated_topics(ros, sim_log_dir):
    poses = ros.collect(PoseArray, "/agents/poses", depth=50)
    cloud = ros.collect(PointCloud2, "/lidar/points", depth=5)
    port = _free_port()
    sim = SimProcess(ros, {**SWARM, "foxglove_port": port}, sim_log_dir, "swarm")
    try:
        sim.wait_ready(SWARM_TOPICS, READY_SERVICES, timeout=180.0)  # building 1,000 agents takes a while
        topics = ros.topics()
        per_agent = sorted(t for t in topics if t.startswith("/agent_") and t != "/agent_0/cmd_vel")
        assert not per_agent, f"per-agent topics in a swarm: {per_agent[:5]}"
        assert ros.node.count_publishers("/tf") == 0 and ros.node.count_subscribers("/agent_1/cmd_vel") == 0
        first = poses.wait_for(1, timeout=60.0)[-1]
        assert len(first.poses) == N_SWARM
        points = _cloud_points(cloud.wait_for(1, timeout=60.0)[-1])
        assert len(points) >= N_SWARM and len(points) % N_SWARM == 0, len(points)
        hits = points[np.isfinite(points[:, 0])]
        assert len(hits) and np.all(np.abs(hits[:, :2]) <= HALF_SIDE + 1.0), "hits lie in the arena"

        # a Foxglove client sees the whole swarm (agents and goals) in one scene, and no per-agent channel
        channels, entities = _foxglove_scene(port)
        assert len(entities) == 2 * N_SWARM and {"agent_0", f"agent_{N_SWARM - 1}"} <= {e["id"] for e in entities}
        assert not [c for c in channels if c.startswith("/agent_")], sorted(channels)[:5]

        # agent_0 takes cmd_vel: it moves forward while the command lasts; the others stand still
        start = poses.latest.poses
        command = Twist()
        command.linear.x = 0.5
        ros.publish_for(Twist, "/agent_0/cmd_vel", command, seconds=4.0, period=0.1)
        moved = poses.latest.poses
        dx = [m.position.x - s.position.x for s, m in zip(start, moved)]
        assert dx[0] > 0.02, f"agent_0 moved {dx[0]:.4f} m under a 0.5 m/s command"
        assert max(abs(d) for d in dx[1:]) < dx[0] / 2, "only the commanded agent drives"
        assert sim.stop(signal.SIGINT, timeout=60.0) == 0, sim.describe()
    finally:
        sim.kill()
    log = sim.stderr()
    assert "per-agent topics off (per_agent_topics)" in log and "agents taking cmd_vel: agent_0" in log, log[-2000:]


def test_an_unknown_cmd_vel_agent_is_refused(sim_process):
    sim = sim_process(per_agent_topics="off", cmd_vel_agents="agent_0,robot_9")
    assert sim.wait(60) == 2
    assert "cmd_vel_agents: robot_9 not among the scenario's agents (agent_0, agent_1, agent_2)" in sim.stderr()
