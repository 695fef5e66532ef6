"""A minimal Foxglove WebSocket client (subprotocol foxglove.sdk.v1) shared by the tests."""
from __future__ import annotations

import asyncio
import json
import struct

import websockets

SUBPROTOCOL = "foxglove.sdk.v1"
WAIT = 10.0  # generous upper bound for any single condition; tests finish far sooner


class FoxClient:
    """Minimal foxglove.sdk.v1 client: tracks serverInfo, channels, message data, time and status."""

    def __init__(self, port):
        self.url = f"ws://127.0.0.1:{port}"
        self.server_info = None
        self.channels = {}  # topic -> advertised channel dict
        self.data = {}  # subscription id -> list of (log_time, payload)
        self.times = []
        self.statuses = []
        self._subscriptions = {}  # subscription id -> channel
        self._next_sub = 1

    async def __aenter__(self):
        self.ws = await websockets.connect(self.url, subprotocols=[SUBPROTOCOL], max_size=None)
        self._cond = asyncio.Condition()
        self._reader = asyncio.create_task(self._read())
        return self

    async def __aexit__(self, *exc):
        self._reader.cancel()
        await self.ws.close()

    async def _read(self):
        async for message in self.ws:
            if isinstance(message, str):
                msg = json.loads(message)
                op = msg.get("op")
                if op == "serverInfo":
                    self.server_info = msg
                elif op == "advertise":
                    for channel in msg["channels"]:
                        self.channels[channel["topic"]] = channel
                elif op == "status":
                    self.statuses.append(msg)
            else:
                opcode = message[0]
                if opcode == 1:  # MessageData: u32 subscription id, u64 log time, payload
                    sub_id, log_time = struct.unpack_from("<IQ", message, 1)
                    self.data.setdefault(sub_id, []).append((log_time, bytes(message[13:])))
                elif opcode == 2:  # Time: u64
                    self.times.append(struct.unpack_from("<Q", message, 1)[0])
            async with self._cond:
                self._cond.notify_all()

    async def wait_for(self, predicate, timeout=WAIT, tick=None, every=0.05):
        """Until ``predicate()``; ``tick()`` (e.g. publish a step) runs between short waits."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while not predicate():
            if loop.time() > deadline:
                raise AssertionError(f"condition not met within {timeout} s")
            if tick is not None:
                tick()
            try:
                async with self._cond:
                    await asyncio.wait_for(self._cond.wait_for(predicate), every if tick else deadline - loop.time())
            except (asyncio.TimeoutError, TimeoutError):
                pass

    async def subscribe(self, topic):
        sub_id = self._next_sub
        self._next_sub += 1
        channel = self.channels[topic]
        self._subscriptions[sub_id] = channel
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": sub_id, "channelId": channel["id"]}]}))
        return sub_id

    async def advertise(self, channel_id, topic, schema_name="geometry_msgs/msg/Twist", encoding="json"):
        await self.ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": channel_id, "topic": topic, "encoding": encoding, "schemaName": schema_name}]}))

    async def publish(self, channel_id, payload: bytes):
        await self.ws.send(b"\x01" + struct.pack("<I", channel_id) + payload)


def twist_json(vx=0.0, vy=0.0, wz=0.0) -> bytes:
    return json.dumps({"linear": {"x": vx, "y": vy, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": wz}}).encode()


