"""Observation adapters: how ``policy_node`` turns ROS messages into a policy's observation.

A trained policy expects the exact vector the scenario's ``observation()``
built in training. In simulation, sim_node publishes that vector on
``<agent>/observation`` (``TopicObservations``, the default). A real robot
has no such topic: it has odometry, scans and goal poses. An adapter rebuilds
the training observation from those standard messages, so the same exported
policy runs on hardware.

The hook (select one with ``-p adapter:=package.module:Class``)::

    class MyAdapter(ObservationAdapter):
        def __init__(self, agents, observation_size, **adapter_kwargs): ...
        def topics(self) -> Dict[str, type]:       # topic -> message class to subscribe
            return {f"{a}/odom": Odometry for a in self.agents}
        def build(self, latest) -> np.ndarray:     # [n_agents, observation_size]
            ...

``latest`` maps each topic to its newest message that is not older than
``observation_timeout``; stale and missing topics are absent. A row the
adapter cannot build (a message it needs is absent) is NaN: policy_node does
not act for that agent and warns. Relative topic names follow the node's
namespace (``--ros-args -r __ns:=/robot1``).
"""
from __future__ import annotations

import abc
import importlib
import math
from typing import Any, Dict, Mapping, Sequence

import numpy as np


class ObservationAdapter(abc.ABC):
    """Base of observation adapters: the agents' names and the policy's observation size."""

    def __init__(self, agents: Sequence[str], observation_size: int, **kwargs: Any) -> None:
        if kwargs:
            raise ValueError(f"{type(self).__name__} takes no adapter_kwargs, got {sorted(kwargs)}")
        self.agents = list(agents)
        self.observation_size = int(observation_size)

    @abc.abstractmethod
    def topics(self) -> Dict[str, type]:
        """Topic name -> message class of every topic ``build`` reads."""

    @abc.abstractmethod
    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        """The observations [n_agents, observation_size]; NaN rows where inputs are missing."""

    def empty(self) -> np.ndarray:
        return np.full((len(self.agents), self.observation_size), np.nan, dtype=np.float32)


class TopicObservations(ObservationAdapter):
    """The default: each agent's ``<agent>/observation`` (sim_node publishes it), used as is."""

    def topics(self) -> Dict[str, type]:
        from std_msgs.msg import Float32MultiArray

        return {f"{agent}/observation": Float32MultiArray for agent in self.agents}

    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        obs = self.empty()
        for i, agent in enumerate(self.agents):
            msg = latest.get(f"{agent}/observation")
            if msg is not None and len(msg.data) == self.observation_size:
                obs[i] = np.frombuffer(msg.data, dtype=np.float32)
        return obs


def odometry_state(msg) -> np.ndarray:
    """[x, y, vx, vy, yaw] in the world frame from nav_msgs/Odometry (whose twist is in the body frame)."""
    p, q, v = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist.linear
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([p.x, p.y, c * v.x - s * v.y, s * v.x + c * v.y, yaw])


class SimpleSpreadAdapter(ObservationAdapter):
    """simple_spread's observation from odometry and landmark poses.

    Per agent: own position (2), own world-frame velocity (2), every landmark's
    position relative to it (2 each, in ``landmarks`` order) and, with
    ``obs_agents`` (the scenario's default), every other agent's relative
    position (2 each, in agent order). Inputs: ``<agent>/odom``
    (nav_msgs/Odometry) for every agent and one geometry_msgs/PoseArray of
    the landmarks (``landmarks_topic``, default ``landmarks/poses``; on real
    robots, e.g. goal positions from a planner).
    """

    def __init__(self, agents: Sequence[str], observation_size: int, obs_agents: bool = True,
                 landmarks_topic: str = "landmarks/poses") -> None:
        super().__init__(agents, observation_size)
        self.obs_agents, self.landmarks_topic = bool(obs_agents), landmarks_topic
        n = len(self.agents)
        others = n - 1 if self.obs_agents else 0
        landmark_values = observation_size - 4 - 2 * others
        if landmark_values < 0 or landmark_values % 2:
            raise ValueError(f"SimpleSpreadAdapter: observation_size {observation_size} does not fit simple_spread "
                             f"with {n} agents (4 + 2 x landmarks{' + 2 x (agents - 1)' if self.obs_agents else ''})")
        self.n_landmarks = landmark_values // 2

    def topics(self) -> Dict[str, type]:
        from geometry_msgs.msg import PoseArray
        from nav_msgs.msg import Odometry

        found: Dict[str, type] = {f"{agent}/odom": Odometry for agent in self.agents}
        found[self.landmarks_topic] = PoseArray
        return found

    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        obs = self.empty()
        landmarks_msg = latest.get(self.landmarks_topic)
        if landmarks_msg is None or len(landmarks_msg.poses) != self.n_landmarks:
            return obs
        landmarks = np.array([[p.position.x, p.position.y] for p in landmarks_msg.poses]).reshape(-1, 2)
        states = [latest.get(f"{agent}/odom") for agent in self.agents]
        states = [odometry_state(m) if m is not None else None for m in states]
        for i, state in enumerate(states):
            if state is None or (self.obs_agents and any(s is None for s in states)):
                continue
            pos = state[:2]
            parts = [pos, state[2:4], (landmarks - pos).ravel()]
            if self.obs_agents:
                parts.append(np.array([s[:2] - pos for j, s in enumerate(states) if j != i]).reshape(-1))
            obs[i] = np.concatenate(parts)
        return obs


def load_adapter(spec: str, agents: Sequence[str], observation_size: int,
                 kwargs: Dict[str, Any]) -> ObservationAdapter:
    """The adapter named by ``package.module:Class`` (empty: ``TopicObservations``), constructed.

    Raises ValueError with the reason, so policy_node can refuse to start.
    """
    if not spec:
        return TopicObservations(agents, observation_size, **kwargs)
    module_name, _, class_name = spec.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as error:
        raise ValueError(f"cannot import adapter {spec!r}: {error}") from None
    try:
        adapter = cls(agents, observation_size, **kwargs)
    except (TypeError, ValueError) as error:
        raise ValueError(f"adapter {spec!r} refused its arguments: {error}") from None
    if not callable(getattr(adapter, "topics", None)) or not callable(getattr(adapter, "build", None)):
        raise ValueError(f"adapter {spec!r} must have topics() and build(latest) (see vmas_ros.ros.adapters)")
    return adapter
