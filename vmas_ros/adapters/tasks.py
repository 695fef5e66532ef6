"""The shipped adapters: one per task, each the task's ``observation()`` rebuilt from a robot's messages.

Every adapter takes the agents' names and the policy's observation size
(policy_node passes both), checks that the size fits the task, and reads
``<agent>/odom`` (nav_msgs/Odometry) plus what else the task observes. Topic
names are kwargs with ``{agent}`` for the agent's name. A row that cannot be
built is NaN and ``problems[agent]`` says why (see ``base.ObservationAdapter``).

* :class:`NavigationAdapter` (``navigation``): odometry, scan, goal pose.
* :class:`SimpleSpreadAdapter` (``simple_spread``): odometry of every agent,
  the landmarks' PoseArray.
* :class:`DiffDriveAdapter` (``diff_drive``): odometry only (position and
  velocity), which is also kinematic_bicycle's and drone's observation.
* :class:`GoalAdapter` (``goal``): odometry and the goal pose.
"""
from __future__ import annotations

import numbers
from typing import Any, Dict, List, Mapping, Optional, Sequence, Set

import numpy as np

from vmas_ros.adapters.base import ObservationAdapter, agent_topic
from vmas_ros.adapters.pieces import (
    ScanResampler, lead_problem, margin_problem, pose_array_positions, pose_position, read_odometry,
)

__all__ = ["DiffDriveAdapter", "GoalAdapter", "NavigationAdapter", "SimpleSpreadAdapter"]

ODOM_TOPIC, GOAL_TOPIC, SCAN_TOPIC = "{agent}/odom", "{agent}/goal", "{agent}/scan"
#: navigation's values of the ``dynamics`` kwarg (as the scenario's)
NAVIGATION_DYNAMICS = ("holonomic", "diff_drive")


class _OdometryAdapter(ObservationAdapter):
    """Shared reading: every agent's odometry topic, and its state or the reason it has none."""

    def __init__(self, agents: Sequence[str], observation_size: int, odom_topic: str = ODOM_TOPIC) -> None:
        super().__init__(agents, observation_size)
        self.odom_topics = [agent_topic(odom_topic, a, self.agents, "odom_topic") for a in self.agents]

    def topics(self) -> Dict[str, type]:
        from nav_msgs.msg import Odometry

        return {topic: Odometry for topic in self.odom_topics}

    def _states(self, latest: Mapping[str, Any]) -> List[Optional[np.ndarray]]:
        """Each agent's ``[x, y, yaw, vx, vy, yaw_rate]`` (world frame), None with a problem noted where unusable."""
        states: List[Optional[np.ndarray]] = []
        for agent, topic in zip(self.agents, self.odom_topics):
            state, problem = None, "no message"
            msg = latest.get(topic)
            if msg is not None:
                state, problem = read_odometry(msg)
            if state is None:
                self.note(agent, f"{topic}: {problem}")
            states.append(state)
        return states

    def _goal(self, latest: Mapping[str, Any], agent: str, topic: str) -> Optional[np.ndarray]:
        """The position of the PoseStamped on ``topic``; None with a problem noted for ``agent`` if unusable."""
        msg = latest.get(topic)
        position, problem = (None, "no message") if msg is None else pose_position(msg)
        if position is None:
            self.note(agent, f"{topic}: {problem}")
        return position

    def _size_must_be(self, expected: int, what: str) -> None:
        if self.observation_size != expected:
            raise ValueError(f"{type(self).__name__}: observation_size {self.observation_size} does not fit {what}, "
                             f"which observes {expected} values")


class DiffDriveAdapter(_OdometryAdapter):
    """The debug ``diff_drive`` task's observation: own position (2), own world-frame velocity (2).

    kinematic_bicycle and drone observe the same, so it serves them too.
    Kwargs: ``odom_topic`` (``"{agent}/odom"``).
    """

    def __init__(self, agents: Sequence[str], observation_size: int, odom_topic: str = ODOM_TOPIC) -> None:
        super().__init__(agents, observation_size, odom_topic)
        self._size_must_be(4, "diff_drive (position, velocity)")

    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        obs, self.problems = self.empty(), {}
        for i, state in enumerate(self._states(latest)):
            if state is not None:
                obs[i] = state[[0, 1, 3, 4]]
        return obs


