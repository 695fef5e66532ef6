"""FoxgloveBridge against a real WebSocket client (``websockets``, subprotocol foxglove.sdk.v1).

The inputs come from a real simple_spread env with lidars added as sim_node
does. Protobuf payloads are decoded with a small wire-format reader driven by
the FileDescriptorSet each channel advertises, so no protobuf package is needed.
"""
from __future__ import annotations

import asyncio
import base64
import json
import logging
import math
import os
import queue
import socket
from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("foxglove")
import websockets  # noqa: E402  (test extra: a real Foxglove WebSocket client)

import vmas_ros  # noqa: E402
from vmas_ros.simulator import env_snapshot  # noqa: E402
from vmas_ros.simulator.sensors import Lidar  # noqa: E402
from test.foxglove_client import SUBPROTOCOL, WAIT, FoxClient, twist_json  # noqa: E402
from test.viz.protobuf_decode import decode, schema_descriptors  # noqa: E402
from vmas_ros.viz.foxglove_bridge import MAX_CLIENT_MESSAGE_BYTES, FoxgloveBridge, parse_twist  # noqa: E402

pytestmark = pytest.mark.timeout(60)

LIDAR_RANGE = 1.0
DT_NS = 100_000_000
ROOT = Path(__file__).resolve().parents[2]


# --------------------------------------------------------------------------- inputs
@pytest.fixture(scope="module")
def sim():
    """A real env (1 env) with lidars as sim_node adds them, agents placed so some rays hit."""
    env = vmas_ros.make_env("simple_spread", num_envs=1, seed=0)
    world = env.world
    for agent in world.agents:
        agent.add_sensor(Lidar(world, n_rays=12, max_range=LIDAR_RANGE,
                               entity_filter=lambda e, me=agent: e.collides(me) and me.collides(e)))
    # a second lidar on agent 0 -> /agent_0/scan_1
    world.agents[0].add_sensor(Lidar(world, n_rays=6, max_range=LIDAR_RANGE, angle_start=-1.0, angle_end=1.0,
                                     entity_filter=lambda e, me=world.agents[0]: e.collides(me) and me.collides(e)))
    env.reset()
    for agent, xy in zip(world.agents, [(0.0, 0.0), (0.5, 0.0), (-0.6, 0.6)]):
        agent.set_pos(torch.tensor(xy, dtype=torch.float32), batch_index=0)
        agent.set_rot(torch.tensor([0.3], dtype=torch.float32), batch_index=0)
    names = env_snapshot.unique_names([a.name for a in world.agents])
    lidars = env_snapshot.agent_lidars(world)
    geometry = {i: [env_snapshot.ScanGeometry.of(s) for s in ls] for i, ls in lidars.items()}
    snap = env_snapshot.Snapshot.take(world, 0, lidars)
    assert np.isfinite(snap.scans[0][0]).all() and (snap.scans[0][0] < LIDAR_RANGE).any()
    assert (snap.scans[0][0] >= LIDAR_RANGE).any()  # both hits and no-returns to check
    return dict(world=world, names=names, geometry=geometry, snap=snap)


class Twists:
    """A thread-safe on_twist recorder."""

    def __init__(self):
        self.calls = queue.Queue()

    def __call__(self, index, vx, vy, wz):
        self.calls.put((index, vx, vy, wz))

    def get(self, timeout=WAIT):
        return self.calls.get(timeout=timeout)

    def empty(self):
        return self.calls.empty()


@pytest.fixture
def twists():
    return Twists()


@pytest.fixture
def bridge(sim, twists):
    with FoxgloveBridge(port=0, agent_names=sim["names"], on_twist=twists) as b:
        yield b
    assert b.closed


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 30))


def expected_topics(sim):
    topics = {"/scene": "foxglove.SceneUpdate", "/tf": "foxglove.FrameTransforms"}
    for i, name in enumerate(sim["names"]):
        topics[f"/{name}/pose"] = "foxglove.PoseInFrame"
        for k in range(len(sim["geometry"][i])):
            topics[f"/{name}/scan" if k == 0 else f"/{name}/scan_{k}"] = "foxglove.LaserScan"
    return topics


