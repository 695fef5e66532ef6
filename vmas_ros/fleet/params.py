"""robot_fleet's parameters, declared once in a :class:`ParamTable` (types, defaults, ranges, help, docs).

Names follow Jazzy's diff_drive_controller where it has the same notion
(``cmd_vel_timeout``, ``odom_frame``, speed and acceleration limits with 0
meaning "no limit" for the accelerations), so a launch file written for real
robots reads the same. Every parameter is start-only: the summary of an
evaluation states one set of noise, latency and lag values for the whole run.
"""
from __future__ import annotations

import math
import os
import re
from typing import List, Optional

import yaml

from vmas_ros.ros.param_table import Param, ParamTable

__all__ = ["FLEET_PARAMS", "FleetParams", "CROSS_CHECKED", "DRIVES", "MAX_ROBOTS", "MAX_RAYS"]

DRIVES = ("holonomic", "diff_drive")
#: every robot has topics of its own: beyond this many, DDS discovery alone would swamp a machine
MAX_ROBOTS = 1000
MAX_RAYS = 4096
MAX_SEED = 2**32 - 1
#: rclpy turns 1/rate seconds into int64 nanoseconds; rates outside this range are unit mistakes
MIN_RATE, MAX_RATE = 1e-2, 1e4
#: a robot name is one ROS name token: it becomes the first part of its topics and frames
NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


# ------------------------------------------------------------------ rules
def names_in(value: str) -> List[str]:
    """``robot_names`` split at commas, blanks dropped."""
    return [name.strip() for name in value.split(",") if name.strip()]


def _robot_names(value: str, current) -> Optional[str]:
    names = names_in(value)
    bad = [name for name in names if not NAME.fullmatch(name)]
    if bad:
        return (f"robot_names: {bad[0]!r} is not a ROS name token: expected a letter, then letters, digits "
                f"or '_' (e.g. 'robot_a,robot_b')")
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        return f"robot_names must be unique, {', '.join(repeated)} repeats"
    if names and current is not None and len(names) != current.n_robots:
        return (f"robot_names names {len(names)} robots but n_robots is {current.n_robots}: set n_robots:="
                f"{len(names)} too, or leave robot_names empty for agent_0..agent_{current.n_robots - 1}")
    return None


def _above(name: str, low: str):
    """A check that ``name`` is above parameter ``low`` (once all values are known)."""
    def check(value: float, current) -> Optional[str]:
        floor = getattr(current, low, None) if current is not None else None
        if floor is not None and value <= floor:
            return f"{name} must be above {low} ({floor:g}), got {value:g}"
        return None
    return check


def _arena(name: str):
    def check(value: float, current) -> Optional[str]:
        if value and current is not None and value <= current.robot_radius:
            return (f"{name} must be 0 (no walls) or more than robot_radius ({current.robot_radius:g}) so that "
                    f"a robot fits, got {value:g}")
        return None
    return check


def _episodes_file(value: str, current) -> Optional[str]:
    if not value:
        return None
    if not value.endswith((".yaml", ".yml", ".json")):
        return f"episodes_file must be a .yaml, .yml or .json file, got {value!r}"
    if not os.path.isfile(value):
        return f"episodes_file must name an existing file, got {value!r}"
    if not os.access(value, os.R_OK):
        return f"episodes_file {value!r} is not readable by this user"
    return None


def _start_poses(value: str, current) -> Optional[str]:
    if not value:
        return None
    try:
        parsed = yaml.safe_load(value)
    except yaml.YAMLError as error:
        return f"start_poses must be a YAML/JSON mapping like '{{robots: [[0, 0, 0]], goals: [[1, 0]]}}': {error}"
    if not isinstance(parsed, dict):
        return (f"start_poses must be a mapping like '{{robots: [[0, 0, 0]], goals: [[1, 0]]}}', "
                f"got {type(parsed).__name__}")
    if current is not None and current.episodes_file:
        return "start_poses and episodes_file are both set: give one (start_poses is one quick episode)"
    return None


def _summary_path(value: str, current) -> Optional[str]:
    if "\0" in value:
        return f"summary_path must not contain NUL bytes, got {value!r}"
    if value and (value.endswith("/") or os.path.isdir(value)):
        return f"summary_path must name a file (the JSON summary), got the directory {value!r}"
    return None


def _not_empty(name: str):
    return lambda value, current: None if value.strip() else f"{name} must not be empty"


def _topic(value: str, current) -> Optional[str]:
    if not value or value.endswith("/") or "//" in value or not all(c.isalnum() or c in "_/~" for c in value):
        return f"goals_topic must be a topic name like 'landmarks/poses', got {value!r}"
    return None


