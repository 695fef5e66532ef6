"""Live view of one env in Foxglove, and teleop from it, without ROS.

``FoxgloveBridge`` runs a foxglove-sdk WebSocket server (subprotocol
``foxglove.sdk.v1``; open ``ws://127.0.0.1:<port>`` in the Foxglove app) and
turns the per-env host snapshot that ``sim_node`` already takes
(:class:`vmas_ros.ros.convert.Snapshot`) into Foxglove's own schemas:

==========================  ============================  =========================
topic                       schema                        frame
==========================  ============================  =========================
``/scene``                  ``foxglove.SceneUpdate``      ``frame_id`` (world)
``/tf``                     ``foxglove.FrameTransforms``  world -> ``<agent>/base_link``
``/<agent>/pose``           ``foxglove.PoseInFrame``      ``frame_id``
``/<agent>/scan[_k]``       ``foxglove.LaserScan``        ``<agent>/base_link``
any, via ``log_json``       JSON (e.g. ``/rewards``)      -
==========================  ============================  =========================

Every message is logged with ``log_time`` = simulation time, and the server's
time (capability ``Time``) is set to it, so Foxglove's clock follows the
simulation rather than the wall clock.

Lidar rays that hit nothing are sent as ``+inf``. Foxglove's LaserScan schema
has no ``range_min``/``range_max`` and only says ``ranges`` are "distances of
detections", so ``max_range`` would draw a ring of detections that are not
there; ``+inf`` keeps the REP 117 convention of the ROS ``LaserScan`` that
``sim_node`` publishes. Pass ``scan_no_return="max_range"`` for the other
choice.

Teleop: the server advertises ``ClientPublish`` with the ``json`` encoding.
A client (e.g. Foxglove's Teleop panel) that advertises
``/<agent>/cmd_vel`` with schema ``geometry_msgs/msg/Twist`` (or
``geometry_msgs/Twist``, or the ``TwistStamped`` variants) and publishes
``{"linear": {"x": .., "y": .., "z": ..}, "angular": {..}}`` makes the bridge
call ``on_twist(agent_index, vx, vy, wz)`` (body frame, REP 103). Anything
else (bad JSON, unknown topic or channel, non-finite values, payloads over
64 KiB, other encodings) is dropped with a throttled ``logging`` warning.

Threading: ``on_twist`` runs on the SDK's server thread, not the caller's.
Keep it short and thread-safe (storing the command in a dict is enough);
exceptions it raises are caught and logged.

The server listens on 127.0.0.1 unless told otherwise: it has no
authentication, and a client that can reach it can drive the agents.
"""
from __future__ import annotations

import json
import logging
import math
import socket
import threading
import time
import weakref
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

try:
    import foxglove
    from foxglove import Channel, Context
    from foxglove.channels import (
        FrameTransformsChannel,
        LaserScanChannel,
        PoseInFrameChannel,
        SceneUpdateChannel,
    )
    from foxglove.messages import (
        Color as FoxColor,
        CubePrimitive,
        CylinderPrimitive,
        FrameTransform,
        FrameTransforms,
        LaserScan,
        Pose,
        PoseInFrame,
        Quaternion,
        SceneEntity,
        SceneEntityDeletion,
        SceneUpdate,
        Timestamp,
        Vector3,
    )
    from foxglove.websocket import Capability, ServerListener
except ImportError as _error:  # pragma: no cover - depends on the installation
    raise ImportError(
        "vmas_ros.viz.foxglove_bridge needs foxglove-sdk: pip install 'vmas_ros[foxglove]'"
    ) from _error

from vmas_ros.ros.convert import ScanGeometry, Snapshot, unique_names, yaw_to_quaternion

__all__ = ["FoxgloveBridge", "TwistCallback", "parse_twist", "MAX_CLIENT_MESSAGE_BYTES", "TWIST_SCHEMAS"]

logger = logging.getLogger(__name__)

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
_THROTTLE_S = 2.0
_MAX_CLIENT_CHANNELS = 4096  # bound on remembered client channels (a client may advertise many)
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
            with self._lock:
                if len(self._channels) >= _MAX_CLIENT_CHANNELS:
                    self._channels.pop(next(iter(self._channels)))
                self._channels[(client.id, channel.id)] = (topic, index)
        except Exception:  # never let an error reach the server thread
            logger.exception("foxglove: error handling a client advertisement")

    def on_client_unadvertise(self, client, client_channel_id: int) -> None:
        with self._lock:
            self._channels.pop((client.id, client_channel_id), None)

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


