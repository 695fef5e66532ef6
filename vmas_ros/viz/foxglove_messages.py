"""Client-message parsing and Foxglove message building for :mod:`vmas_ros.viz.foxglove_bridge`.

Holds what the bridge needs that is not the server itself: validation of the
JSON ``geometry_msgs/Twist`` a client publishes (:func:`parse_twist`), the
server listener routing client ``cmd_vel`` channels to ``on_twist``
(:class:`_TwistRouter`, with its throttled warnings), and the helpers turning a
host snapshot into Foxglove schema fields (timestamps, poses, colours,
visibility) and arbitrary values into JSON (and a JSON Schema).

Warnings are logged on the ``vmas_ros.viz.foxglove_bridge`` logger, as before
the split. Public names are re-exported by :mod:`vmas_ros.viz.foxglove_bridge`.
"""
from __future__ import annotations

import json
import logging
import math
import threading
import time
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

try:
    from foxglove.messages import (
        Color as FoxColor,
        Pose,
        Quaternion,
        Timestamp,
        Vector3,
    )
    from foxglove.websocket import ServerListener
except ImportError as _error:  # pragma: no cover - depends on the installation
    raise ImportError(
        "vmas_ros.viz.foxglove_messages needs foxglove-sdk: pip install 'vmas_ros[foxglove]'"
    ) from _error

from vmas_ros.simulator.env_snapshot import yaw_to_quaternion
from vmas_ros.viz.foxglove_logs import THROTTLE_S as _THROTTLE_S

__all__ = ["TwistCallback", "parse_twist", "MAX_CLIENT_MESSAGE_BYTES", "TWIST_SCHEMAS"]

# the bridge's logger: warnings keep the name they had before the split
logger = logging.getLogger("vmas_ros.viz.foxglove_bridge")

TwistCallback = Callable[[int, float, float, float], None]

#: client messages larger than this are dropped unread (a Twist in JSON is ~100 bytes)
MAX_CLIENT_MESSAGE_BYTES = 64 * 1024
#: schema names a client channel may carry on ``/<agent>/cmd_vel`` ("" = schemaless JSON)
TWIST_SCHEMAS = frozenset({
    "geometry_msgs/msg/Twist",
    "geometry_msgs/Twist",
    "geometry_msgs/msg/TwistStamped",
    "geometry_msgs/TwistStamped",
    "",
})
_MAX_CLIENT_CHANNELS = 4096  # bound on remembered client channels over all clients
#: one client's channels beyond this are ignored (never evicting another client's: a client that
#: advertises thousands of channels must not break someone else's teleop)
_MAX_CHANNELS_PER_CLIENT = 256
_DISC_HEIGHT = 0.05  # thickness of the 2D shapes in the 3D panel, as sim_node's markers
_LINE_WIDTH = 0.02


class _Throttle:
    """Logs a warning per key at most once every ``period`` seconds, counting the rest."""

    def __init__(self, period: float = _THROTTLE_S) -> None:
        self.period = period
        self._last: Dict[str, float] = {}
        self._suppressed: Dict[str, int] = {}
        self._lock = threading.Lock()

    def warn(self, key: str, message: str, *args) -> None:
        now = time.monotonic()
        with self._lock:
            if now - self._last.get(key, -math.inf) < self.period:
                self._suppressed[key] = self._suppressed.get(key, 0) + 1
                return
            self._last[key] = now
            suppressed = self._suppressed.pop(key, 0)
        if suppressed:
            message += f" ({suppressed} similar dropped since the last warning)"
        logger.warning(message, *args)


