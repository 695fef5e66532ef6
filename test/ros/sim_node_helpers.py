"""Shared pieces of the sim_node process tests (test_sim_node*.py): the scenario, seeds and helpers.

The engine itself is the reference: scans and layouts are recomputed
in-process with ``vmas_ros.make_env`` and compared with what the node published.
"""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import PoseArray
from nav_msgs.msg import Odometry
from std_srvs.srv import SetBool

import vmas_ros
from test.ros.conftest import NODE, stamp_ns

SCENARIO = "simple_spread"
DT = float(vmas_ros.make_env(SCENARIO, num_envs=1).world.dt)  # 0.1 s
DT_NS = int(round(DT * 1e9))
AGENTS = ["agent_0", "agent_1", "agent_2"]

SPREAD_SEED = 5  # agents apart (no contact) and 5 of the 36 rays hit another agent
LIDAR_RAYS, LIDAR_RANGE = 12, 2.0
BATCH_SEED = 2  # no two agents touch in any of the 4 envs: a zero-control layout stays put
HEURISTIC_SEED = 1  # the layout after one reset is far from covered (sum of distances 2.7 m)


# ------------------------------------------------------------------- helpers
def yaw_of(orientation) -> float:
    return 2.0 * math.atan2(orientation.z, orientation.w)


def xy(pose) -> np.ndarray:
    return np.array([pose.position.x, pose.position.y])


def positions(array: PoseArray) -> np.ndarray:
    return np.array([[p.position.x, p.position.y] for p in array.poses])


def coverage(agents: np.ndarray, landmarks: np.ndarray) -> float:
    """Sum over landmarks of the distance to the closest agent (simple_spread's coverage)."""
    return float(np.linalg.norm(landmarks[:, None, :] - agents[None, :, :], axis=-1).min(axis=1).sum())


def engine(seed: int, num_envs: int = 1, resets: int = 1, **kwargs):
    """The env the node builds (make_env, then reset), plus ``resets - 1`` further resets."""
    env = vmas_ros.make_env(SCENARIO, num_envs=num_envs, seed=seed, **kwargs)
    for _ in range(resets):
        env.reset()
    return env


def layout(env, index: int):
    agents = np.array([a.state.pos[index].tolist() for a in env.world.agents])
    landmarks = np.array([lm.state.pos[index].tolist() for lm in env.world.landmarks])
    return agents, landmarks


def angle_between(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2 * math.pi))


def speed(odom: Odometry) -> float:
    return math.hypot(odom.twist.twist.linear.x, odom.twist.twist.linear.y)


def pause(ros, on: bool):
    response = ros.call(SetBool, f"{NODE}/pause", SetBool.Request(data=on))
    assert response.success, response.message
    return response


def max_clock(clock) -> int:
    return max((stamp_ns(m.clock) for m in clock.messages), default=-1)