def _stop(server) -> None:
    try:
        server.stop()
    except Exception:  # pragma: no cover - stopping twice or at interpreter exit
        pass


def _port_released(host: str, port: int) -> bool:
    """True once nothing listens on (host, port): a SO_REUSEADDR bind succeeds then (Linux, macOS)."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except OSError:
        return True  # cannot tell: do not wait
    for family, kind, proto, _, address in infos:
        with socket.socket(family, kind, proto) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                probe.bind(address)
            except OSError:
                return False
    return True


def _wait_released(host: str, port: int, timeout: float = 1.0) -> bool:
    """``server.stop()`` returns before the SDK's runtime closes the listener: wait (a few ms) for it."""
    deadline = time.monotonic() + timeout
    while not _port_released(host, port):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.001)
    return True


class FoxgloveBridge:
    """A foxglove-sdk WebSocket server showing one env of the batch, with Twist teleop.

    Args:
        host: interface to listen on; 127.0.0.1 by default (only this machine).
        port: TCP port; 0 picks a free one, read back from ``.port``.
        frame_id: fixed frame of the scene, poses and transforms.
        agent_names: ROS-style agent names (``convert.unique_names``), in
            ``world.agents`` order; they name topics and frames.
        on_twist: ``on_twist(agent_index, vx, vy, wz)`` for each valid Twist a
            client publishes on ``/<agent>/cmd_vel`` (called on the server's thread).
        scan_no_return: ``"inf"`` (default) or ``"max_range"``: what a ray that
            hit nothing reads in ``foxglove.LaserScan``.
        name: server name shown by Foxglove.

    Raises ``RuntimeError`` (from the SDK: "Failed to bind port ...") when the
    port is taken. Call ``close()`` (or use ``with``) when done; a bridge that
    is never closed stops its server at interpreter exit.

    Example::

        bridge = FoxgloveBridge(port=8765, agent_names=node.agent_names,
                                on_twist=lambda i, vx, vy, wz: commands.update({i: (vx, vy, wz)}))
        snap = convert.Snapshot.take(world, env_index, lidars)
        bridge.publish(snap, world.entities, scan_geometry, sim_time_ns)
        bridge.log_json("/rewards", {"agent_0": 0.1, "total": 0.3}, sim_time_ns)
        bridge.close()
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 8765,
        frame_id: str = "world",
        agent_names: Sequence[str] = (),
        on_twist: Optional[TwistCallback] = None,
        *,
        scan_no_return: str = "inf",
        name: str = "vmas_ros",
    ) -> None:
        if scan_no_return not in ("inf", "max_range"):
            raise ValueError(f"scan_no_return must be 'inf' or 'max_range', got {scan_no_return!r}")
        if not isinstance(port, int) or isinstance(port, bool) or not 0 <= port <= 65535:
            raise ValueError(f"port must be an int in 0..65535, got {port!r}")
        names = [str(n) for n in agent_names]
        if len(set(names)) != len(names):
            raise ValueError(f"agent names must be unique, got {names}")
        self.host = host
        self.frame_id = frame_id
        self.agent_names: List[str] = names
        self.scan_no_return = scan_no_return
        self._closed = False
        self._lock = threading.Lock()  # publish / log_json / close from different threads
        self._context = Context()  # our own: topics never clash with other bridges or the global context
        self._router = _TwistRouter(names, on_twist)
        self._server = foxglove.start_server(
            name=name,
            host=host,
            port=port,
            capabilities=[Capability.ClientPublish, Capability.Time],
            supported_encodings=["json"],
            server_listener=self._router,
            context=self._context,
        )
        self._finalizer = weakref.finalize(self, _stop, self._server)
        self.port: int = int(self._server.port)
        ctx = self._context
        self._scene = SceneUpdateChannel("/scene", context=ctx)
        self._tf = FrameTransformsChannel("/tf", context=ctx)
        self._poses = [PoseInFrameChannel(f"/{n}/pose", context=ctx) for n in names]
        self._scans: Dict[Tuple[int, int], Any] = {}  # (agent, lidar) -> LaserScanChannel, made on first use
        self._json: Dict[str, Channel] = {}
        self._entity_ids: Tuple[Tuple[str, ...], List[str]] = ((), [])
        self._hidden: set = set()
        logger.info("foxglove: serving on ws://%s:%d (subprotocol foxglove.sdk.v1)", host, self.port)

    # ---------------------------------------------------------------- properties
    @property
    def url(self) -> str:
        """``ws://host:port`` to open in Foxglove (Open connection -> Foxglove WebSocket)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def twists_delivered(self) -> int:
        """How many client Twists reached ``on_twist``."""
        return self._router.delivered

    @property
    def messages_dropped(self) -> int:
        """How many client messages were refused (bad JSON, unknown channel, non-finite, too big...)."""
        return self._router.dropped

    def scan_topic(self, agent_index: int, lidar_index: int = 0) -> str:
        """``/<agent>/scan`` for an agent's first lidar, ``/<agent>/scan_<k>`` for the others (as sim_node)."""
        name = self.agent_names[agent_index]
        return f"/{name}/scan" if lidar_index == 0 else f"/{name}/scan_{lidar_index}"

    # ------------------------------------------------------------------- publish
    def publish(
        self,
        snapshot: Snapshot,
        entities: Sequence,
        lidar_geometry: Mapping[int, Sequence[ScanGeometry]],
        sim_time_ns: int,
        *,
        env_index: int = 0,
    ) -> None:
        """Log one step: ``/scene``, ``/tf``, ``/<agent>/pose`` and ``/<agent>/scan*``.

        ``snapshot`` rows follow ``entities`` (``world.entities``: landmarks
        first, then the agents in ``agent_names`` order). ``env_index`` only
        picks per-env colours and visibility. Channels no client subscribes to
        cost nothing but a ``has_sinks()`` check.
        """
        sim_time_ns = int(sim_time_ns)
        n_entities = len(entities)
        if snapshot.pos.shape[0] != n_entities:
            raise ValueError(f"snapshot has {snapshot.pos.shape[0]} entities, the world {n_entities}")
        n_agents = len(self.agent_names)
        if n_agents > n_entities:
            raise ValueError(f"{n_agents} agent names but only {n_entities} entities")
        with self._lock:
            if self._closed:
                return
            first_agent = n_entities - n_agents
            stamp = _timestamp(sim_time_ns)
            pos, rot = np.asarray(snapshot.pos, dtype=np.float64), np.asarray(snapshot.rot, dtype=np.float64)
            if self._scene.has_sinks():
                self._scene.log(self._scene_update(entities, pos, rot, stamp, env_index), log_time=sim_time_ns)
            if self._tf.has_sinks():
                transforms = []
                for i, name in enumerate(self.agent_names):
                    k = first_agent + i
                    qx, qy, qz, qw = yaw_to_quaternion(float(rot[k]))
                    transforms.append(FrameTransform(
                        timestamp=stamp, parent_frame_id=self.frame_id, child_frame_id=f"{name}/base_link",
                        translation=Vector3(x=float(pos[k, 0]), y=float(pos[k, 1]), z=0.0),
                        rotation=Quaternion(x=qx, y=qy, z=qz, w=qw),
                    ))
                self._tf.log(FrameTransforms(transforms=transforms), log_time=sim_time_ns)
            for i, channel in enumerate(self._poses):
                if channel.has_sinks():
                    k = first_agent + i
                    channel.log(PoseInFrame(timestamp=stamp, frame_id=self.frame_id,
                                            pose=_pose(pos[k, 0], pos[k, 1], rot[k])), log_time=sim_time_ns)
            for i, readings in snapshot.scans.items():
                geometries = lidar_geometry.get(i, [])
                for j, ranges in enumerate(readings):
                    if j >= len(geometries) or not 0 <= i < n_agents:
                        continue  # no geometry for this lidar: nothing sensible to draw
                    channel = self._scan_channel(i, j)
                    if channel.has_sinks():
                        channel.log(self._laser_scan(i, geometries[j], ranges, stamp), log_time=sim_time_ns)
            self._server.broadcast_time(sim_time_ns)

    def _scan_channel(self, agent_index: int, lidar_index: int):
        key = (agent_index, lidar_index)
        channel = self._scans.get(key)
        if channel is None:
            channel = LaserScanChannel(self.scan_topic(agent_index, lidar_index), context=self._context)
            self._scans[key] = channel
        return channel

    def _laser_scan(self, agent_index: int, geometry: ScanGeometry, ranges, stamp: Timestamp) -> LaserScan:
        values = np.asarray(ranges, dtype=np.float64).reshape(-1)
        if self.scan_no_return == "inf":
            values = np.where(values >= geometry.range_max, np.inf, values)
        else:
            values = np.minimum(values, geometry.range_max)
        return LaserScan(
            timestamp=stamp,
            frame_id=f"{self.agent_names[agent_index]}/base_link",
            pose=Pose(position=Vector3(), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            start_angle=geometry.angle_min,
            end_angle=geometry.angle_max,
            ranges=values.tolist(),
        )

    def _ids(self, entities: Sequence) -> List[str]:
        names = tuple(str(getattr(e, "name", "entity")) for e in entities)
        if names != self._entity_ids[0]:
            self._entity_ids = (names, unique_names(names))
        return self._entity_ids[1]

    def _scene_update(self, entities, pos, rot, stamp, env_index: int) -> SceneUpdate:
        scene, deletions, hidden = [], [], set()
        visible = _visibility(entities, env_index)
        for k, (entity, entity_id) in enumerate(zip(entities, self._ids(entities))):
            if not visible[k]:
                hidden.add(entity_id)
                if entity_id not in self._hidden:
                    deletions.append(SceneEntityDeletion(timestamp=stamp, id=entity_id))
                continue
            pose, color, shape = _pose(pos[k, 0], pos[k, 1], rot[k]), _rgba(entity, env_index), entity.shape
            kind = getattr(shape, "kind", "")
            primitives: Dict[str, list] = {}
            if kind == "sphere":
                d = 2.0 * float(shape.radius)
                primitives["cylinders"] = [CylinderPrimitive(
                    pose=pose, size=Vector3(x=d, y=d, z=_DISC_HEIGHT), bottom_scale=1.0, top_scale=1.0, color=color)]
            elif kind == "box":
                primitives["cubes"] = [CubePrimitive(
                    pose=pose, size=Vector3(x=float(shape.length), y=float(shape.width), z=_DISC_HEIGHT), color=color)]
            elif kind == "line":  # a thin box along body x, as sim_node's markers
                primitives["cubes"] = [CubePrimitive(
                    pose=pose, size=Vector3(x=float(shape.length), y=_LINE_WIDTH, z=_DISC_HEIGHT), color=color)]
            else:
                continue  # unknown shape: nothing to draw
            scene.append(SceneEntity(timestamp=stamp, frame_id=self.frame_id, id=entity_id, **primitives))
        self._hidden = hidden
        return SceneUpdate(deletions=deletions, entities=scene)

    # ---------------------------------------------------------------------- json
    def log_json(self, topic: str, message: Mapping[str, Any], sim_time_ns: int, *,
                 schema: Optional[dict] = None) -> None:
        """Log a JSON object on ``topic`` (made on first use) at ``sim_time_ns``.

        Numbers may be numpy or torch scalars/arrays; NaN and inf become
        ``null``. Unless ``schema`` is given, a JSON Schema is inferred from the
        first message so that Foxglove can autocomplete message paths.

        Example, per-agent rewards for the layout's Plot panel::

            bridge.log_json("/rewards", {"agent_0": 0.1, "agent_1": -0.2, "total": -0.1}, sim_time_ns)
        """
        if not isinstance(message, Mapping):
            raise TypeError(f"log_json needs a mapping (a JSON object), got {type(message).__name__}")
        if not isinstance(topic, str) or not topic:
            raise ValueError("topic must be a non-empty string")
        data = _jsonable(message)
        with self._lock:
            if self._closed:
                return
            channel = self._json.get(topic)
            if channel is None:
                if topic in self._typed_topics():
                    raise ValueError(f"{topic} is already a typed channel of this bridge")
                inferred = dict(schema) if schema is not None else _json_schema(data)
                inferred.setdefault("type", "object")
                inferred.setdefault("title", "vmas_ros" + (topic if topic.startswith("/") else "/" + topic))
                channel = Channel(topic, schema=inferred, context=self._context)
                self._json[topic] = channel
            if channel.has_sinks():
                channel.log(json.dumps(data, allow_nan=False).encode("utf-8"), log_time=int(sim_time_ns))

    def _typed_topics(self) -> set:
        topics = {"/scene", "/tf"} | {f"/{n}/pose" for n in self.agent_names}
        return topics | {self.scan_topic(i, j) for i, j in self._scans}

    # --------------------------------------------------------------------- close
    def close(self) -> None:
        """Stop the server and close the channels; safe to call more than once.

        Returns once the port no longer accepts connections (at most ~1 s).
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._finalizer()  # server.stop(), once
            if not _wait_released(self.host, self.port):
                logger.warning("foxglove: port %d still in use 1 s after stopping the server", self.port)
            channels: Iterable = [self._scene, self._tf, *self._poses, *self._scans.values(), *self._json.values()]
            for channel in channels:
                try:
                    channel.close()
                except Exception:  # pragma: no cover - already closed by the SDK
                    pass
        logger.info("foxglove: server on port %d stopped", self.port)

    def __enter__(self) -> "FoxgloveBridge":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else self.url
        return f"FoxgloveBridge({state}, agents={self.agent_names})"