class GoalAdapter(_OdometryAdapter):
    """The debug ``goal`` task's observation: position (2), world-frame velocity (2), position minus goal (2).

    Inputs: ``odom_topic`` (``"{agent}/odom"``) and ``goal_topic``
    (``"{agent}/goal"``, geometry_msgs/PoseStamped in the odometry's frame).
    The task's ``obs_noise`` is training noise: none is added here.
    """

    def __init__(self, agents: Sequence[str], observation_size: int, odom_topic: str = ODOM_TOPIC,
                 goal_topic: str = GOAL_TOPIC) -> None:
        super().__init__(agents, observation_size, odom_topic)
        self._size_must_be(6, "goal (position, velocity, position - goal)")
        self.goal_topics = [agent_topic(goal_topic, a, self.agents, "goal_topic") for a in self.agents]

    def topics(self) -> Dict[str, type]:
        from geometry_msgs.msg import PoseStamped

        return {**super().topics(), **{topic: PoseStamped for topic in self.goal_topics}}

    def standing_topics(self) -> Set[str]:
        """The goals: a planner may send them once."""
        return set(self.goal_topics)

    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        obs, self.problems = self.empty(), {}
        for i, state in enumerate(self._states(latest)):
            goal = self._goal(latest, self.agents[i], self.goal_topics[i])
            if state is not None and goal is not None:
                obs[i] = np.concatenate([state[[0, 1, 3, 4]], state[:2] - goal])
        return obs


class SimpleSpreadAdapter(_OdometryAdapter):
    """simple_spread's observation from odometry and landmark poses.

    Per agent: own position (2), own world-frame velocity (2), every
    landmark's position relative to it (2 each, in ``landmarks`` order) and,
    with ``obs_agents`` (the scenario's default), every other agent's
    relative position (2 each, in agent order). Inputs: ``odom_topic``
    (``"{agent}/odom"``) for every agent and one geometry_msgs/PoseArray of
    the landmarks (``landmarks_topic``, default ``landmarks/poses``; on real
    robots, e.g. goal positions from a planner). With ``obs_agents`` every
    agent's row needs every agent's odometry.
    """

    def __init__(self, agents: Sequence[str], observation_size: int, obs_agents: bool = True,
                 landmarks_topic: str = "landmarks/poses", odom_topic: str = ODOM_TOPIC) -> None:
        super().__init__(agents, observation_size, odom_topic)
        if not isinstance(landmarks_topic, str) or not landmarks_topic:
            raise ValueError(f"landmarks_topic must be a non-empty topic name, got {landmarks_topic!r}")
        self.obs_agents, self.landmarks_topic = bool(obs_agents), landmarks_topic
        n = len(self.agents)
        others = n - 1 if self.obs_agents else 0
        landmark_values = observation_size - 4 - 2 * others
        if landmark_values < 0 or landmark_values % 2:
            raise ValueError(f"SimpleSpreadAdapter: observation_size {observation_size} does not fit simple_spread "
                             f"with {n} agents (4 + 2 x landmarks{' + 2 x (agents - 1)' if self.obs_agents else ''})")
        self.n_landmarks = landmark_values // 2

    @classmethod
    def kwargs_from_training(cls, scenario_kwargs: Mapping[str, Any]) -> Dict[str, Any]:
        """Whether the trained agents observed each other (simple_spread's ``obs_agents``)."""
        return {"obs_agents": scenario_kwargs["obs_agents"]} if "obs_agents" in scenario_kwargs else {}

    def topics(self) -> Dict[str, type]:
        from geometry_msgs.msg import PoseArray

        return {**super().topics(), self.landmarks_topic: PoseArray}

    def standing_topics(self) -> Set[str]:
        """The landmarks: they stand where they were last reported."""
        return {self.landmarks_topic}

    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        obs, self.problems = self.empty(), {}
        msg = latest.get(self.landmarks_topic)
        landmarks, problem = (None, "no message") if msg is None else pose_array_positions(msg, self.n_landmarks)
        states = self._states(latest)
        if landmarks is None:
            for agent in self.agents:
                self.note(agent, f"{self.landmarks_topic}: {problem}")
            return obs
        unseen = [a for a, s in zip(self.agents, states) if s is None]
        for i, state in enumerate(states):
            if state is None:
                continue
            if self.obs_agents and unseen:
                self.note(self.agents[i], f"no odometry of {', '.join(unseen)}, whom it observes")
                continue
            pos = state[:2]
            parts = [pos, state[3:5], (landmarks - pos).ravel()]
            if self.obs_agents:
                parts.append(np.array([s[:2] - pos for j, s in enumerate(states) if j != i]).reshape(-1))
            obs[i] = np.concatenate(parts)
        return obs


