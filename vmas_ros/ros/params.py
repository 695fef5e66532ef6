"""sim_node's and policy_node's parameters, each declared once in a :class:`ParamTable`.

The tables give the nodes their typed values (``SimParams``,
``PolicyNodeParams``), their validation (a pure function, tested without
ROS, the same at start-up and for runtime changes: a bad value is refused
with a reason, never half-applied), their ROS parameter descriptors and
their ``--help`` (see :mod:`vmas_ros.ros.param_table`).
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional

import yaml

from vmas_ros.simulator.thresholds import DEFAULT_COMPILE_MAX_ENVS
from vmas_ros.ros.param_table import Param, ParamTable
from vmas_ros.ros.policy_commands import ACTION_KINDS, BASES
from vmas_ros.rostools.graph import frame_prefix_error

CONTROL_MODES = ("zero", "heuristic", "policy")
RECORD_ON_ERROR = ("continue", "stop")
PER_AGENT_TOPICS = ("auto", "on", "off")
#: per_agent_topics: auto gives every agent its own topics up to this many agents; a swarm beyond
#: would put thousands of endpoints into DDS discovery, so its agents go out in aggregated topics
PER_AGENT_TOPICS_MAX_AGENTS = 100
DEVICES = ("cpu", "cuda", "auto")
#: upper bounds that catch garbage (1e12 envs, a period rclpy cannot hold in int64 ns) before it runs
MAX_NUM_ENVS = 10_000_000
MAX_LIDAR_RAYS = 4096
#: a lidar spans at most a full circle (plus the rounding a YAML-written 2 pi may carry)
FULL_CIRCLE = 2 * math.pi
CIRCLE_SLACK = 1e-5
MAX_SEED = 2**32 - 1  # numpy's RandomState takes seeds in [0, 2**32)
#: positive rates / time factors live in this range (0 keeps its "off" meaning where documented):
#: rclpy turns 1/rate seconds into int64 nanoseconds, so 1e-12 Hz would overflow and kill the node
MIN_RATE, MAX_RATE = 1e-3, 1e6
#: unpaced_batch_ms above this would leave commands and services waiting for more than a second
MAX_UNPACED_BATCH_MS = 1000.0
#: parameters that name files: read once at start, never changed at runtime by a remote peer
PATH_PARAMETERS = ("record_path", "policy_path")


# ------------------------------------------------------------------ rules
def _scenario(value: str, current) -> Optional[str]:
    from vmas_ros.scenarios import list_scenarios, unknown_scenario

    return None if value.removesuffix(".py") in list_scenarios() else unknown_scenario(value)


def _mapping(name: str, example: str):
    def check(value: str, current) -> Optional[str]:
        try:
            parsed = yaml.safe_load(value or "{}")
        except yaml.YAMLError as error:
            return f"{name} must be a JSON/YAML-flow object like {example}: {error}"
        if not isinstance(parsed, dict):
            return f"{name} must be a mapping, got {type(parsed).__name__}"
        return None
    return check


def _env_index(value: int, current) -> Optional[str]:
    limit = current.num_envs if current is not None else None
    if value < 0 or (limit is not None and value >= limit):
        return f"env_index must be in [0, {limit}), got {value}" if limit else f"env_index must be >= 0, got {value}"
    return None


def _device(value: str, current) -> Optional[str]:
    if value in DEVICES or value.startswith("cuda:"):
        return None
    return f"device must be one of {', '.join(DEVICES)} or cuda:N, got {value!r}"


def _not_empty(name: str, why: str = ""):
    return lambda value, current: None if value else f"{name} must not be empty{why}"


def _lidar_angle_max(value: float, current) -> Optional[str]:
    if current is None:  # checked again against lidar_angle_min once every value is read
        return None
    low = current.lidar_angle_min
    if not value > low:
        return f"lidar_angle_max must be greater than lidar_angle_min, got {value} <= {low}"
    if value - low > FULL_CIRCLE + CIRCLE_SLACK:
        return (f"lidar_angle_max - lidar_angle_min must be at most 2 pi ({FULL_CIRCLE:.6f}) radians, got "
                f"{value} - {low} = {value - low:g} (radians, not degrees)")
    return None


def _lidar_range_min(value: float, current) -> Optional[str]:
    if current is not None and value >= current.lidar_range:
        return f"lidar_range_min must be less than lidar_range ({current.lidar_range}), got {value}"
    return None


def _control(value: str, current) -> Optional[str]:
    if value == "policy" and current is not None and not current.policy_path:
        return "control: policy needs policy_path (an exported policy's .json), set when the node starts"
    return None


def _record_path(value: str, current) -> Optional[str]:
    return _check_record_path(value) if value else None


def _sim_policy_path(value: str, current) -> Optional[str]:
    return _check_policy_path(value, "an exported policy's .json") if value else None


def _policy_node_policy_path(value: str, current) -> Optional[str]:
    if not value:
        return "policy_path must name an existing file (an exported policy's .json or .onnx), got ''"
    return _check_policy_path(value, "an exported policy's .json or .onnx")


def _adapter(value: str, current) -> Optional[str]:
    from vmas_ros.adapters import ADAPTER_NAMES

    if not value or value in ADAPTER_NAMES:
        return None
    if value.count(":") != 1 or not all(value.split(":")):
        return (f"adapter must be one of {', '.join(sorted(ADAPTER_NAMES))}, 'package.module:Class', or empty "
                f"(the agents' observation topics), got {value!r}")
    return None


def _check_record_path(value: str) -> Optional[str]:
    """Why the bag cannot go to ``value``: the bag and its split parts stay exactly where the user pointed.

    ``NAME.mcap`` is a single file (split parts ``NAME_<n>.mcap`` beside it),
    any other name a rosbag2 bag folder; missing parent directories are
    created. A symlink at ``value`` (even a dangling one) would send the write
    somewhere else, so it is refused. Whether a bag is already there is the
    recorder's to say (see ``record_overwrite``).
    """
    import os

    if "\0" in value:
        return f"record_path must not contain NUL bytes, got {value!r}"
    if os.path.basename(value.rstrip("/")) in ("", ".", "..", ".mcap"):
        return f"record_path must name a file NAME.mcap or a bag folder NAME, got {value!r}"
    if os.path.islink(value.rstrip("/")):
        return f"record_path {value!r} is a symlink (to {os.readlink(value.rstrip('/'))!r}); give the real path"
    if value.endswith(".mcap") and os.path.isdir(value):
        return f"record_path {value!r} is a directory; name a bag folder without .mcap, or a new .mcap file"
    if not value.endswith(".mcap") and os.path.isfile(value.rstrip("/")):
        return f"record_path {value!r} is a file; a bag folder needs a name that is free or a folder"
    return None


def _check_policy_path(value: str, what: str) -> Optional[str]:
    """Why ``value`` is no usable policy file name: an existing regular file ending in .json or .onnx."""
    import os

    if "\0" in value:
        return f"policy_path must not contain NUL bytes, got {value!r}"
    if not value.endswith((".json", ".onnx")):
        return f"policy_path must end in .json or .onnx ({what}), got {value!r}"
    if not os.path.isfile(value):
        return f"policy_path must name an existing file ({what}), got {value!r}"
    if not os.access(value, os.R_OK):
        return f"policy_path {value!r} is not readable by this user"
    return None


# ---------------------------------------------------------------- sim_node
SIM_PARAMS = ParamTable("sim_node", [
    Param("scenario", "simple_spread", "scenario name (vmas-ros list)", check=_scenario),
    Param("scenario_kwargs", "{}", "JSON or YAML-flow mapping of scenario kwargs, e.g. '{n_agents: 4}'",
          check=_mapping("scenario_kwargs", "'{\"n_agents\": 4}'")),
    Param("num_envs", 1, "environments stepped in parallel", minimum=1, maximum=MAX_NUM_ENVS),
    Param("env_index", 0, "the env that is published and commanded", runtime=True, check=_env_index),
    Param("device", "cpu", "torch device: cpu, cuda, cuda:N or auto", check=_device),
    Param("compile_physics", "auto", "torch.compile the step: auto compiles in the background while stepping "
          f"eagerly (where a C++ compiler works, up to {DEFAULT_COMPILE_MAX_ENVS:,} envs); true compiles on the first "
          "step; false: eager",
          choices=("auto", "true", "false")),
    Param("seed", 0, "environment seed", minimum=0, maximum=MAX_SEED),
    Param("rate_hz", 0.0, "steps per wall-clock second; 0: paced by real_time_factor", runtime=True,
          minimum=MIN_RATE, maximum=MAX_RATE, zero_is_off=True),
    Param("real_time_factor", 1.0, "simulated seconds per wall second; 0: as fast as possible", runtime=True,
          minimum=MIN_RATE, maximum=MAX_RATE, zero_is_off=True),
    Param("unpaced_batch_ms", 4.0, "unpaced only: wall milliseconds of steps per executor round", runtime=True,
          minimum=0.0, maximum=MAX_UNPACED_BATCH_MS, note="(0: one step per executor round)"),
    Param("frame_id", "world", "world frame of poses, odometry and markers", check=_not_empty("frame_id")),
    Param("frame_prefix", "auto", "put before every frame name (world and <agent>/base_link); "
          "auto: the node's namespace, e.g. 'swarm_a/' under /swarm_a, nothing at the root", check=lambda value, current: frame_prefix_error(value)),
    Param("publish_clock", True, "publish /clock; false when another node of the graph owns the clock "
          "(a recording keeps this node's own)"),
    Param("add_lidar", True, "give every agent without a lidar one, so ROS consumers always get scans"),
    Param("robot_lidar", False, "give every agent that lidar, even one the scenario gave lidars of its own: "
          "published as <agent>/scan, the scenario's as <agent>/scan_1, ..."),
    Param("lidar_rays", 16, "rays of that lidar, evenly from lidar_angle_min to lidar_angle_max",
          minimum=1, maximum=MAX_LIDAR_RAYS),
    Param("lidar_range", 2.0, "range of that lidar (LaserScan range_max), m", minimum=0.0, strict=True),
    Param("lidar_range_min", 0.0, "readings of that lidar closer than this are published as -inf (REP 117), m",
          minimum=0.0, note="(0: none)", check=_lidar_range_min),
    Param("lidar_angle_min", 0.0, "angle of that lidar's first ray, rad, body frame (0: ahead, counter-clockwise)",
          minimum=-FULL_CIRCLE, maximum=FULL_CIRCLE),
    Param("lidar_angle_max", FULL_CIRCLE, "angle of its last ray, rad; a span of 2 pi is a full circle whose "
          "rays do not repeat the first", minimum=-FULL_CIRCLE, maximum=FULL_CIRCLE, check=_lidar_angle_max),
    Param("cmd_vel_timeout", 0.5, "seconds after which an agent's last command is dropped", runtime=True,
          minimum=0.0),
    Param("per_agent_topics", "auto", "each agent's own pose, odom, scan, observation, reward, action and cmd_vel "
          "topics and /tf: on, off, or auto (on up to 100 agents); off publishes lidar/points instead",
          choices=PER_AGENT_TOPICS),
    Param("cmd_vel_agents", "", "comma-separated agents that take <agent>/cmd_vel even with per_agent_topics off"),
    Param("use_stamped_cmd_vel", False, "subscribe geometry_msgs/TwistStamped instead of Twist"),
    Param("control", "zero", "what drives agents with no live command (policy needs policy_path)", runtime=True,
          choices=CONTROL_MODES, check=_control),
    Param("foxglove_port", 0, "port of the live Foxglove WebSocket server", minimum=0, maximum=65535,
          note="(0: off)"),
    Param("foxglove_host", "127.0.0.1", "address the Foxglove server listens on",
          check=_not_empty("foxglove_host", " (127.0.0.1 keeps the server private to this machine)")),
    Param("record_path", "", "record everything published and received: NAME.mcap (one MCAP file) or NAME "
          "(a rosbag2 bag folder); empty: off", check=_record_path),
    Param("record_overwrite", False, "replace an existing bag at record_path (a folder only if it holds nothing "
          "but a bag)"),
    Param("record_on_error", "continue", "when writing the bag fails (disk full, read-only, vanished): continue "
          "without recording, or stop the node with exit code 4", choices=RECORD_ON_ERROR),
    Param("record_topics", "", "comma-separated topics to record; empty: all"),
    Param("record_max_mb", 0.0, "split the bag past this size", minimum=0.0, note="(0: no split)"),
    Param("record_max_duration_s", 0.0, "split the bag past this span of simulated time", minimum=0.0,
          note="(0: no split)"),
    Param("policy_path", "", "exported policy (.json or .onnx) loaded at start for control: policy",
          check=_sim_policy_path),
], doc="docs/node.md#parameters")

#: parameters that may change while the node runs; the others need a restart
RUNTIME = SIM_PARAMS.runtime()


def _parsed_mapping(text: str) -> Dict[str, Any]:
    """A mapping parameter's value parsed (it was validated by ``_mapping`` beforehand)."""
    return yaml.safe_load(text or "{}") or {}


