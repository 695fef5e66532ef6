"""One env's snapshot written into standard ROS 2 messages.

The node publishes one env of the batch, read as a
:class:`~vmas_ros.simulator.env_snapshot.Snapshot` (the same snapshot the
Foxglove bridge and the recorder read); the fill functions here write its
plain floats into message objects that the node creates once and reuses.
"""
from __future__ import annotations

import math

import numpy as np

from vmas_ros.simulator.env_snapshot import ScanGeometry, rgb, yaw_to_quaternion


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