# ------------------------------------------------------------------------- tests
def test_handshake_and_server_info(bridge):
    assert bridge.port > 0 and bridge.url == f"ws://127.0.0.1:{bridge.port}"

    async def main():
        async with FoxClient(bridge.port) as client:
            assert client.ws.subprotocol == SUBPROTOCOL
            await client.wait_for(lambda: client.server_info is not None)
            info = client.server_info
            assert "clientPublish" in info["capabilities"]
            assert "time" in info["capabilities"]
            assert info["supportedEncodings"] == ["json"]

    run(main())


def test_channels_are_advertised_with_foxglove_schemas(bridge, sim):
    bridge.publish(sim["snap"], sim["world"].entities, sim["geometry"], 0)  # scan channels appear on first use
    topics = expected_topics(sim)
    assert "/agent_0/scan_1" in topics

    async def main():
        async with FoxClient(bridge.port) as client:
            await client.wait_for(lambda: set(topics) <= set(client.channels))
            for topic, schema in topics.items():
                channel = client.channels[topic]
                assert channel["schemaName"] == schema, topic
                assert channel["encoding"] == "protobuf"
                assert channel["schemaEncoding"] == "protobuf"

    run(main())


def collect(bridge, sim, topics, which=-1):
    """Subscribe to ``topics``, publish steps until each delivered, return {topic: (log_time, decoded)}.

    ``which`` picks the message per topic: -1 the last received, 0 the first.
    """
    world, snap, geometry = sim["world"], sim["snap"], sim["geometry"]
    bridge.publish(snap, world.entities, geometry, 0)  # creates the scan channels
    step = {"n": 0}

    def publish_step():
        step["n"] += 1
        bridge.publish(snap, world.entities, geometry, step["n"] * DT_NS)

    async def main():
        async with FoxClient(bridge.port) as client:
            await client.wait_for(lambda: set(topics) <= set(client.channels))
            subs = {topic: await client.subscribe(topic) for topic in topics}
            # publish steps until every subscription has delivered (subscribing is asynchronous)
            await client.wait_for(lambda: all(client.data.get(s) for s in subs.values()) and client.times,
                                  tick=publish_step)
            return client, subs

    client, subs = run(main())
    published_times = {k * DT_NS for k in range(step["n"] + 1)}
    assert client.times and set(client.times) <= published_times  # server time follows sim time
    decoded = {}
    for topic, sub_id in subs.items():
        channel = client.channels[topic]
        descriptors = schema_descriptors(base64.b64decode(channel["schema"]))
        log_time, payload = client.data[sub_id][which]
        assert payload, topic
        assert log_time in published_times
        decoded[topic] = (log_time, decode(descriptors, channel["schemaName"], payload))
    return decoded


def test_subscribed_channels_receive_decodable_messages(bridge, sim):
    world, snap, names, geometry = sim["world"], sim["snap"], sim["names"], sim["geometry"]
    decoded = collect(bridge, sim, expected_topics(sim))

    n_landmarks = len(world.landmarks)
    # /scene: one entity per world entity, spheres as flat discs in the entities' colours
    log_time, scene = decoded["/scene"]
    entities = scene["entities"]
    assert len(entities) == len(world.entities)
    assert [e["id"] for e in entities] == env_snapshot.unique_names([e.name for e in world.entities])
    for k, (entity, msg) in enumerate(zip(world.entities, entities)):
        assert msg["frame_id"] == "world"
        stamp = msg["timestamp"]
        assert stamp.get("seconds", 0) * 10**9 + stamp.get("nanos", 0) == log_time
        (cylinder,) = msg["cylinders"]
        size = cylinder["size"]
        assert size["x"] == pytest.approx(2 * entity.shape.radius) and size["y"] == size["x"]
        assert 0 < size["z"] < size["x"]
        assert cylinder["bottom_scale"] == cylinder["top_scale"] == 1.0
        rgb = env_snapshot.rgb(entity.color)
        assert [cylinder["color"].get(c, 0.0) for c in "rgb"] == pytest.approx(rgb)
        assert cylinder["color"]["a"] > 0
        position = cylinder["pose"]["position"]
        assert (position.get("x", 0.0), position.get("y", 0.0)) == pytest.approx(tuple(snap.pos[k]), abs=1e-6)

    # /tf: world -> <agent>/base_link at the agents' poses
    _, tf = decoded["/tf"]
    transforms = tf["transforms"]
    assert [t["child_frame_id"] for t in transforms] == [f"{n}/base_link" for n in names]
    for i, t in enumerate(transforms):
        k = n_landmarks + i
        assert t["parent_frame_id"] == "world"
        assert (t["translation"].get("x", 0.0), t["translation"].get("y", 0.0)) == pytest.approx(
            tuple(snap.pos[k]), abs=1e-6)
        q = t["rotation"]
        assert 2 * math.atan2(q.get("z", 0.0), q.get("w", 0.0)) == pytest.approx(float(snap.rot[k]), abs=1e-6)

    # /<agent>/pose in the world frame
    for i, name in enumerate(names):
        _, pose = decoded[f"/{name}/pose"]
        assert pose["frame_id"] == "world"
        p = pose["pose"]["position"]
        assert (p.get("x", 0.0), p.get("y", 0.0)) == pytest.approx(tuple(snap.pos[n_landmarks + i]), abs=1e-6)

    # /<agent>/scan[_k] in <agent>/base_link; no-return rays read +inf
    for i, name in enumerate(names):
        for k, geo in enumerate(geometry[i]):
            _, scan = decoded[f"/{name}/scan" if k == 0 else f"/{name}/scan_{k}"]
            assert scan["frame_id"] == f"{name}/base_link"
            assert scan.get("start_angle", 0.0) == pytest.approx(geo.angle_min)  # proto3 omits zeros
            assert scan.get("end_angle", 0.0) == pytest.approx(geo.angle_max)
            assert scan["pose"]["orientation"]["w"] == 1.0
            expected = np.asarray(snap.scans[i][k], dtype=np.float64)
            expected = np.where(expected >= geo.range_max, np.inf, expected)
            np.testing.assert_allclose(scan["ranges"], expected, rtol=1e-6)
    assert np.isinf(decoded["/agent_0/scan"][1]["ranges"]).any()
    assert np.isfinite(decoded["/agent_0/scan"][1]["ranges"]).any()