class _SimValues:
    """What sim_node derives from its parameter values."""

    def kwargs(self) -> Dict[str, Any]:
        """``scenario_kwargs`` parsed."""
        return _parsed_mapping(self.scenario_kwargs)

    def recorded_topics(self) -> Optional[List[str]]:
        """The topics to record (None: everything the node publishes and receives)."""
        names = [t.strip() for t in self.record_topics.split(",") if t.strip()]
        return names or None

    def per_agent(self, n_agents: int) -> bool:
        """Whether every agent gets topics of its own (``per_agent_topics``)."""
        if self.per_agent_topics == "auto":
            return n_agents <= PER_AGENT_TOPICS_MAX_AGENTS
        return self.per_agent_topics == "on"

    def compile_mode(self) -> str:
        """``compile_physics`` as ``auto``, ``true`` or ``false`` (a bool from ``compile_physics:=true`` too)."""
        return str(self.compile_physics).lower()

    def cmd_vel_names(self) -> List[str]:
        """``cmd_vel_agents`` as a list of names."""
        return [n.strip() for n in self.cmd_vel_agents.split(",") if n.strip()]

    def step_period(self, dt: float) -> float:
        """Wall-clock seconds between steps; 0 means as fast as possible.

        ``rate_hz > 0`` wins; otherwise ``real_time_factor`` paces simulated time
        against wall time (1.0: real time; 0: unpaced).
        """
        if self.rate_hz > 0:
            return 1.0 / self.rate_hz
        if self.real_time_factor > 0:
            return dt / self.real_time_factor
        return 0.0


