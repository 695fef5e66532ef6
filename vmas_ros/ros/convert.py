"""Batched simulator state to standard ROS 2 messages.

The node publishes one env of the batch. The engine takes everything that
env needs to the host as one vector (``simulator.env_snapshot``: computed by a
compiled step itself, or gathered after it in a handful of tensor ops);
:class:`Snapshot` lays it out per entity and per lidar, and the fill
functions then write plain floats into message objects that the node creates
once and reuses.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence

import numpy as np
import torch

from vmas_ros.simulator.env_snapshot import EnvSnapshot, gather
from vmas_ros.simulator.utils import Color

_INVALID = re.compile(r"[^A-Za-z0-9_]")


def ros_name(name: str) -> str:
    """A valid ROS name token for an entity name ("landmark 0" -> "landmark_0", "1a" -> "n1a")."""
    token = _INVALID.sub("_", name.strip()) or "entity"
    token = re.sub(r"_+", "_", token)
    return token if not token[0].isdigit() else "n" + token


def yaw_to_quaternion(yaw: float) -> tuple:
    """(x, y, z, w) of a rotation by ``yaw`` about +z."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def rgb(color, env_index: int = 0) -> tuple:
    """(r, g, b) floats of an entity colour: a Color, a tuple, or a tensor ([3] or per-env [B, 3])."""
    if isinstance(color, Color):
        color = color.value
    if isinstance(color, torch.Tensor):
        color = (color[env_index] if color.dim() > 1 else color).flatten()[:3].tolist()
    return tuple(float(c) for c in color[:3])


@dataclass
class Snapshot:
    """Host copy of one env: per-entity arrays and per-agent lidar readings."""

    pos: np.ndarray  # [N, 2]
    vel: np.ndarray  # [N, 2]
    rot: np.ndarray  # [N]
    ang_vel: np.ndarray  # [N]
    #: agent index -> the ray count of each of its lidars, in the order the scans follow the state in ``host``
    rays: Dict[int, List[int]]
    #: everything above in one host array: the state's 6 N values, then every scan (see all_finite)
    host: Optional[np.ndarray] = None
    n_state: int = 0
    #: the all_finite answer when whoever took the snapshot worked it out already (a compiled step)
    finite: Optional[bool] = None

    @property
    def scans(self) -> Dict[int, List[np.ndarray]]:
        """Agent index -> one array per lidar (views into ``host``), laid out when first asked for: a swarm's
        publishers take every scan at once (:attr:`scan_block`) and never need the thousand views."""
        scans = self.__dict__.get("_scans")
        if scans is None:
            scans, offset = {}, self.n_state
            for i, counts in self.rays.items():
                scans[i] = []
                for n in counts:
                    scans[i].append(self.host[offset: offset + n])
                    offset += n
            self.__dict__["_scans"] = scans
        return scans

    @property
    def scan_block(self) -> np.ndarray:
        """Every scan's ranges end to end, in ``rays`` order (a view into ``host``)."""
        return self.host[self.n_state:]

    def all_finite(self) -> bool:
        """No NaN or inf in the state and no NaN in a scan (an unhit ray may read inf): two passes in all."""
        if self.finite is not None:
            return self.finite
        return bool(np.isfinite(self.host[: self.n_state]).all() and not np.isnan(self.host[self.n_state:]).any())

    @staticmethod
    def take(world, env_index: int, lidars: Dict[int, list]) -> "Snapshot":
        """Env ``env_index`` gathered from the current state with one device-to-host copy (every lidar measures)."""
        host = gather(world, env_index, [s for sensors in lidars.values() for s in sensors])
        return Snapshot.of_host(host, {i: [s.n_rays for s in sensors] for i, sensors in lidars.items()})

    @staticmethod
    def of_host(host: np.ndarray, rays: Dict[int, List[int]], finite: Optional[bool] = None) -> "Snapshot":
        """The snapshot laid out in ``host`` (``env_snapshot.EnvVector.values``): the ``[6, N]`` state rows
        (x, y, angle, vx, vy, wz), then the scans, ``rays[agent]`` values per lidar in that order (views into
        ``host``, no copies); ``finite``: the :meth:`all_finite` answer when it is known already."""
        n_state = host.size - sum(n for counts in rays.values() for n in counts)
        state = host[:n_state].reshape(6, -1)
        return Snapshot(state[0:2].T, state[3:5].T, state[2], state[5], rays, host, n_state, finite)