def test_hidden_entities_are_deleted_from_the_scene(bridge, sim):
    world = sim["world"]
    hidden = world.landmarks[0]
    hidden.is_rendering[0] = False
    try:
        _, scene = collect(bridge, sim, ["/scene"], which=0)["/scene"]
    finally:
        hidden.reset_render()
    hidden_id = env_snapshot.ros_name(hidden.name)
    assert [d["id"] for d in scene["deletions"]] == [hidden_id]
    assert len(scene["entities"]) == len(world.entities) - 1
    assert hidden_id not in {e["id"] for e in scene["entities"]}


def test_scan_no_return_as_max_range(sim):
    with pytest.raises(ValueError):
        FoxgloveBridge(port=0, agent_names=sim["names"], scan_no_return="zero")
    with FoxgloveBridge(port=0, agent_names=sim["names"], scan_no_return="max_range") as b:
        _, scan = collect(b, sim, ["/agent_0/scan"])["/agent_0/scan"]
    expected = np.minimum(np.asarray(sim["snap"].scans[0][0], dtype=np.float64), LIDAR_RANGE)
    np.testing.assert_allclose(scan["ranges"], expected, rtol=1e-6)
    assert np.isfinite(scan["ranges"]).all() and max(scan["ranges"]) == LIDAR_RANGE


def test_client_twist_reaches_on_twist(bridge, twists):
    async def main():
        async with FoxClient(bridge.port) as client:
            await client.wait_for(lambda: client.server_info is not None)
            await client.advertise(7, "/agent_0/cmd_vel", "geometry_msgs/msg/Twist")
            await client.advertise(8, "/agent_2/cmd_vel", "geometry_msgs/Twist")  # ROS 1 name, as Teleop sends
            await client.publish(7, twist_json(0.4, -0.1, 0.25))
            assert await asyncio.to_thread(twists.get) == (0, 0.4, -0.1, 0.25)
            await client.publish(8, twist_json(-0.3, 0.0, 1.5))
            assert await asyncio.to_thread(twists.get) == (2, -0.3, 0.0, 1.5)

    run(main())
    assert bridge.twists_delivered == 2


