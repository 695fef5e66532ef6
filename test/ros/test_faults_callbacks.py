"""A crashing scenario or policy stops sim_node with a clear message (exit 3), a finished bag and no garbage.

Five real sim_node processes run at once, each in its own namespace, each
with one injected fault (test/ros/faulty_sim.py for the scenario ones):

* the scenario raises in ``post_step`` at step 40;
* the scenario's dynamics turn agent_1's position into NaN at step 40;
* the scenario's rewards become NaN at step 40 (the state stays finite);
* an ONNX policy (``control: policy``) starts returning NaN once agent 0
  moves faster than 0.3 m/s along x (a few steps in);
* an ONNX policy whose graph cannot run on the node's batch (onnxruntime
  raises at the first step).

Each must exit with code 3 and a last stderr line saying which step failed
in which part and why; nothing non-finite may reach a subscriber or the bag;
the bag must be finished (rosbags reads it all) and end with the last good
step.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np
import pytest
import torch
from geometry_msgs.msg import PoseArray
from nav_msgs.msg import Odometry
from std_msgs.msg import Float32

from test.ros.fault_tools import FaultProcess, assert_whole_steps, read_finished, sweep

pytestmark = pytest.mark.ros

DT_NS = 100_000_000
FAULT_STEP = 40
EXIT_FAULT = 3
AGENTS = ("agent_0", "agent_1", "agent_2")


# ------------------------------------------------------------- broken policies
class NanWhenFast(torch.nn.Module):
    """Pushes every agent along +x; once agent 0's x velocity (observation column 0) passes
    0.3 m/s, every action is NaN (sqrt of a negative number): a policy that breaks mid-run."""

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        push = torch.zeros_like(observation[..., :2]) + torch.tensor([1.0, 0.0])
        gate = torch.sqrt(0.3 - observation[:, :1, :1]) * 0.0  # [B, 1, 1]: NaN for all once agent 0 is fast
        return push + gate


class FixedBatch(torch.nn.Module):
    """Reshapes to a batch of 2 whatever it gets: onnxruntime raises for the node's batch of 1."""

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return observation[..., :2].reshape(2, 3, 2) * 0.0


def export_policy(module: torch.nn.Module, directory: Path, stem: str, obs_size: int = 14) -> Path:
    """``<stem>.onnx`` + ``<stem>.json`` in the exported-policy format sim_node loads (for simple_spread)."""
    onnx_path = directory / f"{stem}.onnx"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(module, (torch.zeros(2, len(AGENTS), obs_size),), str(onnx_path),
                          input_names=["observation"], output_names=["action"],
                          dynamic_axes={"observation": {0: "batch"}, "action": {0: "batch"}}, dynamo=False)
    meta = {
        "format": "vmas_ros.policy", "version": 1, "scenario": "simple_spread", "scenario_kwargs": {},
        "algorithm": "fault-test", "agents": list(AGENTS), "observation_size": obs_size, "action_size": 2,
        "action_low": [-1.0, -1.0], "action_high": [1.0, 1.0], "action_type": "continuous",
        "onnx_file": onnx_path.name, "onnx_sha256": hashlib.sha256(onnx_path.read_bytes()).hexdigest(),
        "created_by": "test/ros/test_faults_callbacks.py",
    }
    json_path = directory / f"{stem}.json"
    json_path.write_text(json.dumps(meta))
    return json_path


# ------------------------------------------------------------------- the runs
@dataclass
class Case:
    label: str
    params: Dict[str, object]
    module: str
    expect: List[str]  # in the last stderr line
    last_step: Optional[int]  # steps recorded (0..last_step); None: not known in advance
    process: Optional[FaultProcess] = None
    bag: Optional[Path] = None
    returncode: Optional[int] = None
    received: Dict[str, list] = field(default_factory=dict)


def _scenario_case(fault: str, expect: List[str]) -> Case:
    return Case(f"scenario_{fault}", dict(scenario="faulty_spread", real_time_factor=1.0,
                                          scenario_kwargs={"fault": fault, "fault_step": FAULT_STEP}),
                "test.ros.faulty_sim", [f"step {FAULT_STEP} (t=4.000 s) failed in", *expect], FAULT_STEP - 1)


@pytest.fixture(scope="module")
def bag_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fault_callback_bags")