# ---------------------------------------------------------------- the table
FLEET_PARAMS = ParamTable("robot_fleet", [
    # the fleet
    Param("n_robots", 3, "number of robots", minimum=1, maximum=MAX_ROBOTS),
    Param("robot_names", "", "comma-separated robot names, n_robots of them; empty: agent_0..agent_<n-1> "
          "(sim_node's agent names)", check=_robot_names),
    Param("robot_radius", 0.1, "radius of every robot's disc, m", minimum=0.0, strict=True),
    Param("arena_half_x", 0.0, "walls at x = +-arena_half_x, m", minimum=0.0, note="(0: no walls on x)",
          check=_arena("arena_half_x")),
    Param("arena_half_y", 0.0, "walls at y = +-arena_half_y, m", minimum=0.0, note="(0: no walls on y)",
          check=_arena("arena_half_y")),
    # commands and motion
    Param("drive", "holonomic", "holonomic tracks linear.x, linear.y and angular.z; diff_drive tracks linear.x "
          "and angular.z (linear.y ignored)", choices=DRIVES),
    Param("use_stamped_cmd_vel", True, "subscribe <robot>/cmd_vel as geometry_msgs/TwistStamped (Jazzy's "
          "diff_drive_controller); false: geometry_msgs/Twist"),
    Param("rate_hz", 100.0, "integration steps per wall-clock second", minimum=1.0, maximum=MAX_RATE),
    Param("cmd_vel_timeout", 0.5, "seconds after which a robot's last command is dropped (target: zero velocity)",
          minimum=0.0, strict=True),
    Param("command_latency", 0.0, "seconds between a command's arrival and its effect", minimum=0.0, maximum=10.0),
    Param("velocity_lag", 0.0, "time constant of the first-order lag of the velocity behind the command, s",
          minimum=0.0, maximum=100.0, note="(0: none)"),
    Param("max_linear_speed", 1.0, "limit of the linear speed, m/s (of |(vx, vy)| for holonomic)",
          minimum=0.0, strict=True),
    Param("max_angular_speed", 2.0, "limit of |angular.z|, rad/s", minimum=0.0, strict=True),
    Param("max_linear_accel", 0.0, "limit of the linear acceleration, m/s^2", minimum=0.0,
          note="(0: unlimited)"),
    Param("max_angular_accel", 0.0, "limit of the angular acceleration, rad/s^2", minimum=0.0,
          note="(0: unlimited)"),
    # odometry
    Param("odom_frame", "odom", "frame of every robot's odometry pose, goals and pose arrays (shared by all)",
          check=_not_empty("odom_frame")),
    Param("odom_rate_hz", 50.0, "odometry (and agents/poses) messages per second", minimum=MIN_RATE,
          maximum=MAX_RATE),
    Param("odom_noise_position", 0.0, "sigma of Gaussian noise on the published x and y, m", minimum=0.0),
    Param("odom_noise_yaw", 0.0, "sigma of Gaussian noise on the published yaw, rad", minimum=0.0),
    Param("odom_noise_velocity", 0.0, "sigma of Gaussian noise on the published linear velocity, m/s",
          minimum=0.0),
    # the laser scanner
    Param("scan_rays", 360, "rays per scan", minimum=1, maximum=MAX_RAYS),
    Param("scan_angle_min", -math.pi, "angle of the first ray in the body frame, rad", minimum=-2 * math.pi,
          maximum=2 * math.pi),
    Param("scan_angle_max", math.pi - 2 * math.pi / 360, "angle of the last ray, rad (pi - 2 pi / scan_rays: "
          "a full circle)", minimum=-2 * math.pi, maximum=2 * math.pi,
          check=_above("scan_angle_max", "scan_angle_min")),
    Param("scan_range_min", 0.12, "closer hits read -inf (REP 117), m", minimum=0.0),
    Param("scan_range_max", 3.5, "rays hitting nothing within it read +inf (REP 117), m", minimum=0.0, strict=True,
          check=_above("scan_range_max", "scan_range_min")),
    Param("scan_rate_hz", 10.0, "scans per second (0: no scans)", minimum=MIN_RATE, maximum=MAX_RATE,
          zero_is_off=True),
    Param("scan_noise", 0.0, "sigma of Gaussian noise on each range, m", minimum=0.0),
    Param("scan_dropout", 0.0, "probability that a ray reads NaN", minimum=0.0, maximum=1.0),
    Param("seed", 0, "seed of the odometry and scan noise", minimum=0, maximum=MAX_SEED),
    # episodes and evaluation
    Param("episodes_file", "", "YAML or JSON file of episodes (start poses and goals); empty: one episode from "
          "start_poses, or robots side by side", check=_episodes_file),
    Param("start_poses", "", "one episode as a YAML/JSON mapping '{robots: [[x, y, yaw], ...], goals: "
          "[[x, y], ...]}'", check=_start_poses),
    Param("episode_seconds", 0.0, "length of an episode, s", minimum=0.0, note="(0: until ~/reset)"),
    Param("exit_after_last", True, "exit with code 0 after the last episode; false: start again from the first"),
    Param("wait_for_commands", False, "hold the robots and the first episode's clock until every robot's cmd_vel "
          "has a publisher (an evaluation then starts when its controller is up)"),
    Param("end_on_goals", False, "end an episode once every robot stands within goal_radius of its own goal at "
          "once (navigation's done; only with one goal per robot)"),
    Param("goal_radius", 0.1, "a robot whose centre is this close to its goal has reached it, m", minimum=0.0,
          strict=True),
    Param("goals_topic", "landmarks/poses", "PoseArray of every goal (sim_node's landmark topic)", check=_topic),
    Param("summary_path", "", "JSON file of per-episode metrics, rewritten after every episode and at exit; "
          "empty: none", check=_summary_path),
], doc="docs/fleet.md#parameters")

#: parameters checked again once every value is known (they depend on others)
CROSS_CHECKED = ("robot_names", "scan_angle_max", "scan_range_max", "arena_half_x", "arena_half_y",
                 "start_poses")


class _FleetValues:
    """What robot_fleet derives from its parameter values."""

    def names_list(self) -> List[str]:
        """The robots' names, ``agent_0``... unless ``robot_names`` gives them."""
        return names_in(self.robot_names) or [f"agent_{i}" for i in range(self.n_robots)]

    def as_dict(self) -> dict:
        """Every parameter by name, in the table's order (for the summary file)."""
        return {name: getattr(self, name) for name in self.names()}


#: the values of every robot_fleet parameter (defaults: the table's)
FleetParams = FLEET_PARAMS.values_class("FleetParams", _FleetValues)
