"""sim_node's per-step state topics, converted in bulk and published as pre-serialised bytes.

Why bytes: filling an rclpy message field by field is slow in Python, and
``publish(msg)`` then converts the whole object to C again, which makes a
MarkerArray the dearest message of all. Yet from one step to the
next only numbers change: frame ids, marker shapes and array lengths stay put,
so the serialised (CDR) layout of every message is fixed once the node is built.

So each message is serialised once from a prototype, and the byte offsets of
the fields that change (stamps, positions, quaternions, body twists, scan
ranges, per-env colours) are found by writing unique sentinel values into the
prototype and searching the bytes for them (no hand-written CDR layout; a
sentinel that is not found exactly once refuses the build). All messages live
back to back in one byte arena; a step writes every changed number with four
numpy scatters, then publishes each message's slice with ``publish(bytes)``.
What subscribers and bags receive is, field for field, what ``publish(msg)`` of
the same values would send (test/ros/test_publish.py checks it against the
per-field conversion of ``convert``), with every CDR padding byte zero (record/cdr.py):
identical steps give identical bytes, and no stray heap memory goes out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from builtin_interfaces.msg import Time

from vmas_ros.ros import convert
from vmas_ros.record.cdr import serialize_zeroed
from vmas_ros.ros.message_types import type_name
from vmas_ros.ros.topic_audit import quiet_publisher_events
from vmas_ros.simulator import env_snapshot


def _resolve(message, path: str) -> Tuple[object, str]:
    """(owner object, attribute name) of a dotted field path such as ``pose.position.x``."""
    *parents, name = path.split(".")
    owner = message
    for part in parents:
        owner = owner[int(part)] if part.isdigit() else getattr(owner, part)
    return owner, name


@dataclass
class _Template:
    """One message: its prototype, where it sits in the arena and which fields a step rewrites."""

    topic: str
    message: object
    f64: List[Tuple[str, int]] = field(default_factory=list)  # (field path, index into the float64 values)
    f32: List[Tuple[str, int]] = field(default_factory=list)  # (field path, index into the float32 values)
    arrays: List[Tuple[str, int, int]] = field(default_factory=list)  # (path, start, length) in the ranges
    points: List[Tuple[str, int]] = field(default_factory=list)  # (path of a uint8[] holding float32s, count)
    stamps: List[str] = field(default_factory=list)  # paths of builtin_interfaces/Time fields


class StateMessages:
    """Poses, odometry, scans, pose arrays, markers and /clock of one env, as CDR bytes per step.

    ``fill(snap, stamp_ns, colours)`` rewrites the arena from an ``env_snapshot.Snapshot``;
    ``payloads()`` then yields ``(topic, type name, bytes)`` per message in a fixed
    order. Values go in as ``convert`` computes them (float32 arithmetic where it
    uses float32, ``math`` for trigonometry), so the bytes equal the per-field path.

    ``frame_id`` is the world frame as published; ``frame_prefix`` goes before each ``<agent>/base_link``.
    ``per_agent``: every agent's own pose, odometry, scans and goal (a swarm leaves them out: its agents
    are in ``agents/poses``); ``goals``: agent index -> the entity row of its goal, published as
    ``<agent>/goal`` (a PoseStamped in the world frame); ``cloud``: ``lidar/points``, every lidar ray's
    hit as a point of one ``sensor_msgs/PointCloud2`` in the world frame (NaN for a ray that hit nothing).
    """

    def __init__(self, agent_names: Sequence[str], n_landmarks: int, n_entities: int,
                 scan_geometry: Dict[int, List[env_snapshot.ScanGeometry]], scan_rays: Dict[int, List[int]],
                 frame_id: str, markers, per_agent: bool = True, cloud: bool = False,
                 frame_prefix: str = "", goals: Optional[Dict[int, int]] = None) -> None:
        from geometry_msgs.msg import Pose, PoseArray, PoseStamped
        from nav_msgs.msg import Odometry
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import LaserScan

        self.n_landmarks, self.n_entities = n_landmarks, n_entities
        self._twist_base = 4 * n_entities  # float64 values: entity (x, y, qz, qw), then agent body (vx, vy, wz)
        templates: List[_Template] = []
        clock = _Template("/clock", Clock(), stamps=["clock"])
        templates.append(clock)
        scans: List[Tuple[int, int]] = []  # (agent, lidar) in ranges order
        self.scan_max: List[np.ndarray] = []
        self.scan_min: List[np.ndarray] = []  # -inf for a lidar without a range_min (no reading is below it)
        ranges_offset = 0
        ray_entity: List[np.ndarray] = []  # per ray, for the cloud: the agent's entity row and its body angle
        ray_angle: List[np.ndarray] = []
        for i, name in enumerate(agent_names):
            k = n_landmarks + i
            if per_agent:
                pose = _Template(f"{name}/pose", PoseStamped(), stamps=["header.stamp"])
                pose.message.header.frame_id = frame_id
                pose.f64 = self._pose_fields("pose", k)
                odom = _Template(f"{name}/odom", Odometry(), stamps=["header.stamp"])
                odom.message.header.frame_id, odom.message.child_frame_id = frame_id, f"{frame_prefix}{name}/base_link"
                t = self._twist_base + 3 * i
                odom.f64 = self._pose_fields("pose.pose", k) + [
                    ("twist.twist.linear.x", t), ("twist.twist.linear.y", t + 1), ("twist.twist.angular.z", t + 2)]
                templates += [pose, odom]
                if goals and i in goals:
                    goal = _Template(f"{name}/goal", PoseStamped(), stamps=["header.stamp"])
                    goal.message.header.frame_id = frame_id
                    goal.f64 = self._pose_fields("pose", goals[i])
                    templates.append(goal)
            for j, geometry in enumerate(scan_geometry.get(i, [])):
                n_rays = scan_rays[i][j]
                if per_agent:
                    topic = f"{name}/scan" if j == 0 else f"{name}/scan_{j}"
                    scan = _Template(topic, LaserScan(), stamps=["header.stamp"])
                    convert.fill_scan(scan.message, geometry, np.zeros(0, np.float32))
                    scan.message.header.frame_id = f"{frame_prefix}{name}/base_link"
                    scan.arrays = [("ranges", ranges_offset, n_rays)]
                    templates.append(scan)
                ranges_offset += n_rays
                self.scan_max.append(np.full(n_rays, geometry.range_max, dtype=np.float32))
                self.scan_min.append(np.full(n_rays, geometry.range_min if geometry.range_min > 0 else -np.inf,
                                             dtype=np.float32))
                scans.append((i, j))
                ray_entity.append(np.full(n_rays, k, dtype=np.intp))
                ray_angle.append(geometry.angle_min + geometry.angle_increment * np.arange(n_rays, dtype=np.float64))
        self.scan_order = scans
        self._rays_seen: Optional[dict] = None  # the snapshots' ray counts last checked against scan_order
        self._block_order = False  # ... whether their scans follow one another in scan_order already
        self.n_ranges = ranges_offset
        self._ray_entity = np.concatenate(ray_entity) if ray_entity else np.zeros(0, np.intp)
        self._ray_angle = np.concatenate(ray_angle) if ray_angle else np.zeros(0, np.float64)
        self.cloud = cloud and ranges_offset > 0
        if self.cloud:
            templates.append(self._cloud_template(frame_id, ranges_offset))
        for topic, rows in (("agents/poses", range(n_landmarks, n_entities)), ("landmarks/poses", range(n_landmarks))):
            array = _Template(topic, PoseArray(), stamps=["header.stamp"])
            array.message.header.frame_id = frame_id
            array.message.poses = [Pose() for _ in rows]
            for slot, k in enumerate(rows):
                array.f64 += self._pose_fields(f"poses.{slot}", k)
            templates.append(array)
        marker_array = _Template("world/markers", markers)
        for k in range(n_entities):
            marker_array.stamps.append(f"markers.{k}.header.stamp")
            marker_array.f64 += self._pose_fields(f"markers.{k}.pose", k)
        templates.append(marker_array)
        self._marker_template = marker_array
        self.templates = templates
        self.types = [type_name(type(t.message)) for t in templates]
        self.topics = [t.topic for t in templates]
        self._build()

    @staticmethod
    def _cloud_template(frame_id: str, n_points: int) -> _Template:
        """``lidar/points``: one x, y, z float32 point per ray, in the world frame, laid out as
        ``sensor_msgs/PointCloud2`` (unorganised: height 1, not dense, since misses are NaN)."""
        from sensor_msgs.msg import PointCloud2, PointField

        cloud = _Template("lidar/points", PointCloud2(), stamps=["header.stamp"])
        message = cloud.message
        message.header.frame_id = frame_id
        message.height, message.width = 1, n_points
        message.fields = [PointField(name=axis, offset=4 * m, datatype=PointField.FLOAT32, count=1)
                          for m, axis in enumerate("xyz")]
        message.is_bigendian, message.point_step, message.row_step = False, 12, 12 * n_points
        message.is_dense = False
        cloud.points = [("data", 3 * n_points)]  # float32 values, written as the message's bytes
        return cloud

    @staticmethod
    def _pose_fields(prefix: str, k: int) -> List[Tuple[str, int]]:
        """A geometry_msgs/Pose's changing fields: x, y and the yaw quaternion's z, w (the rest stays 0)."""
        return [(f"{prefix}.position.x", 4 * k), (f"{prefix}.position.y", 4 * k + 1),
                (f"{prefix}.orientation.z", 4 * k + 2), (f"{prefix}.orientation.w", 4 * k + 3)]

    def set_colour_fields(self, per_env: Sequence[int]) -> None:
        """Entities whose colour is drawn per env: their marker colours are rewritten every step."""
        self._marker_template.f32 = [
            (f"markers.{k}.color.{c}", 3 * n + m) for n, k in enumerate(per_env) for m, c in enumerate("rgb")]
        self._build()

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        """Serialise every prototype with sentinels in its changing fields and record their byte offsets."""
        chunks: List[bytes] = []
        idx64, src64, idx32, src32, idx_ranges, idx_points, idx_stamp = [], [], [], [], [], [], []
        offset, counter = 0, 0
        self.spans: List[Tuple[int, int]] = []
        for template in self.templates:
            message = template.message
            sentinels = []  # (packed bytes, kind, source)
            for path, source in template.f64:
                counter += 1
                value = 1.0e6 + 0.0078125 * counter + 7.0e5 * (counter % 7)
                owner, name = _resolve(message, path)
                setattr(owner, name, value)
                sentinels.append((np.float64(value).astype("<f8").tobytes(), 8, "f64", source))
            for path, source in template.f32:
                counter += 1
                value = float(np.float32(3.0e4 + 0.25 * counter))
                owner, name = _resolve(message, path)
                setattr(owner, name, value)
                sentinels.append((np.float32(value).astype("<f4").tobytes(), 4, "f32", source))
            for path, start, length in template.arrays:
                values = (5.0e4 + 0.5 * np.arange(counter, counter + length)).astype(np.float32)
                counter += length
                owner, name = _resolve(message, path)
                setattr(owner, name, values.tolist())
                sentinels.append((values.astype("<f4").tobytes(), 4 * length, "ranges", (start, length)))
            for path, length in template.points:
                packed = (5.0e4 + 0.5 * np.arange(counter, counter + length)).astype("<f4").tobytes()
                counter += length
                owner, name = _resolve(message, path)
                setattr(owner, name, packed)
                sentinels.append((packed, 4 * length, "points", None))
            for path in template.stamps:
                counter += 1
                owner, name = _resolve(message, path)
                setattr(owner, name, Time(sec=1_100_000_000 + counter, nanosec=900_000_000 + counter))
                packed = np.array([1_100_000_000 + counter, 900_000_000 + counter], "<u4").tobytes()
                sentinels.append((packed, 8, "stamp", None))
            data = serialize_zeroed(message)  # rclpy leaves padding bytes as the heap left them
            for packed, size, kind, source in sentinels:
                at = data.find(packed)
                if at < 0 or data.find(packed, at + 1) >= 0:
                    raise RuntimeError(f"{template.topic}: a sentinel of {kind} was not found exactly once in the "
                                       f"serialised message; cannot pre-serialise it")
                rows = offset + at + np.arange(size)
                if kind == "f64":
                    idx64.append(rows), src64.append(source)
                elif kind == "f32":
                    idx32.append(rows), src32.append(source)
                elif kind == "ranges":
                    idx_ranges.append(rows)
                elif kind == "points":
                    idx_points.append(rows)
                else:
                    idx_stamp.append(rows)
            self.spans.append((offset, offset + len(data)))
            chunks.append(data)
            offset += len(data)
        self.arena = np.frombuffer(b"".join(chunks), dtype=np.uint8).copy()
        self._idx64 = np.array(idx64, dtype=np.intp).reshape(-1, 8)
        self._src64 = np.array(src64, dtype=np.intp)
        self._idx32 = np.array(idx32, dtype=np.intp).reshape(-1, 4)
        self._src32 = np.array(src32, dtype=np.intp)
        self._idx_ranges = np.concatenate(idx_ranges) if idx_ranges else np.zeros(0, np.intp)
        self._idx_points = np.concatenate(idx_points) if idx_points else np.zeros(0, np.intp)
        self._idx_stamp = np.array(idx_stamp, dtype=np.intp).reshape(-1, 8)
        self._scan_max = np.concatenate(self.scan_max) if self.scan_max else np.zeros(0, np.float32)
        self._scan_min = np.concatenate(self.scan_min) if self.scan_min else np.zeros(0, np.float32)
        self._has_min = bool((self._scan_min > 0).any())  # else the -inf pass is skipped
        self._bytes = self.arena.tobytes()
        self._pending: Optional[tuple] = None  # (snapshot, stamp, colours) of a fill not yet written

    # -------------------------------------------------------------------- step
    def values(self, snap: env_snapshot.Snapshot) -> np.ndarray:
        """The float64 values of a step: per entity (x, y, qz, qw), then per agent its body-frame twist.

        Computed exactly as ``convert.set_pose``/``fill_odometry`` do: ``math`` trigonometry on the
        float64 of each float32 angle, and the body twist in float32 arithmetic (NumPy 2's rule for a
        float32 times a Python float), so the bytes match the per-message conversion bit for bit.
        """
        rot = snap.rot.tolist()
        half = [y / 2.0 for y in rot]
        out = np.empty(self._twist_base + 3 * (self.n_entities - self.n_landmarks), dtype=np.float64)
        quarter = out[: self._twist_base].reshape(-1, 4)
        quarter[:, 0:2] = snap.pos
        quarter[:, 2] = [math.sin(h) for h in half]
        quarter[:, 3] = [math.cos(h) for h in half]
        agents = slice(self.n_landmarks, self.n_entities)
        yaw = rot[agents]
        c = np.array([math.cos(y) for y in yaw], dtype=np.float64).astype(np.float32)
        s = np.array([math.sin(y) for y in yaw], dtype=np.float64).astype(np.float32)
        vx, vy = snap.vel[agents, 0], snap.vel[agents, 1]
        twist = out[self._twist_base:].reshape(-1, 3)
        twist[:, 0] = vx * c + vy * s
        twist[:, 1] = -vx * s + vy * c
        twist[:, 2] = snap.ang_vel[agents]
        return out

    def ranges(self, snap: env_snapshot.Snapshot) -> np.ndarray:
        """Every scan's ranges in publishing order, float32, as ``convert.fill_scan`` writes them (REP 117):
        +inf where nothing was hit, -inf closer than a lidar's ``range_min``."""
        if not self.scan_order:
            return np.zeros(0, np.float32)
        if snap.rays is not self._rays_seen:  # the same dict every step: checked once
            self._rays_seen = snap.rays
            order = [(i, j) for i, counts in snap.rays.items() for j in range(len(counts))]
            self._block_order = order == self.scan_order
        if self._block_order:  # every scan end to end already: no slice per lidar
            ranges = snap.scan_block.astype(np.float32, copy=False)
        else:
            ranges = np.concatenate([snap.scans[i][j] for i, j in self.scan_order]).astype(np.float32, copy=False)
        out = np.where(ranges >= self._scan_max, np.float32(np.inf), ranges)
        if self._has_min:
            out = np.where(ranges < self._scan_min, np.float32(-np.inf), out)
        return out.astype(np.float32)

    def points(self, snap: env_snapshot.Snapshot, ranges: np.ndarray) -> np.ndarray:
        """``[R, 3]`` float32: where each ray hit, in the world frame (z 0); NaN for a ray that hit nothing
        (``ranges`` +inf) or something closer than its lidar's ``range_min`` (-inf)."""
        k = self._ray_entity
        angle = snap.rot[k].astype(np.float64) + self._ray_angle
        hit = np.where(np.isfinite(ranges), ranges, np.nan).astype(np.float64)
        out = np.zeros((k.size, 3), dtype=np.float32)
        out[:, 0] = snap.pos[k, 0] + hit * np.cos(angle)
        out[:, 1] = snap.pos[k, 1] + hit * np.sin(angle)
        out[:, 2] = np.where(np.isfinite(hit), 0.0, np.nan)
        return out

    def fill(self, snap: env_snapshot.Snapshot, stamp_ns: int, colours: Optional[np.ndarray] = None) -> None:
        """Make one step the messages' content. The arena is written (four scatters, whatever the number of
        agents) when the bytes are first asked for: a step nobody subscribes to or records costs nothing."""
        self._pending = (snap, stamp_ns, colours)

    @property
    def _data(self) -> bytes:
        """Every message's CDR bytes end to end, of the last ``fill``."""
        if self._pending is not None:
            self._write(*self._pending)
            self._pending = None
        return self._bytes

    def _write(self, snap: env_snapshot.Snapshot, stamp_ns: int, colours: Optional[np.ndarray]) -> None:
        arena = self.arena
        arena[self._idx64] = self.values(snap)[self._src64].astype("<f8").view(np.uint8).reshape(-1, 8)
        if self._idx_ranges.size or self._idx_points.size:
            ranges = self.ranges(snap)
            if self._idx_ranges.size:
                arena[self._idx_ranges] = ranges.astype("<f4").view(np.uint8)
            if self._idx_points.size:
                arena[self._idx_points] = self.points(snap, ranges).astype("<f4").view(np.uint8).reshape(-1)
        if self._idx32.size and colours is not None:
            arena[self._idx32] = np.asarray(colours, dtype="<f4")[self._src32].view(np.uint8).reshape(-1, 4)
        stamp = np.array([stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000], dtype="<u4").view(np.uint8)
        arena[self._idx_stamp] = stamp
        self._bytes = arena.tobytes()

    def payloads(self) -> List[Tuple[str, str, bytes]]:
        """(topic as created, relative but /clock, type name, CDR bytes) of every message, in ``topics`` order."""
        data = self._data
        return [(topic, kind, data[a:b]) for topic, kind, (a, b) in zip(self.topics, self.types, self.spans)]

    def payload(self, index: int) -> bytes:
        a, b = self.spans[index]
        return self._data[a:b]

    def decode(self, topic: str):
        """The message last filled for ``topic``, deserialised (for tests and tools; not used per step)."""
        import importlib

        from rclpy.serialization import deserialize_message

        index = [t.lstrip("/") for t in self.topics].index(topic.lstrip("/"))
        package, _, name = self.types[index].split("/")
        return deserialize_message(self.payload(index), getattr(importlib.import_module(f"{package}.msg"), name))