def test_bad_client_messages_are_dropped_and_server_keeps_working(bridge, sim, twists, caplog):
    caplog.set_level(logging.WARNING, logger="vmas_ros.viz.foxglove_bridge")
    calls = []

    def flaky(index, vx, vy, wz):  # the first valid twist raises: must not kill the server thread
        calls.append((index, vx, vy, wz))
        if len(calls) == 1:
            raise RuntimeError("boom")
        twists(index, vx, vy, wz)

    bridge._router.on_twist = flaky
    bad = [
        (1, b'{"linear": {"x": 1.0'),  # malformed JSON
        (1, b"\xff\xfe not utf-8"),
        (1, b'{"linear": {"x": NaN}, "angular": {"z": 0}}'),  # NaN literal
        (1, b'{"linear": {"x": 1e999}, "angular": {"z": 0}}'),  # inf after parsing
        (1, b'{"linear": {"x": 1, "y": 0, "z": 0}, "angular": {"z": "fast"}}'),  # not a number
        (1, b'{"linear": {"x": true}, "angular": {"z": 0}}'),  # bool is not a number
        (1, b'{"linear": {"x": ' + b"9" * 400 + b"}}"),  # overflows a double
        (1, b'{"foo": 1}'),  # not a Twist
        (1, b"[1, 2, 3]"),
        (1, b"[" * 5000 + b"]" * 5000),  # deep nesting
        (1, twist_json(1.0)[:-1] + b" " * MAX_CLIENT_MESSAGE_BYTES + b"}"),  # > 64 KiB
        (2, twist_json(1.0)),  # channel on an unknown topic
        (3, twist_json(1.0)),  # cdr encoding: refused
        (4, twist_json(1.0)),  # wrong schema name
        (99, twist_json(1.0)),  # never advertised
    ]

    async def main():
        async with FoxClient(bridge.port) as client:
            await client.wait_for(lambda: client.server_info is not None)
            await client.advertise(1, "/agent_1/cmd_vel")
            await client.advertise(2, "/nobody/cmd_vel")
            await client.advertise(3, "/agent_1/cmd_vel", encoding="cdr")
            await client.advertise(4, "/agent_1/cmd_vel", schema_name="std_msgs/msg/String")
            for channel_id, payload in bad:
                await client.publish(channel_id, payload)
            # messages are handled in order: once the valid ones arrive, the bad ones were dropped
            await client.publish(1, twist_json(0.1, 0.2, 0.3))  # raises in on_twist
            await client.publish(1, twist_json(0.5, 0.6, 0.7))
            assert await asyncio.to_thread(twists.get) == (1, 0.5, 0.6, 0.7)
            # the server still serves data after all that
            sub = None
            await client.wait_for(lambda: "/scene" in client.channels)
            sub = await client.subscribe("/scene")
            await client.wait_for(lambda: client.data.get(sub),
                                  tick=lambda: bridge.publish(sim["snap"], sim["world"].entities, sim["geometry"], 5))

    run(main())
    assert calls == [(1, 0.1, 0.2, 0.3), (1, 0.5, 0.6, 0.7)]
    assert twists.empty()
    assert bridge.messages_dropped >= len(bad) - 1  # the SDK itself drops the never-advertised channel
    warnings = [r.getMessage() for r in caplog.records if r.name == "vmas_ros.viz.foxglove_bridge"]
    # throttled: eleven bad payloads on /agent_1/cmd_vel give one warning, not eleven
    assert sum("dropped a message on /agent_1/cmd_vel" in w for w in warnings) == 1
    assert any("unknown topic '/nobody/cmd_vel'" in w for w in warnings)
    assert any("on_twist raised RuntimeError" in w for w in warnings)


def test_parse_twist_accepts_twist_and_twist_stamped():
    assert parse_twist(twist_json(1, 2, 3)) == ((1.0, 2.0, 3.0), "")
    stamped = {"header": {"frame_id": "agent_0/base_link"}, "twist": {"linear": {"x": 1}, "angular": {"z": -2}}}
    assert parse_twist(json.dumps(stamped).encode()) == ((1.0, 0.0, -2.0), "")
    assert parse_twist(b'{"angular": {"z": 0.5}}') == ((0.0, 0.0, 0.5), "")
    values, reason = parse_twist(b'{"linear": {"x": 1, "z": NaN}}')
    assert values is None and "linear.z" in reason


def test_old_subprotocol_is_refused(bridge):
    async def main():
        with pytest.raises(websockets.exceptions.InvalidStatus) as error:
            async with websockets.connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=["foxglove.websocket.v1"]):
                pass
        assert error.value.response.status_code == 400

    run(main())


