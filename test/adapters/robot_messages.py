"""What a robot would publish for one env of an Environment: Odometry, a dense LaserScan, goal poses.

The scan is a 360-ray lidar of a real robot's kind (1 degree apart, 3.5 m),
cast by the engine from the same state, so an adapter's training rays can be
compared with the Environment's own observation.
"""
from __future__ import annotations

import math
from typing import Dict, List, Optional

import numpy as np
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan

from vmas_ros.ros import convert
from vmas_ros.simulator import env_snapshot
from vmas_ros.simulator.core import Agent
from vmas_ros.simulator.sensors import Lidar

SCAN_RAYS, SCAN_RANGE = 360, 3.5


def names(env) -> List[str]:
    """The agents' ROS names, as sim_node and policy_node give them."""
    return env_snapshot.unique_names([a.name for a in env.agents])


def odometry(agent, index: int, yaw: Optional[float] = None) -> Odometry:
    """The agent's Odometry in env ``index``: pose in the world, twist in the body (``yaw``: a heading
    other than the engine's, for a robot turned where the trained agent never turns)."""
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = "world", f"{agent.name}/base_link"
    x, y = agent.state.pos[index].tolist()
    vx, vy = agent.state.vel[index].tolist()
    heading = float(agent.state.rot[index, 0]) if yaw is None else yaw
    convert.fill_odometry(msg, x, y, heading, vx, vy, float(agent.state.ang_vel[index, 0]))
    return msg


def goal_pose(entity, index: int) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = "world"
    convert.set_pose(msg.pose, *entity.state.pos[index].tolist(), 0.0)
    return msg


def pose_array(entities, index: int) -> PoseArray:
    msg = PoseArray()
    for entity in entities:
        pose = Pose()
        convert.set_pose(pose, *entity.state.pos[index].tolist(), 0.0)
        msg.poses.append(pose)
    return msg


def scan_message(angle_min: float, increment: float, ranges, range_min: float = 0.0,
                 range_max: float = SCAN_RANGE) -> LaserScan:
    """A LaserScan with rays ``angle_min + i * increment``; ``ranges`` as given (inf, NaN and all)."""
    msg = LaserScan()
    msg.angle_min, msg.angle_increment = float(angle_min), float(increment)
    msg.angle_max = float(angle_min + (len(ranges) - 1) * increment)
    msg.range_min, msg.range_max = float(range_min), float(range_max)
    msg.ranges = [float(r) for r in ranges]
    return msg


def dense_scan(env, agent, index: int, world_offset: float = 0.0) -> LaserScan:
    """The 360-ray scan ``agent`` would see in env ``index``, rays from -pi in its frame, seeing agents only.

    ``world_offset``: how far the robot's body is turned beyond the engine's heading (a robot facing
    anywhere while the trained agent never turns): the rays are cast that much further round.
    """
    lidar = Lidar(env.world, angle_start=-math.pi + world_offset, angle_end=math.pi + world_offset,
                  n_rays=SCAN_RAYS, max_range=SCAN_RANGE, entity_filter=lambda e: isinstance(e, Agent))
    lidar.agent = agent
    ranges = lidar.cast_alone()[index].cpu().numpy()
    increment = 2 * math.pi / SCAN_RAYS
    msg = LaserScan()
    msg.header.frame_id = f"{agent.name}/base_link"
    geometry = env_snapshot.ScanGeometry(-math.pi, -math.pi + (SCAN_RAYS - 1) * increment, increment, SCAN_RANGE)
    convert.fill_scan(msg, geometry, ranges)
    return msg


def robot_messages(env, index: int, yaws: Optional[List[float]] = None) -> Dict[str, object]:
    """Every agent's ``<agent>/odom`` for env ``index``, its ``<agent>/scan`` where it has a lidar in
    training, and its ``<agent>/goal`` where it has a ``goal`` landmark. ``yaws``: each robot's heading,
    when it is not the engine's (see :func:`dense_scan`)."""
    latest: Dict[str, object] = {}
    for k, (name, agent) in enumerate(zip(names(env), env.agents)):
        yaw = None if yaws is None else yaws[k]
        latest[f"{name}/odom"] = odometry(agent, index, yaw)
        if any(isinstance(sensor, Lidar) for sensor in agent.sensors):
            offset = 0.0 if yaw is None else yaw - float(agent.state.rot[index, 0])
            latest[f"{name}/scan"] = dense_scan(env, agent, index, offset)
        if getattr(agent, "goal", None) is not None:
            latest[f"{name}/goal"] = goal_pose(agent.goal, index)
    return latest


def expected(obs, index: int) -> np.ndarray:
    """The Environment's observations of env ``index``, one row per agent."""
    return np.stack([o[index].cpu().numpy() for o in obs])
