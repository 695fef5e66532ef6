"""sim_node's parameters: names, defaults, meaning and validation in one table.

Validation is a pure function so it is tested without ROS, and so start-up
and runtime changes apply the same rules: a bad value is refused with a reason,
never half-applied.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Dict, List, Optional

import yaml

#: parameters that may change while the node runs; the others need a restart
RUNTIME = {"env_index", "cmd_vel_timeout", "control", "real_time_factor", "rate_hz"}
CONTROL_MODES = ("zero", "heuristic", "policy")
DEVICES = ("cpu", "cuda", "auto")


@dataclass
class SimParams:
    """Defaults of every sim_node parameter (documented in the README)."""

    scenario: str = "simple_spread"
    scenario_kwargs: str = "{}"
    num_envs: int = 1
    env_index: int = 0
    device: str = "cpu"
    seed: int = 0
    rate_hz: float = 0.0
    real_time_factor: float = 1.0
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
    if name == "num_envs" and value < 1:
        return f"num_envs must be >= 1, got {value}"
    if name == "env_index":
        limit = current.num_envs if current is not None else None
        if value < 0 or (limit is not None and value >= limit):
            return f"env_index must be in [0, {limit}), got {value}" if limit else f"env_index must be >= 0, got {value}"
    if name == "device" and not (value in DEVICES or value.startswith("cuda:")):
        return f"device must be one of {', '.join(DEVICES)} or cuda:N, got {value!r}"
    if name in ("rate_hz", "real_time_factor", "cmd_vel_timeout") and value < 0:
        return f"{name} must be >= 0, got {value}"
    if name == "lidar_rays" and value < 1:
        return f"lidar_rays must be >= 1, got {value}"
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
    if name == "record_path" and value and not value.endswith(".mcap"):
        return f"record_path must end in .mcap, got {value!r}"
    if name == "control" and value not in CONTROL_MODES:
        return f"control must be one of {', '.join(CONTROL_MODES)}, got {value!r}"
    if name == "control" and value == "policy" and current is not None and not current.policy_path:
        return "control: policy needs policy_path (an exported policy's .json), set when the node starts"
    if name == "policy_path" and value:
        import os

        if not os.path.isfile(value):
            return f"policy_path must name an existing file (an exported policy's .json), got {value!r}"
    return None


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


@dataclass
class PolicyNodeParams:
    """Defaults of every policy_node parameter (documented in the README)."""

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
        import os

        if not value or not os.path.isfile(value):
            return f"policy_path must name an existing file (an exported policy's .json or .onnx), got {value!r}"
    if name == "output" and value not in POLICY_OUTPUTS:
        return f"output must be one of {', '.join(POLICY_OUTPUTS)}, got {value!r}"
    if name in ("rate_hz", "observation_timeout") and value <= 0:
        return f"{name} must be > 0, got {value}"
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