def _listening_addresses(port):
    """Local addresses of LISTEN sockets on ``port`` (Linux /proc)."""
    found = []
    for path, family in (("/proc/net/tcp", socket.AF_INET), ("/proc/net/tcp6", socket.AF_INET6)):
        if not os.path.exists(path):
            continue
        with open(path) as f:
            next(f)
            for line in f:
                fields = line.split()
                address, hex_port = fields[1].split(":")
                if int(hex_port, 16) != port or fields[3] != "0A":  # 0A = LISTEN
                    continue
                raw = bytes.fromhex(address)
                # /proc prints the address as host-order 32-bit words
                raw = b"".join(raw[k:k + 4][::-1] for k in range(0, len(raw), 4))
                found.append(socket.inet_ntop(family, raw))
    return found


@pytest.mark.skipif(not os.path.exists("/proc/net/tcp"), reason="needs Linux /proc/net/tcp")
def test_listens_on_loopback_only_by_default(bridge):
    assert bridge.host == "127.0.0.1"
    assert _listening_addresses(bridge.port) == ["127.0.0.1"]


def test_close_is_idempotent_and_frees_the_port(sim):
    b = FoxgloveBridge(port=0, agent_names=sim["names"])
    port = b.port
    assert port > 0 and _can_connect(port)
    b.close()
    b.close()
    assert b.closed and not _can_connect(port)
    b.publish(sim["snap"], sim["world"].entities, sim["geometry"], 0)  # no-op, no error
    b.log_json("/rewards", {"total": 1.0}, 0)
    with FoxgloveBridge(port=0, agent_names=sim["names"]) as b2:
        assert _can_connect(b2.port)
        with pytest.raises(RuntimeError, match="bind"):
            FoxgloveBridge(port=b2.port, agent_names=sim["names"])
    assert b2.closed and not _can_connect(b2.port)


def _can_connect(port):
    with socket.socket() as s:
        s.settimeout(2.0)
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_log_json_rewards(bridge):
    bridge.log_json("/rewards", {"agent_0": np.float32(0.5), "total": float("nan")}, 0)
    step = {"n": 0}

    def tick():
        step["n"] += 1
        bridge.log_json("/rewards", {"agent_0": np.float32(0.5), "total": float("nan"),
                                     "step": torch.tensor(step["n"])}, step["n"] * DT_NS)

    async def main():
        async with FoxClient(bridge.port) as client:
            await client.wait_for(lambda: "/rewards" in client.channels)
            channel = client.channels["/rewards"]
            assert channel["encoding"] == "json" and channel["schemaEncoding"] == "jsonschema"
            schema = json.loads(channel["schema"])
            assert schema["type"] == "object" and schema["properties"]["agent_0"] == {"type": "number"}
            sub = await client.subscribe("/rewards")
            await client.wait_for(lambda: client.data.get(sub), tick=tick)
            return client.data[sub][-1]

    log_time, payload = run(main())
    msg = json.loads(payload)
    assert msg["agent_0"] == 0.5 and msg["total"] is None
    assert log_time == msg["step"] * DT_NS
    with pytest.raises(ValueError):
        bridge.log_json("/scene", {"x": 1}, 0)
    with pytest.raises(TypeError):
        bridge.log_json("/rewards", [1, 2], 0)


def test_publish_rejects_mismatched_inputs(bridge, sim):
    entities = sim["world"].entities
    with pytest.raises(ValueError):
        bridge.publish(sim["snap"], entities[:-1], sim["geometry"], 0)


def test_layout_file_is_plausible():
    layout = json.loads((ROOT / "config" / "foxglove_layout.json").read_text())
    panels = layout["configById"]

    def placed(node):
        return {node} if isinstance(node, str) else placed(node["first"]) | placed(node["second"])

    assert placed(layout["layout"]) == set(panels)
    three_d = next(v for k, v in panels.items() if k.startswith("3D!"))
    assert three_d["followTf"] == three_d["fixedFrame"] == "world"
    assert three_d["topics"]["/scene"]["visible"] and three_d["topics"]["/agent_0/scan"]["visible"]
    teleop = next(v for k, v in panels.items() if k.startswith("Teleop!"))
    assert teleop["topic"] == "/agent_0/cmd_vel" and teleop["publishRate"] > 2  # > 1 / cmd_vel_timeout
    plot = next(v for k, v in panels.items() if k.startswith("Plot!"))
    assert plot["paths"] and all(p["value"].startswith("/rewards.") for p in plot["paths"])
    # Foxglove reads a panel's title from foxglovePanelTitle and ignores a plain "title"
    assert all(config.get("foxglovePanelTitle") and "title" not in config for config in panels.values())