#: the values of every sim_node parameter (defaults: the table's)
SimParams = SIM_PARAMS.values_class("SimParams", _SimValues)


def validate(name: str, value: Any, current=None) -> Optional[str]:
    """Why ``value`` is not acceptable for sim_node parameter ``name`` (None when it is)."""
    return SIM_PARAMS.validate(name, value, current)


def resolve_device(device: str) -> str:
    """``auto`` picks cuda when present; asking for cuda without one is an error."""
    import torch

    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(f"device {device!r} requested but torch sees no CUDA device (use cpu or auto)")
    return device


# ---------------------------------------------------------------- policy_node
POLICY_OUTPUTS = ("action", "cmd_vel")
#: when policy_node acts: on its own timer, or when new scans arrive (vmas_ros.ros.policy_trigger)
ACT_ON = ("timer", "scan")
#: a policy runs at most this often (one ONNX call per tick); more is a unit mistake (ms for Hz)
MAX_POLICY_RATE = 1000.0


def _agent_template(name: str):
    def check(value: str, current) -> Optional[str]:
        if "{agent}" not in value:
            return f"{name} must contain {{agent}} (each agent's name goes there), got {value!r}"
        return None
    return check


POLICY_PARAMS = ParamTable("policy_node", [
    Param("policy_path", "", "exported policy: the .json or the .onnx of the pair; must exist",
          check=_policy_node_policy_path),
    Param("output", "action", "action: <agent>/action; cmd_vel: <agent>/cmd_vel velocity commands in the body frame",
          choices=POLICY_OUTPUTS),
    Param("use_stamped_cmd_vel", False, "output: cmd_vel publishes geometry_msgs/TwistStamped (what Jazzy's "
          "diff_drive_controller takes) instead of Twist"),
    Param("cmd_vel_frame_id", "{agent}/base_link", "header.frame_id of TwistStamped commands ({agent}: the agent's "
          "name)", check=_agent_template("cmd_vel_frame_id")),
    Param("action_kind", "auto", "what the policy's action means: world_velocity (rotated into the body frame by "
          "the odometry's heading), body_velocity, speed_turn (linear.x, angular.z); auto: speed_turn for policies "
          "trained with dynamics: diff_drive, else world_velocity", choices=ACTION_KINDS),
    Param("base", "holonomic", "the robots' drive: holonomic (linear.x, linear.y, angular.z) or diff_drive "
          "(linear.x, angular.z; a velocity is tracked with a point lookahead ahead of the wheel axis)",
          choices=BASES),
    Param("lookahead", 0.15, "diff_drive base: metres ahead of the wheel axis of the point that follows a "
          "velocity action", runtime=True, minimum=0.0, strict=True),
    Param("odom_topic", "{agent}/odom", "nav_msgs/Odometry of each robot, for its heading ({agent}: the agent's "
          "name)", check=_agent_template("odom_topic")),
    Param("max_linear_speed", 0.0, "limit on the length of (linear.x, linear.y), m/s", runtime=True, minimum=0.0,
          note="(0: none)"),
    Param("max_angular_speed", 0.0, "limit on |angular.z|, rad/s", runtime=True, minimum=0.0, note="(0: none)"),
    Param("max_linear_accel", 0.0, "limit on the change of (linear.x, linear.y) per second, m/s^2", runtime=True,
          minimum=0.0, note="(0: none)"),
    Param("max_angular_accel", 0.0, "limit on the change of angular.z per second, rad/s^2", runtime=True,
          minimum=0.0, note="(0: none)"),
    Param("rate_hz", 10.0, "policy steps per second; act_on: scan: the longest wait, 1 / rate_hz, after a set's "
          "first new scan", runtime=True, minimum=MIN_RATE, maximum=MAX_POLICY_RATE),
    Param("act_on", "timer", "timer: act at rate_hz; scan: act once every scanning robot has a new scan (the "
          "adapter's sensor_msgs/LaserScan topics), or 1 / rate_hz after the first new one", choices=ACT_ON),
    Param("observation_timeout", 0.5, "seconds after which an input message is too old to act on", runtime=True,
          minimum=0.0, strict=True),
    Param("adapter", "", "observation adapter: navigation, simple_spread, diff_drive, goal or package.module:Class; "
          "empty: each agent's <agent>/observation", check=_adapter),
    Param("adapter_kwargs", "{}", "JSON or YAML-flow mapping passed to the adapter",
          check=_mapping("adapter_kwargs", "'{\"scale\": 2}'")),
    Param("cmd_vel_scale", 1.0, "multiplies every command of output: cmd_vel (metres per second per action unit "
          "of a velocity action)", runtime=True, minimum=0.0, strict=True),
], doc="docs/policy_node.md#parameters")