class NavigationAdapter(_OdometryAdapter):
    """navigation's observation from odometry, a LaserScan and a goal pose per agent.

    Per agent, as the scenario: position (2), world-frame velocity (2); with
    ``dynamics="diff_drive"`` the heading's (cos, sin) (2); position minus
    its goal (2) or, with ``observe_all_goals``, minus every agent's goal in
    agent order (2 x n_agents); then ``n_lidar_rays`` lidar proximities
    (``lidar_range - distance``, 0 for no return) when the task has
    collisions. The rays come from the scan by :class:`ScanResampler`'s
    rules: body-frame rays for ``diff_drive``; for ``holonomic`` (agents
    that never turn) world-fixed rays, read from the scan at the odometry's
    heading. ``scan_yaw`` is the scanner's yaw on the robot (0: it faces
    forward). The training lidar sees only the other agents: walls or
    furniture in a real scan appear as neighbours to the policy.
    ``scan_margin`` (m, 0: none) is a safety margin, as a costmap's
    inflation radius: every return of the scan is read that much closer
    (clamped at 0; no return stays no return), so the policy keeps that
    much more room from what it sees. ``scan_lead`` (s, 0: none) adds, per
    ray, the distance the robot's odometry velocity closes along that ray in
    that time, so a fast approach reads nearer than a slow one: the room a
    command needs before it takes effect on a robot with latency and lag.

    Kwargs: ``dynamics`` (``"holonomic"``), ``n_lidar_rays`` (default: what
    the observation size leaves; 0 for a task without collisions),
    ``lidar_range`` (0.35, the scenario's default; cannot be told from the
    size), ``observe_all_goals`` (False), ``odom_topic``
    (``"{agent}/odom"``), ``scan_topic`` (``"{agent}/scan"``), ``goal_topic``
    (``"{agent}/goal"``, geometry_msgs/PoseStamped in the odometry's frame),
    ``scan_yaw`` (0.0), ``scan_margin`` (0.0), ``scan_lead`` (0.0). A size
    that does not fit, a margin that is negative, not finite or not below
    ``lidar_range``, or a lead that is negative or not finite, is a
    ValueError.
    """

    def __init__(self, agents: Sequence[str], observation_size: int, dynamics: str = "holonomic",
                 n_lidar_rays: Optional[int] = None, lidar_range: float = 0.35, observe_all_goals: bool = False,
                 odom_topic: str = ODOM_TOPIC, scan_topic: str = SCAN_TOPIC, goal_topic: str = GOAL_TOPIC,
                 scan_yaw: float = 0.0, scan_margin: float = 0.0, scan_lead: float = 0.0) -> None:
        super().__init__(agents, observation_size, odom_topic)
        if dynamics not in NAVIGATION_DYNAMICS:
            raise ValueError(f"dynamics must be one of {', '.join(NAVIGATION_DYNAMICS)}, got {dynamics!r}")
        if not isinstance(observe_all_goals, bool):
            raise ValueError(f"observe_all_goals must be True or False, got {observe_all_goals!r}")
        self.dynamics, self.observe_all_goals = dynamics, observe_all_goals
        n_goals = len(self.agents) if observe_all_goals else 1
        self.fixed = 4 + (2 if dynamics == "diff_drive" else 0) + 2 * n_goals  # values before the lidar
        heading = " + 2 (heading)" if dynamics == "diff_drive" else ""
        layout = f"4 (position, velocity){heading} + {2 * n_goals} (goals) + lidar rays"
        rays = observation_size - self.fixed
        if n_lidar_rays is None:
            if rays < 0:
                raise ValueError(f"NavigationAdapter: observation_size {observation_size} is too small for navigation "
                                 f"with dynamics={dynamics!r}, observe_all_goals={observe_all_goals}: {layout}")
            n_lidar_rays = rays
        elif isinstance(n_lidar_rays, bool) or not isinstance(n_lidar_rays, int) or n_lidar_rays < 0:
            raise ValueError(f"n_lidar_rays must be an int >= 0, got {n_lidar_rays!r}")
        elif n_lidar_rays != rays:
            raise ValueError(f"NavigationAdapter: observation_size {observation_size} does not fit navigation with "
                             f"dynamics={dynamics!r}, observe_all_goals={observe_all_goals}, "
                             f"n_lidar_rays={n_lidar_rays}: {layout} = {self.fixed + n_lidar_rays}")
        if isinstance(lidar_range, bool) or not isinstance(lidar_range, numbers.Real) or not 0 < lidar_range < np.inf:
            raise ValueError(f"lidar_range must be a finite number > 0, got {lidar_range!r}")
        problem = margin_problem(scan_margin, float(lidar_range), "scan_margin") or lead_problem(scan_lead, "scan_lead")
        if problem:
            raise ValueError(problem)
        self.n_lidar_rays, self.scan_margin, self.scan_lead = n_lidar_rays, float(scan_margin), float(scan_lead)
        self.resampler = None
        if n_lidar_rays:
            frame = "body" if dynamics == "diff_drive" else "world"
            self.resampler = ScanResampler(n_lidar_rays, float(lidar_range), frame=frame, mount_yaw=scan_yaw,
                                           margin=self.scan_margin, lead=self.scan_lead)
        self.goal_topics = [agent_topic(goal_topic, a, self.agents, "goal_topic") for a in self.agents]
        self.scan_topics = [agent_topic(scan_topic, a, self.agents, "scan_topic") for a in self.agents]

    @classmethod
    def kwargs_from_training(cls, scenario_kwargs: Mapping[str, Any]) -> Dict[str, Any]:
        """The training's dynamics, lidar and goal layout (navigation's kwargs, when the policy names them)."""
        found = {k: scenario_kwargs[k] for k in ("dynamics", "lidar_range", "observe_all_goals", "n_lidar_rays")
                 if k in scenario_kwargs}
        if scenario_kwargs.get("collisions") is False:
            found["n_lidar_rays"] = 0  # no lidar in the observation
        return found

    def topics(self) -> Dict[str, type]:
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import LaserScan

        found = {**super().topics(), **{topic: PoseStamped for topic in self.goal_topics}}
        if self.resampler is not None:
            found.update({topic: LaserScan for topic in self.scan_topics})
        return found

    def standing_topics(self) -> Set[str]:
        """The goals: a planner may send them once."""
        return set(self.goal_topics)

    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        obs, self.problems = self.empty(), {}
        states = self._states(latest)
        goals = [self._goal(latest, a, t) for a, t in zip(self.agents, self.goal_topics)]
        missing_goals = [a for a, g in zip(self.agents, goals) if g is None]
        for i, (agent, state) in enumerate(zip(self.agents, states)):
            if self.observe_all_goals and missing_goals and goals[i] is not None:
                self.note(agent, f"no goal of {', '.join(missing_goals)}, which it observes")
            rays = self._rays(latest, i, state)
            if agent in self.problems:  # every missing or unusable input noted one
                continue
            pos = state[:2]
            parts = [pos, state[3:5]]
            if self.dynamics == "diff_drive":
                parts.append(np.array([np.cos(state[2]), np.sin(state[2])]))
            parts.append((pos - np.stack(goals)).ravel() if self.observe_all_goals else pos - goals[i])
            if rays is not None:
                parts.append(rays)
            obs[i] = np.concatenate(parts)
        return obs

    def _rays(self, latest: Mapping[str, Any], i: int, state: Optional[np.ndarray]) -> Optional[np.ndarray]:
        """Agent ``i``'s lidar readings (None without a lidar, or with a problem noted)."""
        if self.resampler is None:
            return None
        topic = self.scan_topics[i]
        scan = latest.get(topic)
        if scan is None:
            self.note(self.agents[i], f"{topic}: no message")
            return None
        if state is None and self.resampler.frame == "world":  # the heading is needed; the odometry's problem says why
            return None
        if state is None:
            rays, problem = self.resampler.resample(scan)
        else:
            rays, problem = self.resampler.resample(scan, float(state[2]), state[3:5])
        if rays is None:
            self.note(self.agents[i], f"{topic}: {problem}")
        return rays
