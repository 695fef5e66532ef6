"""robot_fleet's ROS messages: built once per robot, filled from the fleet's arrays on every publish.

Conventions (REP 103/105): the odometry pose and every goal and pose array
are in the shared odom frame; the odometry twist and the scan are in
``<robot>/base_link`` (x forward, y left). A pose's yaw becomes a quaternion
about z. Covariances state the noise the node adds (sigma squared on the
diagonal), so a consumer that reads them knows how far to trust the values.
"""
from __future__ import annotations

import array
import math
from typing import Sequence

import numpy as np
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan

from vmas_ros.fleet.raycast import angle_increment

__all__ = ["set_pose", "odometry", "fill_odometry", "laser_scan", "fill_scan", "pose_array", "goal"]


def set_pose(pose: Pose, x: float, y: float, yaw: float) -> None:
    """``pose`` at (x, y, 0), turned by ``yaw`` about z."""
    pose.position.x, pose.position.y, pose.position.z = float(x), float(y), 0.0
    pose.orientation.x = pose.orientation.y = 0.0
    pose.orientation.z, pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)


def odometry(frame: str, child: str, position_sigma: float, yaw_sigma: float, velocity_sigma: float) -> Odometry:
    """An Odometry for robot frame ``child`` in ``frame``, its covariances set from the noise sigmas."""
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = frame, child
    pose_cov = [0.0] * 36
    pose_cov[0] = pose_cov[7] = position_sigma ** 2  # x, y
    pose_cov[35] = yaw_sigma ** 2  # rotation about z
    twist_cov = [0.0] * 36
    twist_cov[0] = twist_cov[7] = velocity_sigma ** 2
    msg.pose.covariance, msg.twist.covariance = pose_cov, twist_cov
    return msg


def fill_odometry(msg: Odometry, stamp, report: Sequence[float]) -> Odometry:
    """``msg`` stamped ``stamp`` with ``report [6]``: x, y, yaw (odom frame), vx, vy, wz (body frame)."""
    x, y, yaw, vx, vy, wz = (float(v) for v in report)
    msg.header.stamp = stamp
    set_pose(msg.pose.pose, x, y, yaw)
    msg.twist.twist.linear.x, msg.twist.twist.linear.y = vx, vy
    msg.twist.twist.angular.z = wz
    return msg


def laser_scan(frame: str, n_rays: int, angle_min: float, angle_max: float, range_min: float,
               range_max: float, rate_hz: float) -> LaserScan:
    """A LaserScan of the scanner's fixed geometry; ranges are filled per scan."""
    msg = LaserScan()
    msg.header.frame_id = frame
    msg.angle_min, msg.angle_max = float(angle_min), float(angle_max)
    msg.angle_increment = float(angle_increment(n_rays, angle_min, angle_max))
    msg.time_increment = 0.0  # every ray of a scan is taken at the same instant
    msg.scan_time = 1.0 / rate_hz if rate_hz > 0 else 0.0
    msg.range_min, msg.range_max = float(range_min), float(range_max)
    return msg


def fill_scan(msg: LaserScan, stamp, ranges: np.ndarray) -> LaserScan:
    """``msg`` stamped ``stamp`` with ``ranges [R]`` (float32; copied as bytes, not value by value)."""
    msg.header.stamp = stamp
    values = array.array("f")
    values.frombytes(np.ascontiguousarray(ranges, dtype=np.float32).tobytes())
    msg.ranges = values
    return msg


def pose_array(frame: str, stamp, poses: np.ndarray) -> PoseArray:
    """A PoseArray in ``frame`` of ``poses [k, 3]`` (x, y, yaw) or ``[k, 2]`` (x, y; yaw 0)."""
    msg = PoseArray()
    msg.header.frame_id, msg.header.stamp = frame, stamp
    for row in poses:
        pose = Pose()
        set_pose(pose, row[0], row[1], row[2] if len(row) > 2 else 0.0)
        msg.poses.append(pose)
    return msg


def goal(frame: str, stamp, x: float, y: float) -> PoseStamped:
    """A PoseStamped in ``frame`` at goal (x, y)."""
    msg = PoseStamped()
    msg.header.frame_id, msg.header.stamp = frame, stamp
    set_pose(msg.pose, x, y, 0.0)
    return msg