#: policy_node parameters that may change while it runs; the others need a restart
POLICY_NODE_RUNTIME = POLICY_PARAMS.runtime()


class _PolicyValues:
    """What policy_node derives from its parameter values."""

    def kwargs(self) -> Dict[str, Any]:
        """``adapter_kwargs`` parsed."""
        return _parsed_mapping(self.adapter_kwargs)


#: the values of every policy_node parameter (defaults: the table's)
PolicyNodeParams = POLICY_PARAMS.values_class("PolicyNodeParams", _PolicyValues)


def validate_policy_node(name: str, value: Any) -> Optional[str]:
    """Why ``value`` is not acceptable for policy_node parameter ``name`` (None when it is)."""
    return POLICY_PARAMS.validate(name, value)


# ------------------------------------------------------------------ start-up
def asks_for_help(argv: Optional[List[str]]) -> bool:
    """Whether a node's command line asks for ``-h``/``--help`` (before any ``--ros-args``)."""
    import sys

    args = list(sys.argv if argv is None else argv)[1:]
    own = args[:args.index("--ros-args")] if "--ros-args" in args else args
    return "-h" in own or "--help" in own


def node_help(table: ParamTable, usage: str) -> str:
    """A node's ``--help``: how to start it, then every parameter from its table."""
    return f"usage: {usage}\n\n{table.help()}\n"


def run_checked(name: str, make_node, argv: Optional[List[str]] = None, table: Optional[ParamTable] = None) -> int:
    """``lifecycle.run_node``, with command-line and parameter-file errors refused like bad values.

    With ``-h``/``--help`` it prints the node's parameters (from ``table``) and
    returns 0 before rclpy starts.

    ``rclpy.init`` parses ``--ros-args`` itself: a missing, unreadable or
    corrupt ``--params-file`` or a malformed ``-p`` raises ``RCLError`` before
    any node exists. That is a user's input error, so it exits with code 2 and
    rcl's message (which names the file or rule), not a traceback.
    """
    import sys

    from vmas_ros.ros.lifecycle import run_node

    if table is not None and asks_for_help(argv):
        print(node_help(table, f"{name} [--help] [--ros-args -p name:=value ... | --params-file FILE]"), end="")
        return 0
    try:
        return run_node(name, make_node, argv)
    except Exception as error:
        text = str(error)
        if type(error).__name__ != "RCLError" or "failed to initialize rcl" not in text:
            raise
        print(f"{name}: refused arguments: {text.split(', at ')[0]}", file=sys.stderr)
        return 2
