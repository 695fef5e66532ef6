"""Hostile Foxglove clients against a real FoxgloveBridge server (real WebSocket clients, no mocks).

test_foxglove_bridge.py covers bad *payloads* on client channels (JSON, NaN,
size, schema). This file covers the protocol layer and resource limits: what
foxglove-sdk itself refuses (malformed text frames, unknown ops and binary
opcodes, unknown channel ids, frames over its 16 MiB limit), what our listener
refuses (payloads over 64 KiB, channel floods), that the SDK's log lines are
rate-limited, and above all that a second, well-behaved client keeps getting
data and keeps driving agents meanwhile.
"""
from __future__ import annotations

import asyncio
import json
import logging
import queue
import time

import pytest

pytest.importorskip("foxglove")
import websockets  # noqa: E402

from test.foxglove_client import FoxClient, twist_json  # noqa: E402
from vmas_ros.viz.foxglove_bridge import FoxgloveBridge  # noqa: E402
from vmas_ros.viz.foxglove_logs import _SDK_LOG_LIMIT, SDK_CLIENT_LOGGERS, SUBPROTOCOL  # noqa: E402
from vmas_ros.viz.foxglove_messages import _MAX_CHANNELS_PER_CLIENT, _MAX_CLIENT_CHANNELS  # noqa: E402

pytestmark = pytest.mark.timeout(60)

AGENTS = ["agent_0", "agent_1", "agent_2"]


@pytest.fixture
def twists():
    return queue.Queue()


@pytest.fixture
def bridge(twists):
    with FoxgloveBridge(port=0, agent_names=AGENTS, on_twist=lambda *a: twists.put(a)) as b:
        yield b


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 40))


async def good_client_works(bridge, client: FoxClient, twists: queue.Queue, channel: int, vx: float) -> None:
    """The well-behaved client still receives /rewards and still drives agent_0."""
    sub = await client.subscribe("/rewards")
    before = len(client.data.get(sub, []))
    await client.wait_for(lambda: len(client.data.get(sub, [])) > before,
                          tick=lambda: bridge.log_json("/rewards", {"total": 1.0}, 1))
    await client.publish(channel, twist_json(vx))
    assert await asyncio.to_thread(twists.get, True, 10) == (0, vx, 0.0, 0.0)


async def connected(bridge) -> FoxClient:
    client = await FoxClient(bridge.port).__aenter__()
    await client.wait_for(lambda: client.server_info is not None)
    return client


def test_protocol_garbage_gets_a_status_and_the_connection_stays(bridge, twists):
    garbage = [
        ("{not json", "Invalid message"),
        (json.dumps({"op": "frobnicate"}), "unknown variant `frobnicate`"),
        (json.dumps({"subscriptions": []}), "missing field `op`"),
        (json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 987654}]}),
         "Unknown channel ID: 987654"),
        (b"\x99abc", "Unknown binary opcode 153"),
        (b"\x01\x01", "Buffer too short"),
        (b"\x01" + (555).to_bytes(4, "little") + twist_json(1.0), "Unknown channel ID: 555"),
    ]

    async def main():
        bridge.log_json("/rewards", {"total": 0.0}, 0)  # the channel exists before the clients connect
        good, bad = await connected(bridge), await connected(bridge)
        try:
            await good.wait_for(lambda: "/rewards" in good.channels)
            await good.advertise(1, "/agent_0/cmd_vel")
            await bad.advertise(1, "/agent_0/cmd_vel")
            for frame, _ in garbage:
                await bad.ws.send(frame)
                await bad.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [42]}))  # silently ignored
                await bad.ws.send(b"")  # an empty binary frame: silently ignored
            await bad.wait_for(lambda: len(bad.statuses) >= len(garbage))
            texts = [s.get("message", "") for s in bad.statuses]
            for (_, expected), text in zip(garbage, texts):
                assert expected in text, texts
            assert all(s.get("level") == 2 for s in bad.statuses), bad.statuses  # error level
            # the offender is still connected and its valid messages still count
            await bad.publish(1, twist_json(0.25))
            assert await asyncio.to_thread(twists.get, True, 10) == (0, 0.25, 0.0, 0.0)
            await good_client_works(bridge, good, twists, 1, 0.5)
        finally:
            await bad.__aexit__()
            await good.__aexit__()

    run(main())
    assert bridge.twists_delivered == 2


