"""sim_node with its live Foxglove server: a real WebSocket client watches and drives an agent."""
from __future__ import annotations

import asyncio
import socket
import time

import pytest
from nav_msgs.msg import Odometry

from test.foxglove_client import FoxClient, twist_json

pytestmark = pytest.mark.ros


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(port: int, timeout: float = 20.0) -> None:
    """Until something accepts TCP on the port: topic discovery can be satisfied by a node
    from an earlier test that is still leaving the graph, before this one serves Foxglove."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def test_foxglove_client_sees_the_scene_and_drives_an_agent(ros, sim_node):
    port = _free_port()
    sim = sim_node(scenario_kwargs='{"n_agents": 1}', foxglove_port=port, cmd_vel_timeout=0.5, seed=3)
    _wait_listening(port)
    odom = ros.collect(Odometry, "/agent_0/odom")

    async def session():
        async with FoxClient(port) as client:
            topics = {"/scene": "foxglove.SceneUpdate", "/tf": "foxglove.FrameTransforms",
                      "/agent_0/scan": "foxglove.LaserScan", "/agent_0/pose": "foxglove.PoseInFrame", "/rewards": None}
            await client.wait_for(lambda: all(t in client.channels for t in topics))
            for topic, schema in topics.items():
                if schema:
                    assert client.channels[topic]["schemaName"] == schema
            scene = await client.subscribe("/scene")
            await client.wait_for(lambda: len(client.data.get(scene, [])) >= 3)
            log_times = [t for t, _ in client.data[scene]]
            assert log_times == sorted(log_times) and len(set(log_times)) == len(log_times), "sim time advances"
            await client.advertise(7, "/agent_0/cmd_vel")
            start = time.monotonic()
            while time.monotonic() - start < 2.0:  # a teleop panel at 20 Hz
                await client.publish(7, twist_json(vx=0.3))
                await asyncio.sleep(0.05)

    asyncio.run(asyncio.wait_for(session(), 30))
    ros.spin_for(0.5)  # deliver the odometry queued while the WebSocket session ran
    speeds = [m.twist.twist.linear.x for m in odom.messages]
    assert speeds, "odometry keeps flowing"
    # force-limited (u_range 1, mass 1): +0.1 m/s per step up to the command, then held
    assert max(speeds) == pytest.approx(0.3, rel=0.05), speeds
    assert sum(1 for v in speeds if v == pytest.approx(0.3, rel=0.05)) >= 5, "the command was held"
    assert sim.alive()