class StatePublisher:
    """The publishers of ``StateMessages`` on a node; publishes a step's bytes and hands them to ``record``.

    ``publish_clock=False`` leaves ``/clock`` off the graph (another node owns the clock) while a
    recording still gets it: a bag's steps are this node's own.
    """

    def __init__(self, node, messages: StateMessages, qos, publish_clock: bool = True) -> None:
        from geometry_msgs.msg import PoseArray, PoseStamped
        from nav_msgs.msg import Odometry
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import LaserScan, PointCloud2
        from visualization_msgs.msg import MarkerArray

        classes = {type_name(c): c for c in (PoseArray, PoseStamped, Odometry, Clock, LaserScan, PointCloud2,
                                              MarkerArray)}
        self.messages = messages
        self._on_graph = [i for i, topic in enumerate(messages.topics) if publish_clock or topic != "/clock"]
        # no default event handlers: they cost every executor round (QosAudit warns instead)
        self.publishers = [node.create_publisher(classes[messages.types[i]], messages.topics[i], qos,
                                                 event_callbacks=quiet_publisher_events()) for i in self._on_graph]
        resolved = dict(zip(self._on_graph, (p.topic_name for p in self.publishers)))
        #: each message's resolved topic, in ``messages.topics`` order (``/clock`` also when not published)
        self.topic_names = [resolved.get(i, topic) for i, topic in enumerate(messages.topics)]
        # rclpy's Publisher.publish takes its handle's lock and type-checks each message, a large share of
        # the cost of publishing bytes. The node publishes and destroys its publishers on one thread,
        # never at once, so it calls the bound rcl publisher directly where this rclpy has one.
        raw = [getattr(p, "_Publisher__publisher", None) for p in self.publishers]
        self._send = [r.publish_raw for r in raw] if all(hasattr(r, "publish_raw") for r in raw) else \
            [p.publish for p in self.publishers]

    def publish(self, record: Optional[Callable[[str, str, bytes], None]] = None) -> None:
        """Publish the last ``fill``; ``record(resolved topic, type name, bytes)`` gets each message too.
        With no subscriber on any of them and nothing to record, the messages are not even written (the
        publishers are volatile: a message nobody is matched to is lost anyway)."""
        if record is None and not any(p.get_subscription_count() for p in self.publishers):
            return
        data, spans = self.messages._data, self.messages.spans
        for send, i in zip(self._send, self._on_graph):
            a, b = spans[i]
            send(data[a:b])
        if record is not None:
            for topic, kind, (a, b) in zip(self.topic_names, self.messages.types, spans):
                record(topic, kind, data[a:b])


class StepPhases:
    """Wall time of each part of sim_node's step, summed (``vmas-ros bench node`` reads it).

    actions; engine (``env.step``); lidar: the published env's snapshot from the engine (its lidar
    casts and the copy to the host, or taking what a compiled step computed); convert: laying it out and
    filling the messages; publish.
    """

    NAMES = ("actions", "engine", "lidar", "convert", "publish")

    def __init__(self) -> None:
        self.steps = 0
        self.seconds: Dict[str, float] = {name: 0.0 for name in self.NAMES}

    def add(self, name: str, since: float) -> None:
        import time

        self.seconds[name] += time.perf_counter() - since

    def per_step_us(self, steps: Optional[int] = None) -> Dict[str, float]:
        """Microseconds per step of each part (over ``steps``, default the steps that published)."""
        steps = self.steps if steps is None else steps
        return {name: 1e6 * s / max(1, steps) for name, s in self.seconds.items()}
