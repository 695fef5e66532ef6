"""Live view of one env in Foxglove, and teleop from it, without ROS.

``FoxgloveBridge`` runs a foxglove-sdk WebSocket server (subprotocol
``foxglove.sdk.v1``; open ``ws://127.0.0.1:<port>`` in the Foxglove app) and
turns the per-env host snapshot that ``sim_node`` already takes
(:class:`vmas_ros.simulator.env_snapshot.Snapshot`) into Foxglove's own schemas:

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

The SDK itself answers malformed JSON, unknown opcodes, subscriptions to
unknown channel ids and MessageData on unknown client channels with a status
message and a log line (rate-limited, :mod:`vmas_ros.viz.foxglove_logs`), and closes
the connection of a client that sends a frame over 16 MiB; other clients are
not affected. A client may advertise at most 256 channels.

Threading: ``on_twist`` runs on the SDK's server thread, not the caller's.
Keep it short and thread-safe (storing the command in a dict is enough);
exceptions it raises are caught and logged.

The server listens on 127.0.0.1 unless told otherwise: it has no
authentication, and a client that can reach it can drive the agents.
"""
from __future__ import annotations

import json
import logging
import socket
import threading
import time
import weakref
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

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
    from foxglove.websocket import Capability
except ImportError as _error:  # pragma: no cover - depends on the installation
    raise ImportError(
        "vmas_ros.viz.foxglove_bridge needs foxglove-sdk: pip install 'vmas_ros[foxglove]'"
    ) from _error

from vmas_ros.simulator.env_snapshot import ScanGeometry, Snapshot, unique_names, yaw_to_quaternion
from vmas_ros.viz.foxglove_logs import SUBPROTOCOL  # importing it also makes the SDK's client log lines useful
from vmas_ros.viz.foxglove_messages import (  # noqa: F401 - re-exported (public names and helpers)
    _DISC_HEIGHT,
    _LINE_WIDTH,
    _MAX_CHANNELS_PER_CLIENT,
    _MAX_CLIENT_CHANNELS,
    _THROTTLE_S,
    MAX_CLIENT_MESSAGE_BYTES,
    TWIST_SCHEMAS,
    TwistCallback,
    _json_schema,
    _jsonable,
    _number,
    _pose,
    _rgba,
    _Throttle,
    _timestamp,
    _TwistRouter,
    _visibility,
    parse_twist,
)

__all__ = ["FoxgloveBridge", "TwistCallback", "parse_twist", "MAX_CLIENT_MESSAGE_BYTES", "TWIST_SCHEMAS"]

logger = logging.getLogger(__name__)

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
        frame_prefix: goes before each agent's ``<agent>/base_link`` frame.
        agent_names: ROS-style agent names (``env_snapshot.unique_names``), in
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
        snap = env_snapshot.Snapshot.take(world, env_index, lidars)
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
        frame_prefix: str = "",
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
        self.frame_id, self.frame_prefix = frame_id, frame_prefix
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
        logger.info("foxglove: serving on ws://%s:%d (subprotocol %s)", host, self.port, SUBPROTOCOL)

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
                        timestamp=stamp, parent_frame_id=self.frame_id,
                        child_frame_id=f"{self.frame_prefix}{name}/base_link",
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
            frame_id=f"{self.frame_prefix}{self.agent_names[agent_index]}/base_link",
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