class PublishedEnv:
    """The published env's :class:`Snapshot` after each step, from the engine's ``EnvSnapshot``.

    Built once with the node's world and lidars (``agent_lidars``); the
    engine chooses then how every snapshot is taken. ``take(env_index)``
    after a step or a reset.
    """

    def __init__(self, world, lidars: Dict[int, list]) -> None:
        self.source = EnvSnapshot(world, [s for sensors in lidars.values() for s in sensors])
        self._rays = {i: [s.n_rays for s in sensors] for i, sensors in lidars.items()}

    def take(self, env_index: int) -> Snapshot:
        vector = self.source.take(env_index)
        return Snapshot.of_host(vector.values, self._rays, vector.finite)


def set_pose(pose, x: float, y: float, yaw: float) -> None:
    pose.position.x, pose.position.y, pose.position.z = float(x), float(y), 0.0
    q = yaw_to_quaternion(float(yaw))
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = q


def fill_odometry(msg, x: float, y: float, yaw: float, vx: float, vy: float, wz: float) -> None:
    """Pose in the world frame, twist in the body frame (nav_msgs/Odometry convention)."""
    set_pose(msg.pose.pose, x, y, yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    msg.twist.twist.linear.x = float(vx * c + vy * s)
    msg.twist.twist.linear.y = float(-vx * s + vy * c)
    msg.twist.twist.linear.z = 0.0
    msg.twist.twist.angular.z = float(wz)


@dataclass
class ScanGeometry:
    """LaserScan angles and ranges of one lidar; count == round((max - min) / increment) + 1 == n_rays.

    The angles are the lidar's own rays: a full circle's last ray stops one
    increment short of the first (no ray twice), a partial span ends on its
    ``angle_end``. ``range_min`` 0 means the lidar has none.
    """

    angle_min: float
    angle_max: float
    angle_increment: float
    range_max: float
    range_min: float = 0.0

    @staticmethod
    def of(lidar, range_min: float = 0.0) -> "ScanGeometry":
        angles = lidar.angles[0].detach().cpu().tolist()
        increment = (angles[-1] - angles[0]) / (len(angles) - 1) if len(angles) > 1 else 0.0
        return ScanGeometry(float(angles[0]), float(angles[-1]), float(increment), float(lidar.max_range),
                            float(range_min))


def fill_scan(msg, geometry: ScanGeometry, ranges: np.ndarray) -> None:
    """REP 117: a ray that hit nothing reads +inf, not max_range; one closer than a ``range_min`` > 0 reads
    -inf (something is there, too close to measure)."""
    msg.angle_min, msg.angle_max = geometry.angle_min, geometry.angle_max
    msg.angle_increment = geometry.angle_increment
    msg.range_min, msg.range_max = geometry.range_min, geometry.range_max
    msg.time_increment, msg.scan_time = 0.0, 0.0
    values = np.where(ranges >= geometry.range_max, np.inf, ranges)
    if geometry.range_min > 0:
        values = np.where(ranges < geometry.range_min, -np.inf, values)
    msg.ranges = values.astype(np.float32).tolist()


def shape_marker(marker, entity, marker_id: int, frame_id: str, namespace: str = "entities") -> None:
    """Static part of an entity's marker: type, size, colour (pose is set every step)."""
    from visualization_msgs.msg import Marker

    shape = entity.shape
    marker.header.frame_id = frame_id
    marker.ns, marker.id, marker.action = namespace, marker_id, Marker.ADD
    r, g, b = rgb(entity.color)
    marker.color.r, marker.color.g, marker.color.b = r, g, b
    marker.color.a = float(getattr(entity, "alpha", 1.0)) if getattr(entity, "alpha", None) else 1.0
    marker.scale.z = 0.05
    if shape.kind == "sphere":
        marker.type = Marker.CYLINDER
        marker.scale.x = marker.scale.y = 2 * shape.radius
    elif shape.kind == "box":
        marker.type = Marker.CUBE
        marker.scale.x, marker.scale.y = shape.length, shape.width
    else:  # line: a thin box along body x
        marker.type = Marker.CUBE
        marker.scale.x, marker.scale.y = shape.length, 0.02


def agent_lidars(world) -> Dict[int, list]:
    """Agent index -> its Lidar sensors (the ones the node publishes as LaserScan)."""
    from vmas_ros.simulator.sensors import Lidar

    found = {}
    for i, agent in enumerate(world.agents):
        lidars = [s for s in agent.sensors if isinstance(s, Lidar)]
        if lidars:
            found[i] = lidars
    return found


def unique_names(names: Sequence[str]) -> List[str]:
    """Sanitised names, made unique by suffixes when sanitising makes two equal."""
    seen: Dict[str, int] = {}
    result = []
    for name in names:
        token = ros_name(name)
        count = seen.get(token, 0)
        seen[token] = count + 1
        result.append(token if count == 0 else f"{token}_{count}")
    return result

