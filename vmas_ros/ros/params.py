"""sim_node's parameters: names, defaults, meaning and validation in one table.

Validation is a pure function so it is tested without ROS, and so start-up
and runtime changes apply the same rules: a bad value is refused with a reason,
never half-applied.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple

import yaml

#: parameters that may change while the node runs; the others need a restart
RUNTIME = {"env_index", "cmd_vel_timeout", "control", "real_time_factor", "rate_hz", "unpaced_batch_ms"}
CONTROL_MODES = ("zero", "heuristic", "policy")
DEVICES = ("cpu", "cuda", "auto")
#: upper bounds that catch garbage (1e12 envs, a period rclpy cannot hold in int64 ns) before it runs
MAX_NUM_ENVS = 10_000_000
MAX_LIDAR_RAYS = 4096
MAX_SEED = 2**32 - 1  # numpy's RandomState takes seeds in [0, 2**32)
#: positive rates / time factors live in this range (0 keeps its "off" meaning where documented):
#: rclpy turns 1/rate seconds into int64 nanoseconds, so 1e-12 Hz would overflow and kill the node
MIN_RATE, MAX_RATE = 1e-3, 1e6
#: unpaced_batch_ms above this would leave commands and services waiting for more than a second
MAX_UNPACED_BATCH_MS = 1000.0
#: parameters that name files: read once at start, never changed at runtime by a remote peer
PATH_PARAMETERS = ("record_path", "policy_path")


@dataclass
class SimParams:
    """Defaults of every sim_node parameter (documented in docs/node.md)."""

    scenario: str = "simple_spread"
    scenario_kwargs: str = "{}"
    num_envs: int = 1
    env_index: int = 0
    device: str = "cpu"
    compile_physics: bool = False
    seed: int = 0
    rate_hz: float = 0.0
    real_time_factor: float = 1.0
    unpaced_batch_ms: float = 4.0
    frame_id: str = "world"
    add_lidar: bool = True
    lidar_rays: int = 16
    lidar_range: float = 2.0
    cmd_vel_timeout: float = 0.5
    use_stamped_cmd_vel: bool = False
    control: str = "zero"
    foxglove_port: int = 0
    foxglove_host: str = "127.0.0.1"
    record_path: str = ""
    record_topics: str = ""
    record_max_mb: float = 0.0
    record_max_duration_s: float = 0.0
    policy_path: str = ""

    @staticmethod
    def names() -> List[str]:
        return [f.name for f in fields(SimParams)]

    def kwargs(self) -> Dict[str, Any]:
        """``scenario_kwargs`` parsed (validated beforehand)."""
        return yaml.safe_load(self.scenario_kwargs or "{}") or {}

    def recorded_topics(self) -> Optional[List[str]]:
        """The topics to record (None: everything the node publishes and receives)."""
        names = [t.strip() for t in self.record_topics.split(",") if t.strip()]
        return names or None

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


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def validate(name: str, value: Any, current: Optional[SimParams] = None) -> Optional[str]:
    """Why ``value`` is not acceptable for parameter ``name`` (None when it is)."""
    expected = {f.name: f.type for f in fields(SimParams)}
    if name not in expected:
        return f"unknown parameter {name!r}; known: {', '.join(SimParams.names())}"
    kind = expected[name]
    if kind == "int" and (isinstance(value, bool) or not isinstance(value, int)):
        return f"{name} must be an integer, got {value!r}"
    if kind == "float" and not _is_number(value):
        return f"{name} must be a finite number, got {value!r}"
    if kind == "bool" and not isinstance(value, bool):
        return f"{name} must be true or false, got {value!r}"
    if kind == "str" and not isinstance(value, str):
        return f"{name} must be a string, got {value!r}"
    if name == "scenario":
        from vmas_ros.scenarios import list_scenarios

        if value.removesuffix(".py") not in list_scenarios():
            return f"unknown scenario {value!r}; valid: {', '.join(list_scenarios())}"
    if name == "scenario_kwargs":
        try:
            parsed = yaml.safe_load(value or "{}")
        except yaml.YAMLError as error:
            return f"scenario_kwargs must be a JSON/YAML-flow object like '{{\"n_agents\": 4}}': {error}"
        if not isinstance(parsed, dict):
            return f"scenario_kwargs must be a mapping, got {type(parsed).__name__}"
    if name == "num_envs" and not 1 <= value <= MAX_NUM_ENVS:
        return f"num_envs must be in [1, {MAX_NUM_ENVS}], got {value}"
    if name == "seed" and not 0 <= value <= MAX_SEED:
        return f"seed must be in [0, {MAX_SEED}], got {value}"
    if name == "env_index":
        limit = current.num_envs if current is not None else None
        if value < 0 or (limit is not None and value >= limit):
            return f"env_index must be in [0, {limit}), got {value}" if limit else f"env_index must be >= 0, got {value}"
    if name == "device" and not (value in DEVICES or value.startswith("cuda:")):
        return f"device must be one of {', '.join(DEVICES)} or cuda:N, got {value!r}"
    if name in ("rate_hz", "real_time_factor", "cmd_vel_timeout") and value < 0:
        return f"{name} must be >= 0, got {value}"
    if name in ("rate_hz", "real_time_factor") and value != 0 and not MIN_RATE <= value <= MAX_RATE:
        return f"{name} must be 0 (off) or in [{MIN_RATE:g}, {MAX_RATE:g}], got {value}"
    if name == "unpaced_batch_ms" and not 0 <= value <= MAX_UNPACED_BATCH_MS:
        return f"unpaced_batch_ms must be in [0, {MAX_UNPACED_BATCH_MS:g}] (0: one step per executor round), got {value}"
    if name == "lidar_rays" and not 1 <= value <= MAX_LIDAR_RAYS:
        return f"lidar_rays must be in [1, {MAX_LIDAR_RAYS}], got {value}"
    if name == "lidar_range" and value <= 0:
        return f"lidar_range must be > 0, got {value}"
    if name == "frame_id" and not value:
        return "frame_id must not be empty"
    if name == "foxglove_port" and not 0 <= value <= 65535:
        return f"foxglove_port must be in [0, 65535] (0: off), got {value}"
    if name == "foxglove_host" and not value:
        return "foxglove_host must not be empty (127.0.0.1 keeps the server private to this machine)"
    if name in ("record_max_mb", "record_max_duration_s") and value < 0:
        return f"{name} must be >= 0 (0: no split), got {value}"
    if name == "record_path" and value:
        return _check_record_path(value)
    if name == "control" and value not in CONTROL_MODES:
        return f"control must be one of {', '.join(CONTROL_MODES)}, got {value!r}"
    if name == "control" and value == "policy" and current is not None and not current.policy_path:
        return "control: policy needs policy_path (an exported policy's .json), set when the node starts"
    if name == "policy_path" and value:
        return _check_policy_path(value, "an exported policy's .json")
    return None


def _check_record_path(value: str) -> Optional[str]:
    """Why the bag cannot go to ``value``: the bag and its split parts stay exactly where the user pointed.

    The recorder writes ``value`` and ``<stem>_<n>.mcap`` beside it, creating
    missing parent directories. A symlink at ``value`` (even a dangling one)
    would send the write somewhere else, so it is refused, as is a path whose
    last part is not a ``.mcap`` file name.
    """
    import os

    if "\0" in value:
        return f"record_path must not contain NUL bytes, got {value!r}"
    if not value.endswith(".mcap") or os.path.basename(value) in ("", ".mcap"):
        return f"record_path must be a file name ending in .mcap, got {value!r}"
    if os.path.islink(value):
        return f"record_path {value!r} is a symlink (to {os.readlink(value)!r}); give the real path"
    if os.path.isdir(value):
        return f"record_path {value!r} is a directory; give a file name ending in .mcap"
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


def unknown_parameters(given: Iterable[str], known: Sequence[str], node: str) -> Tuple[List[str], List[str]]:
    """Errors and warnings for parameter overrides the node does not declare.

    A name close to a known one (``num_env``) is a typo: an error, because the
    node would otherwise run silently with the default. Other names only get a
    warning: a shared ``/**`` parameter file may carry values for other nodes.
    A nested key under a known name (``num_envs.a``: a mapping in a parameter
    file) is an error; ``qos_overrides.*`` belongs to rclpy and is left alone.
    """
    import difflib

    errors, warnings = [], []
    for name in sorted(set(given) - set(known)):
        if name.startswith("qos_overrides."):
            continue
        root = name.split(".")[0]
        if root in known:  # a mapping in a parameter file: rcl flattens {num_envs: {a: 1}} to num_envs.a
            errors.append(f"{root} must be a single value, got a nested key {name!r}")
            continue
        if "." in name:
            continue
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
        if close:
            errors.append(f"unknown parameter {name!r} (did you mean {close[0]!r}?)")
        else:
            warnings.append(f"{node} ignores unknown parameter {name!r}; known: {', '.join(known)}")
    return errors, warnings


def resolve_device(device: str) -> str:
    """``auto`` picks cuda when present; asking for cuda without one is an error."""
    import torch

    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(f"device {device!r} requested but torch sees no CUDA device (use cpu or auto)")
    return device


# ---------------------------------------------------------------- policy_node
#: policy_node parameters that may change while it runs; the others need a restart
POLICY_NODE_RUNTIME = {"rate_hz", "observation_timeout", "cmd_vel_scale"}
POLICY_OUTPUTS = ("action", "cmd_vel")
#: a policy runs at most this often (one ONNX call per tick); more is a unit mistake (ms for Hz)
MAX_POLICY_RATE = 1000.0


@dataclass
class PolicyNodeParams:
    """Defaults of every policy_node parameter (documented in docs/policy_node.md)."""

    policy_path: str = ""
    output: str = "action"
    rate_hz: float = 10.0
    observation_timeout: float = 0.5
    adapter: str = ""
    adapter_kwargs: str = "{}"
    cmd_vel_scale: float = 1.0

    @staticmethod
    def names() -> List[str]:
        return [f.name for f in fields(PolicyNodeParams)]

    def kwargs(self) -> Dict[str, Any]:
        """``adapter_kwargs`` parsed (validated beforehand)."""
        return yaml.safe_load(self.adapter_kwargs or "{}") or {}


def validate_policy_node(name: str, value: Any) -> Optional[str]:
    """Why ``value`` is not acceptable for policy_node parameter ``name`` (None when it is)."""
    expected = {f.name: f.type for f in fields(PolicyNodeParams)}
    if name not in expected:
        return f"unknown parameter {name!r}; known: {', '.join(PolicyNodeParams.names())}"
    if expected[name] == "float" and not _is_number(value):
        return f"{name} must be a finite number, got {value!r}"
    if expected[name] == "str" and not isinstance(value, str):
        return f"{name} must be a string, got {value!r}"
    if name == "policy_path":
        if not value:
            return "policy_path must name an existing file (an exported policy's .json or .onnx), got ''"
        return _check_policy_path(value, "an exported policy's .json or .onnx")
    if name == "output" and value not in POLICY_OUTPUTS:
        return f"output must be one of {', '.join(POLICY_OUTPUTS)}, got {value!r}"
    if name in ("rate_hz", "observation_timeout", "cmd_vel_scale") and value <= 0:
        return f"{name} must be > 0, got {value}"
    if name == "rate_hz" and not MIN_RATE <= value <= MAX_POLICY_RATE:
        return f"rate_hz must be in [{MIN_RATE:g}, {MAX_POLICY_RATE:g}], got {value}"
    if name == "adapter" and value and (value.count(":") != 1 or not all(value.split(":"))):
        return f"adapter must be 'package.module:Class' (empty: the agents' observation topics), got {value!r}"
    if name == "adapter_kwargs":
        try:
            parsed = yaml.safe_load(value or "{}")
        except yaml.YAMLError as error:
            return f"adapter_kwargs must be a JSON/YAML-flow object: {error}"
        if not isinstance(parsed, dict):
            return f"adapter_kwargs must be a mapping, got {type(parsed).__name__}"
    return None


# ------------------------------------------------------------------ start-up
def run_checked(name: str, make_node, argv: Optional[List[str]] = None) -> int:
    """``lifecycle.run_node``, with command-line and parameter-file errors refused like bad values.

    ``rclpy.init`` parses ``--ros-args`` itself: a missing, unreadable or
    corrupt ``--params-file`` or a malformed ``-p`` raises ``RCLError`` before
    any node exists. That is a user's input error, so it exits with code 2 and
    rcl's message (which names the file or rule), not a traceback.
    """
    import sys

    from vmas_ros.ros.lifecycle import run_node

    try:
        return run_node(name, make_node, argv)
    except Exception as error:
        text = str(error)
        if type(error).__name__ != "RCLError" or "failed to initialize rcl" not in text:
            raise
        print(f"{name}: refused arguments: {text.split(', at ')[0]}", file=sys.stderr)
        return 2