@pytest.fixture(scope="module")
def fault_runs(ros, bag_dir, sim_log_dir, tmp_path_factory) -> Dict[str, Case]:
    policies = tmp_path_factory.mktemp("broken_policies")
    cases = [
        _scenario_case("raise", ["the scenario 'faulty_spread' (Environment.step)",
                                 "RuntimeError: faulty_spread: injected failure at step 40",
                                 "nothing of this step was published or recorded"]),
        _scenario_case("nan_state", ["the state scenario 'faulty_spread' produced",
                                     "non-finite state in env 0: agent_1",
                                     "no non-finite value was published"]),
        _scenario_case("nan_reward", ["NaN in the observations or rewards of env 0",
                                      "agent_0/reward, agent_1/reward, agent_2/reward",
                                      "no non-finite value was published"]),
        Case("policy_nan", dict(control="policy", real_time_factor=1.0,
                                policy_path=str(export_policy(NanWhenFast(), policies, "nan_when_fast"))),
             "vmas_ros.ros.sim_node", ["computing the actions (control: policy, policy ",
                                       "the policy returned NaN actions for agent(s) 0, 1, 2 in 1 of 1 envs",
                                       "nothing of this step was published or recorded"], None),
        Case("policy_raises", dict(control="policy", real_time_factor=1.0,
                                   policy_path=str(export_policy(FixedBatch(), policies, "fixed_batch"))),
             "vmas_ros.ros.sim_node", ["step 1 (t=0.100 s) failed in computing the actions (control: policy",
                                       "Fail", "nothing of this step was published or recorded"], 0),
    ]
    collectors = {}
    for case in cases:
        ns = f"/{case.label}"
        collectors[case.label] = {
            "poses": ros.collect(PoseArray, f"{ns}/agents/poses"),
            "odom": ros.collect(Odometry, f"{ns}/agent_1/odom"),
            "reward": ros.collect(Float32, f"{ns}/agent_0/reward"),
        }
        case.bag = bag_dir / f"{case.label}.mcap"
        params = dict(case.params, record_path=str(case.bag))
        case.process = FaultProcess(ros, params, sim_log_dir, case.label, module=case.module)
    end = time.monotonic() + 90.0
    while any(c.process.alive() for c in cases) and time.monotonic() < end:
        ros.spin_for(0.05)
    ros.spin_for(0.3)  # the last messages in flight
    for case in cases:
        try:
            case.returncode = case.process.wait(1.0)
        finally:
            case.process.kill()
        case.received = {name: list(c.messages) for name, c in collectors[case.label].items()}
        for collector in collectors[case.label].values():
            collector.destroy()
    return {case.label: case for case in cases}


LABELS = ["scenario_raise", "scenario_nan_state", "scenario_nan_reward", "policy_nan", "policy_raises"]


@pytest.mark.parametrize("label", LABELS)
def test_fault_stops_the_node_with_a_clear_message(fault_runs, label):
    case = fault_runs[label]
    info = case.process.describe()
    assert case.returncode == EXIT_FAULT, info
    lines = [line for line in case.process.stderr().splitlines() if line.startswith("sim_node: ")]
    assert len(lines) == 2 and lines[0].startswith("sim_node: stopped: step "), info
    for part in case.expect:
        assert part in lines[0], f"{part!r} not in {lines[0]!r}"
    assert lines[1] == f"sim_node: the bag {case.bag} is closed and readable", info


@pytest.mark.parametrize("label", LABELS)
def test_fault_leaves_a_finished_bag_without_garbage(fault_runs, bag_dir, label):
    case = fault_runs[label]
    bag = read_finished(case.bag)
    assert_whole_steps(bag, DT_NS, namespace=f"/{label}")
    steps = len(bag.steps())
    if case.last_step is not None:
        assert steps == case.last_step + 1, f"{steps} steps recorded, expected 0..{case.last_step}"
    else:
        assert steps >= 3, f"the NaN policy should have driven a few steps first: {steps}"
    for topic, messages in bag.messages.items():
        for _, message in messages:
            assert _finite(message), f"non-finite value recorded on {topic}: {message}"
    if label == "policy_nan":  # it drove agent 0 until just past 0.3 m/s (the policy sees the step before)
        odom = bag.messages[f"/{label}/agent_0/odom"]
        assert 0.2 < odom[-1][1].twist.twist.linear.x < 0.5, odom[-1][1].twist.twist.linear


@pytest.mark.parametrize("label", LABELS)
def test_subscribers_get_no_garbage(fault_runs, label):
    case = fault_runs[label]
    received = case.received
    if label != "policy_raises":  # that one never steps: its only messages are the initial state, before discovery
        assert received["poses"] and received["odom"], f"nothing received before the fault: {case.process.describe()}"
    for name, messages in received.items():
        for message in messages:
            assert _finite(message), f"non-finite {name} received: {message}"


def _finite(value, field_name: str = "") -> bool:
    """Every float in a (rosbags or rclpy) message is finite; LaserScan ranges may be +inf (REP 117), never NaN."""
    if isinstance(value, float):
        return math.isfinite(value) or (field_name in ("ranges", "range_max") and value == math.inf)
    if isinstance(value, (int, str, bytes, bool)) or value is None:
        return True
    if isinstance(value, np.ndarray) or type(value).__name__ == "array":
        values = np.asarray(value)
        if values.dtype.kind != "f":
            return True
        return bool((~np.isnan(values)).all() if field_name == "ranges" else np.isfinite(values).all())
    if isinstance(value, (list, tuple)):
        return all(_finite(v, field_name) for v in value)
    if dataclasses.is_dataclass(value):  # rosbags
        names = [f.name for f in dataclasses.fields(value)]
    else:  # rclpy
        names = list(value.get_fields_and_field_types())
    return all(_finite(getattr(value, name), name) for name in names)


def test_no_corrupted_file_left(fault_runs, bag_dir):
    verdicts = sweep(bag_dir, min_files=len(LABELS))
    print("\n" + "\n".join(f"{name}: {verdict}" for name, verdict in verdicts.items()))
