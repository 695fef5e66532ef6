"""Export a trained policy as ``<stem>.onnx`` + ``<stem>.json`` (the contract ``OnnxPolicy`` reads).

The ONNX graph computes the *deterministic* action (TanhNormal's transformed
mean, clipped to the action bounds) from ``"observation"`` float32
``[batch, n_agents, obs_size]`` to ``"action"`` float32 ``[batch, n_agents,
action_size]``, batch dynamic. The JSON metadata names the scenario, the agents
in env order, sizes and bounds, and pins the ONNX file by SHA-256, so the ROS
node can refuse a policy that does not fit the world it runs in.
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any, Dict, Optional, Tuple, Union

import torch
from torch import nn

from vmas_ros.envs.randomisation import Randomisation
from vmas_ros.policy.onnx_policy import POLICY_FORMAT, POLICY_VERSION, sha256_of_file, validate_metadata
from vmas_ros.train.algorithms import ALGORITHMS
from vmas_ros.train.checkpoint import load_checkpoint
from vmas_ros.train.models import build_actor_network, deterministic_action

__all__ = ["describe_env", "export_policy", "export_checkpoint", "DeterministicPolicy"]


def describe_env(env) -> Dict[str, Any]:
    """Agent names, shared observation/action sizes and per-agent bounds of a continuous Environment.

    Raises ``ValueError`` when agents differ in observation or action size: one
    exported graph takes one ``[batch, n_agents, obs]`` tensor.
    """
    agents = [agent.name for agent in env.agents]
    if not agents:
        raise ValueError("the scenario has no policy agents to export a policy for")
    if not env.continuous_actions:
        raise ValueError("only continuous-action policies can be exported (action_type 'continuous')")
    obs_sizes = []
    for name, space in zip(agents, env.observation_space):
        shape = getattr(space, "shape", None)
        if shape is None or len(shape) != 1:
            raise ValueError(f"agent {name!r} has a non-flat observation space {space}; export needs flat vectors")
        obs_sizes.append(int(shape[0]))
    act_sizes = [env.get_agent_action_size(agent) for agent in env.agents]
    for what, sizes in (("observation", obs_sizes), ("action", act_sizes)):
        if len(set(sizes)) != 1:
            detail = ", ".join(f"{n}={s}" for n, s in zip(agents, sizes))
            raise ValueError(f"cannot export a policy for agents with different {what} sizes ({detail}); "
                             f"the export format needs one {what} size shared by all agents")
    lows, highs = zip(*(env._action_bounds(agent) for agent in env.agents))
    return {"agents": agents, "observation_size": obs_sizes[0], "action_size": act_sizes[0],
            "action_low": [low.tolist() for low in lows], "action_high": [high.tolist() for high in highs]}


def _shared_bounds(env_info: Dict[str, Any]) -> Tuple[list, list]:
    """The one ``[action_size]`` bound pair the metadata holds; refuse agents with different bounds."""
    low, high = env_info["action_low"], env_info["action_high"]
    if any(row != low[0] for row in low) or any(row != high[0] for row in high):
        raise ValueError(f"cannot export: agents have different action bounds (low {low}, high {high}); "
                         "the export format has one [action_low, action_high] for all agents")
    return [float(v) for v in low[0]], [float(v) for v in high[0]]


class DeterministicPolicy(nn.Module):
    """``observation [B, n, obs] -> action [B, n, act]``: the graph that is exported."""

    def __init__(self, actor_network: nn.Module, low: torch.Tensor, high: torch.Tensor) -> None:
        super().__init__()
        self.actor_network = actor_network
        self.register_buffer("low", low.detach().clone().float())
        self.register_buffer("high", high.detach().clone().float())

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return deterministic_action(self.actor_network, observation, self.low, self.high)


def export_policy(actor_network: nn.Module, env_info: Dict[str, Any], scenario: str,
                  scenario_kwargs: Dict[str, Any], algorithm: str, out_stem: Union[str, Path],
                  randomisation: Optional[Dict[str, Any]] = None) -> Tuple[Path, Path]:
    """Write ``<out_stem>.onnx`` and ``<out_stem>.json``; returns both paths.

    ``env_info`` is :func:`describe_env`'s dict. The graph is traced on CPU in
    float32, whatever device the network trained on. ``randomisation``: what
    it trained with (``vmas_ros.envs.randomisation``), recorded in the JSON as
    every setting's ``[low, high]`` (all off when None).
    """
    from vmas_ros.compat.version import __version__

    out_stem = Path(out_stem)
    if out_stem.suffix in (".onnx", ".json"):
        out_stem = out_stem.with_suffix("")
    out_stem.parent.mkdir(parents=True, exist_ok=True)
    onnx_path, json_path = out_stem.parent / (out_stem.name + ".onnx"), out_stem.parent / (out_stem.name + ".json")
    low, high = _shared_bounds(env_info)
    n_agents, obs_size = len(env_info["agents"]), env_info["observation_size"]
    network = _cpu_copy(actor_network)
    module = DeterministicPolicy(network, torch.tensor(low), torch.tensor(high)).eval()
    example = torch.zeros(2, n_agents, obs_size)
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")  # the TorchScript-based exporter announces its deprecation
        torch.onnx.export(module, (example,), str(onnx_path), input_names=["observation"], output_names=["action"],
                          dynamic_axes={"observation": {0: "batch"}, "action": {0: "batch"}}, dynamo=False,
                          opset_version=17)
    _check_onnx_matches(module, onnx_path, n_agents, obs_size)
    meta = {
        "format": POLICY_FORMAT,
        "version": POLICY_VERSION,
        "scenario": scenario,
        "scenario_kwargs": dict(scenario_kwargs),
        "algorithm": algorithm,
        "randomisation": Randomisation.from_dict(randomisation).to_dict(),
        "agents": list(env_info["agents"]),
        "observation_size": int(obs_size),
        "action_size": int(env_info["action_size"]),
        "action_low": low,
        "action_high": high,
        "action_type": "continuous",
        "onnx_file": onnx_path.name,
        "onnx_sha256": sha256_of_file(onnx_path),
        "created_by": f"vmas_ros {__version__}",
    }
    validate_metadata(meta, source="export")
    json_path.write_text(json.dumps(meta, indent=2) + "\n")
    return onnx_path, json_path


def _check_onnx_matches(module: nn.Module, onnx_path: Path, n_agents: int, obs_size: int) -> None:
    """Run the written graph on a random batch and compare with torch: a broken export fails here, not on a robot."""
    import numpy as np
    import onnxruntime as ort

    observation = torch.randn(5, n_agents, obs_size, generator=torch.Generator().manual_seed(0)) * 3
    with torch.no_grad():
        expected = module(observation).numpy()
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    (actual,) = session.run(["action"], {"observation": observation.numpy()})
    if actual.shape != expected.shape or not np.allclose(actual, expected, atol=1e-5):
        raise RuntimeError(f"{onnx_path}: the exported graph disagrees with the torch policy "
                           f"(max difference {np.abs(actual - expected).max() if actual.shape == expected.shape else 'shape'})")


def _cpu_copy(network: nn.Module) -> nn.Module:
    """A float32 CPU copy to trace, leaving the training network where it is."""
    import copy

    return copy.deepcopy(network).to("cpu").float()


def export_checkpoint(checkpoint: Union[str, Path], out_stem: Union[str, Path]) -> Tuple[Path, Path]:
    """Rebuild the actor from a training checkpoint (file or run directory) and export it."""
    state = load_checkpoint(checkpoint)
    config, env_info = state["config"], state["env_info"]
    algorithm = config["algorithm"]
    if algorithm not in ALGORITHMS:
        raise ValueError(f"checkpoint has unknown algorithm {algorithm!r}; expected one of {sorted(ALGORITHMS)}")
    network = build_actor_network(ALGORITHMS[algorithm], len(env_info["agents"]), env_info["observation_size"],
                                  env_info["action_size"], config["depth"], config["num_cells"], torch.device("cpu"))
    network.load_state_dict(state["actor"])
    return export_policy(network, env_info, config["scenario"], config["scenario_kwargs"], algorithm, out_stem,
                         randomisation=config.get("randomisation"))