def test_huge_frames_are_refused_and_only_the_sender_is_cut_off(bridge, twists, caplog):
    caplog.set_level(logging.WARNING)

    async def main():
        bridge.log_json("/rewards", {"total": 0.0}, 0)
        good, bad = await connected(bridge), await connected(bridge)
        try:
            await good.wait_for(lambda: "/rewards" in good.channels)
            await good.advertise(3, "/agent_0/cmd_vel")
            await bad.advertise(3, "/agent_0/cmd_vel")
            # 5 MiB: within the SDK's limit, so it reaches our listener, which drops it unread (> 64 KiB)
            await bad.publish(3, b" " * (5 << 20))
            await bad.publish(3, twist_json(0.125))  # the connection survives that
            assert await asyncio.to_thread(twists.get, True, 10) == (0, 0.125, 0.0, 0.0)
            # 20 MiB: over the SDK's 16 MiB message limit; it drops the connection
            with pytest.raises(websockets.exceptions.ConnectionClosed):
                await bad.publish(3, b" " * (20 << 20))
                for _ in range(100):
                    await asyncio.sleep(0.05)
                    await bad.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [1]}))
            await good_client_works(bridge, good, twists, 3, 0.75)
        finally:
            await bad.__aexit__()
            await good.__aexit__()

    run(main())
    assert bridge.messages_dropped == 1
    warnings = [r.getMessage() for r in caplog.records]
    assert any("payload of 5242880 bytes exceeds 65536" in w for w in warnings), warnings
    assert any("Message too long" in w for w in warnings), warnings  # the SDK's own report


def test_a_channel_flood_cannot_evict_another_clients_channel(bridge, twists, caplog):
    caplog.set_level(logging.WARNING, logger="vmas_ros.viz.foxglove_bridge")
    flood = _MAX_CLIENT_CHANNELS + 100  # more than all clients together may hold

    async def main():
        bridge.log_json("/rewards", {"total": 0.0}, 0)
        good, bad = await connected(bridge), await connected(bridge)
        try:
            await good.wait_for(lambda: "/rewards" in good.channels)
            await good.advertise(7, "/agent_0/cmd_vel")
            await asyncio.sleep(0.2)  # the good client advertised first, as it would in real life
            await bad.ws.send(json.dumps({"op": "advertise", "channels": [
                {"id": 1000 + k, "topic": "/agent_1/cmd_vel", "encoding": "json", "schemaName": ""}
                for k in range(flood)]}))
            await bad.publish(1000, twist_json(0.5))  # within its 256: accepted
            assert await asyncio.to_thread(twists.get, True, 10) == (1, 0.5, 0.0, 0.0)
            await bad.publish(1000 + _MAX_CHANNELS_PER_CLIENT + 5, twist_json(0.5))  # beyond: ignored
            await good_client_works(bridge, good, twists, 7, 0.3)
        finally:
            await bad.__aexit__()
            await good.__aexit__()

    run(main())
    assert twists.empty()
    assert bridge.messages_dropped == 1
    warnings = [r.getMessage() for r in caplog.records if r.name == "vmas_ros.viz.foxglove_bridge"]
    assert any(f"a client may advertise at most {_MAX_CHANNELS_PER_CLIENT} channels" in w for w in warnings)
    # every client's channels are forgotten when it disconnects (the SDK unadvertises them): nothing stays
    deadline = time.monotonic() + 10
    while (bridge._router._channels or bridge._router._per_client) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not bridge._router._channels and not bridge._router._per_client


def test_the_sdks_log_lines_about_bad_clients_are_rate_limited(bridge, twists, caplog):
    caplog.set_level(logging.INFO)
    _SDK_LOG_LIMIT._window.clear()  # a fresh window: earlier tests in this process logged too

    async def main():
        good, bad = await connected(bridge), await connected(bridge)
        try:
            await good.advertise(1, "/agent_0/cmd_vel")
            for _ in range(300):
                await bad.ws.send("{not json")
            await bad.wait_for(lambda: len(bad.statuses) >= 300)  # every frame was handled (and answered)
            await good.publish(1, twist_json(0.5))
            assert await asyncio.to_thread(twists.get, True, 10) == (0, 0.5, 0.0, 0.0)
        finally:
            await bad.__aexit__()
            await good.__aexit__()

    run(main())
    sdk = [r for r in caplog.records if r.name in SDK_CLIENT_LOGGERS]
    assert 1 <= len(sdk) <= 10, f"{len(sdk)} SDK log lines for 300 bad frames"
    assert "Invalid message" in sdk[0].getMessage()


def test_a_client_of_the_old_protocol_is_told_what_the_node_needs(bridge, caplog):
    """A client that offers only foxglove.websocket.v1 gets HTTP 400, and the log says which protocol and app work."""
    caplog.set_level(logging.INFO)

    async def main():
        with pytest.raises(websockets.exceptions.InvalidStatus) as refused:
            await websockets.connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=["foxglove.websocket.v1"])
        assert refused.value.response.status_code == 400

    run(main())
    deadline = time.monotonic() + 5
    while not any("refused a client" in r.getMessage() for r in caplog.records) and time.monotonic() < deadline:
        time.sleep(0.05)
    lines = [r for r in caplog.records if "refused a client" in r.getMessage()]
    assert len(lines) == 1 and lines[0].levelname == "WARNING", [r.getMessage() for r in caplog.records]
    message = lines[0].getMessage()
    assert "handshake failed" in message and f"only the {SUBPROTOCOL} WebSocket subprotocol" in message
    assert "Foxglove app" in message and "foxglove.websocket.v1" in message