def _number(value: Any) -> Optional[float]:
    """A finite float from a JSON number, else None (bools, strings, NaN and inf are refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        value = float(value)
    except OverflowError:  # a JSON integer too large for a double
        return None
    return value if math.isfinite(value) else None


def parse_twist(data: bytes) -> Tuple[Optional[Tuple[float, float, float]], str]:
    """Decode a JSON ``geometry_msgs/Twist`` (or ``TwistStamped``) into body-frame ``(vx, vy, wz)``.

    Returns ``(values, "")`` or ``(None, reason)``. Missing components read 0
    (Foxglove's Teleop panel sends all six); present ones must be finite numbers.
    """
    if len(data) > MAX_CLIENT_MESSAGE_BYTES:
        return None, f"payload of {len(data)} bytes exceeds {MAX_CLIENT_MESSAGE_BYTES}"
    try:
        msg = json.loads(bytes(data).decode("utf-8"))  # NaN/Infinity literals are vetted below
    except (UnicodeDecodeError, ValueError, RecursionError) as error:
        return None, f"malformed JSON ({type(error).__name__})"
    if isinstance(msg, dict) and isinstance(msg.get("twist"), dict):  # TwistStamped
        msg = msg["twist"]
    if not isinstance(msg, dict) or not ({"linear", "angular"} & msg.keys()):
        return None, "not a Twist (expected an object with 'linear' and 'angular')"
    values = []
    for part, axis in (("linear", "x"), ("linear", "y"), ("angular", "z")):
        vector = msg.get(part, {})
        if not isinstance(vector, dict):
            return None, f"'{part}' is not an object"
        value = _number(vector.get(axis, 0.0))
        if value is None:
            return None, f"{part}.{axis} is not a finite number"
        values.append(value)
    for part in ("linear", "angular"):  # the unused components must be sane too
        for axis, raw in (msg.get(part) or {}).items():
            if axis in ("x", "y", "z") and _number(raw) is None:
                return None, f"{part}.{axis} is not a finite number"
    return (values[0], values[1], values[2]), ""


class _TwistRouter(ServerListener):
    """The server listener: client cmd_vel channels -> ``on_twist``.

    Holds no reference to the bridge (the server holds this object, and the
    bridge's finalizer holds the server), so a dropped bridge is collected.
    """

    def __init__(self, agent_names: Sequence[str], on_twist: Optional[TwistCallback]) -> None:
        self.on_twist = on_twist
        self.topics: Dict[str, int] = {}
        for i, name in enumerate(agent_names):
            self.topics[f"/{name}/cmd_vel"] = i
            self.topics[f"{name}/cmd_vel"] = i
        self._channels: Dict[Tuple[int, int], Tuple[str, Optional[int]]] = {}
        self._per_client: Dict[int, int] = {}  # client id -> how many of its channels are remembered
        self._lock = threading.Lock()
        self.throttle = _Throttle()
        self.delivered = 0  # twists passed to on_twist (for tests and diagnostics)
        self.dropped = 0

    # -- ServerListener callbacks (SDK thread) --------------------------------
    def on_client_advertise(self, client, channel) -> None:
        try:
            topic, schema = channel.topic, channel.schema_name or ""
            index = self.topics.get(topic)
            if index is None:
                self.throttle.warn("topic", "foxglove: ignoring client channel on unknown topic %r", topic)
            elif channel.encoding != "json":
                index = None
                self.throttle.warn("encoding", "foxglove: ignoring %s with encoding %r (json only)",
                                   topic, channel.encoding)
            elif schema not in TWIST_SCHEMAS:
                index = None
                self.throttle.warn("schema", "foxglove: ignoring %s with schema %r (expected "
                                   "geometry_msgs/msg/Twist)", topic, schema)
            key = (client.id, channel.id)
            with self._lock:
                count = self._per_client.get(client.id, 0)
                full = count >= _MAX_CHANNELS_PER_CLIENT or len(self._channels) >= _MAX_CLIENT_CHANNELS
                if key not in self._channels and full:
                    refused = True
                else:
                    refused = False
                    if key not in self._channels:
                        self._per_client[client.id] = count + 1
                    self._channels[key] = (topic, index)
            if refused:  # its messages then count as "unknown client channel"
                self.throttle.warn("limit", "foxglove: ignoring client channel %d (%r): a client may advertise at "
                                   "most %d channels, %d in all", channel.id, topic, _MAX_CHANNELS_PER_CLIENT,
                                   _MAX_CLIENT_CHANNELS)
        except Exception:  # never let an error reach the server thread
            logger.exception("foxglove: error handling a client advertisement")

    def on_client_unadvertise(self, client, client_channel_id: int) -> None:
        with self._lock:  # the SDK also calls this for each channel of a client that disconnects
            if self._channels.pop((client.id, client_channel_id), None) is not None:
                left = self._per_client.get(client.id, 1) - 1
                if left > 0:
                    self._per_client[client.id] = left
                else:
                    self._per_client.pop(client.id, None)

    def on_message_data(self, client, client_channel_id: int, data: bytes) -> None:
        try:
            self._handle(client.id, client_channel_id, data)
        except Exception:  # pragma: no cover - defensive: _handle catches its own errors
            logger.exception("foxglove: error handling a client message")

    # -------------------------------------------------------------------------
    def _handle(self, client_id: int, channel_id: int, data: bytes) -> None:
        with self._lock:
            entry = self._channels.get((client_id, channel_id))
        if entry is None:
            self.dropped += 1
            self.throttle.warn("channel", "foxglove: message on unknown client channel %d", channel_id)
            return
        topic, index = entry
        if index is None:  # refused at advertisement (unknown topic, encoding or schema)
            self.dropped += 1
            self.throttle.warn("ignored", "foxglove: dropped a message on ignored client topic %r", topic)
            return
        values, reason = parse_twist(data)
        if values is None:
            self.dropped += 1
            self.throttle.warn(f"bad:{topic}", "foxglove: dropped a message on %s: %s", topic, reason)
            return
        if self.on_twist is None:
            return
        try:
            self.on_twist(index, *values)
            self.delivered += 1
        except Exception as error:
            self.throttle.warn("callback", "foxglove: on_twist raised %s: %s", type(error).__name__, error)


def _timestamp(nanoseconds: int) -> Timestamp:
    nanoseconds = int(nanoseconds)
    return Timestamp(nanoseconds // 1_000_000_000, nanoseconds % 1_000_000_000)


def _pose(x: float, y: float, yaw: float) -> Pose:
    qx, qy, qz, qw = yaw_to_quaternion(float(yaw))
    return Pose(position=Vector3(x=float(x), y=float(y), z=0.0), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _rgba(entity, env_index: int) -> FoxColor:
    """An entity's colour (tuple, Color enum, or a [3] / per-env [B, 3] tensor) with its alpha."""
    color = getattr(entity, "color", (0.25, 0.25, 0.25))
    color = getattr(color, "value", color)  # Color enum
    if hasattr(color, "detach"):
        color = color.detach()
        if color.dim() > 1:
            color = color[env_index]
        color = color.flatten().cpu().tolist()
    r, g, b = (float(c) for c in list(color)[:3])
    alpha = getattr(entity, "alpha", None)
    alpha = float(alpha) if isinstance(alpha, (int, float)) and alpha > 0 else 1.0
    return FoxColor(r=r, g=g, b=b, a=min(alpha, 1.0))


def _visibility(entities: Sequence, env_index: int) -> List[bool]:
    """``is_rendering[env_index]`` of every entity, in one gather when they are all tensors."""
    flags = [getattr(e, "is_rendering", None) for e in entities]
    if flags and all(hasattr(f, "detach") and f.dim() == 1 for f in flags):
        try:
            import torch

            return [bool(v) for v in torch.stack([f.detach() for f in flags])[:, env_index].tolist()]
        except (RuntimeError, IndexError):
            pass
    visible = []
    for f in flags:
        try:
            visible.append(True if f is None else bool(f[env_index]))
        except (IndexError, TypeError):
            visible.append(True)
    return visible


def _jsonable(value: Any) -> Any:
    """numpy / torch scalars and arrays to plain Python; non-finite floats to None (JSON null)."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


def _json_schema(value: Any) -> dict:
    """A JSON Schema describing ``value`` (lets Foxglove autocomplete message paths in plots)."""
    if isinstance(value, bool):
        return {"type": "boolean"}
    if isinstance(value, (int, float)):
        return {"type": "number"}
    if isinstance(value, str):
        return {"type": "string"}
    if isinstance(value, dict):
        return {"type": "object", "properties": {k: _json_schema(v) for k, v in value.items()}}
    if isinstance(value, list):
        return {"type": "array", "items": _json_schema(value[0]) if value else {}}
    return {}
