"""Tiny exported policies for the policy tests: a linear map, exported with torch.onnx plus its JSON.

``action = clip(observation @ weight + bias, low, high)`` per agent makes the
expected motion easy to state: a zero weight with bias (0.5, 0) pushes every
agent along +x; ``seek_landmark(...)`` steers each agent to landmark 0 in
simple_spread (whose observation holds that landmark's relative position at
columns 4:6).
"""
from __future__ import annotations

import hashlib
import json
import warnings
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np
import torch


class LinearPolicy(torch.nn.Module):
    """[B, A, obs] -> [B, A, act]: one shared affine map, clipped to the action bounds."""

    def __init__(self, weight: np.ndarray, bias: np.ndarray, low: float, high: float) -> None:
        super().__init__()
        self.weight = torch.nn.Parameter(torch.as_tensor(weight, dtype=torch.float32), requires_grad=False)
        self.bias = torch.nn.Parameter(torch.as_tensor(bias, dtype=torch.float32), requires_grad=False)
        self.low, self.high = float(low), float(high)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return torch.clamp(observation @ self.weight + self.bias, self.low, self.high)


def write_policy(directory: Path, stem: str, weight: np.ndarray, bias: Sequence[float],
                 agents: Sequence[str] = ("agent_0", "agent_1", "agent_2"), scenario: str = "simple_spread",
                 scenario_kwargs: Optional[Dict] = None, low: float = -1.0, high: float = 1.0,
                 metadata: Optional[Dict] = None) -> Path:
    """Export ``LinearPolicy`` to ``<directory>/<stem>.onnx`` + ``.json``; return the JSON's path.

    ``metadata`` overrides JSON keys after the fact (to build mismatched policies).
    """
    directory.mkdir(parents=True, exist_ok=True)
    weight = np.asarray(weight, dtype=np.float32)
    obs_size, act_size = weight.shape
    onnx_path = directory / f"{stem}.onnx"
    example = torch.zeros(2, len(agents), obs_size)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice
        torch.onnx.export(LinearPolicy(weight, np.asarray(bias), low, high), (example,), str(onnx_path),
                          input_names=["observation"], output_names=["action"],
                          dynamic_axes={"observation": {0: "batch"}, "action": {0: "batch"}}, dynamo=False)
    meta = {
        "format": "vmas_ros.policy", "version": 1, "scenario": scenario,
        "scenario_kwargs": scenario_kwargs or {}, "algorithm": "linear-test",
        "agents": list(agents), "observation_size": obs_size, "action_size": act_size,
        "action_low": [low] * act_size, "action_high": [high] * act_size, "action_type": "continuous",
        "onnx_file": onnx_path.name, "onnx_sha256": hashlib.sha256(onnx_path.read_bytes()).hexdigest(),
        "created_by": "test/ros/policy_files.py",
    }
    meta.update(metadata or {})
    json_path = directory / f"{stem}.json"
    json_path.write_text(json.dumps(meta, indent=1))
    return json_path


def constant_push(directory: Path, stem: str, action: Sequence[float], obs_size: int = 14, **kwargs) -> Path:
    """A policy whose action is ``action`` whatever it observes."""
    return write_policy(directory, stem, np.zeros((obs_size, len(action))), action, **kwargs)


def seek_landmark(directory: Path, stem: str, gain: float = 2.0, obs_size: int = 14, **kwargs) -> Path:
    """simple_spread: ``gain * (landmark 0 - own position) - own velocity``, clipped to [-1, 1]."""
    weight = np.zeros((obs_size, 2))
    weight[4, 0] = weight[5, 1] = gain  # landmark 0's relative position
    weight[2, 0] = weight[3, 1] = -1.0  # damping on the own velocity
    return write_policy(directory, stem, weight, [0.0, 0.0], **kwargs)
