"""BenchMARL trains on vmas_ros unchanged, and ``vmas-ros export --from-benchmarl`` makes its run our
STEM.onnx + STEM.json.

BenchMARL 1.5 pins torchrl < 0.12, so ``scripts/setup_benchmarl.sh`` makes
``.venv-benchmarl`` (torch 2.13.0, benchmarl, vmas_ros with the gym extra).
One tiny MAPPO run on BenchMARL's VMAS navigation task (``test.compat.benchmarl_run``,
BenchMARL's venv from ``scripts/setup_benchmarl.sh``); BenchMARL's own
deterministic actions on observations from stepping the task's env
(``test.compat.benchmarl_actions``, same venv); the CLI conversion; then, in this
venv, ``OnnxPolicy`` on those observations must give those actions within 1e-5,
and the converted policy drives sim_node (``control: policy``) and runs as
policy_node against a sim_node process.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray

from test.ros.conftest import ros, sim_log_dir, sim_node  # noqa: F401 (fixtures: the ROS process harness)
from test.ros.policy_process import PolicyProcess
from vmas_ros.policy import OnnxPolicy

ROOT = Path(__file__).resolve().parents[2]
VENV = Path(os.environ.get("VMAS_ROS_BENCHMARL_VENV", ROOT / ".venv-benchmarl"))


def _run(cmd, **kwargs):
    result = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=900, **kwargs)
    assert result.returncode == 0, f"{cmd}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result


def _benchmarl_python() -> str:
    _run(["bash", "scripts/setup_benchmarl.sh"])  # BenchMARL, vmas_ros and the ONNX exporter's packages
    return str(VENV / "bin" / "python")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A tiny BenchMARL MAPPO run on navigation, BenchMARL's actions on recorded observations,
    and the run converted with ``vmas-ros export --from-benchmarl``: a dict of paths and arrays."""
    tmp_path = tmp_path_factory.mktemp("benchmarl_export")
    python = _benchmarl_python()
    trained = _run([python, "-m", "test.compat.benchmarl_run", "--algorithm", "mappo", "--task", "navigation",
                    "--out", str(tmp_path / "run"), "--frames", "1200"])
    result = json.loads(trained.stdout.strip().splitlines()[-1])
    checkpoint = result["checkpoints"][-1]

    # BenchMARL's deterministic actions on observations of the task's env, recorded in its own venv
    _run([python, "-m", "test.compat.benchmarl_actions", checkpoint, str(tmp_path / "recorded"), "--steps", "15"])
    stem = tmp_path / "policy" / "navigation_mappo"
    _run([sys.executable, "-m", "vmas_ros.cli", "export", "--from-benchmarl", result["folder"], "--out", str(stem),
          "--benchmarl-python", python])
    return {
        "python": python, "trained": result,
        "json": Path(str(stem) + ".json"),
        "observations": np.load(tmp_path / "recorded" / "observations.npy"),
        "actions": np.load(tmp_path / "recorded" / "actions.npy"),
    }


def test_benchmarl_mappo_trains_on_vmas_ros(exported):
    """BenchMARL's own VMAS navigation task, with ``vmas`` resolving to vmas_ros, beside torchrl 0.11."""
    versions = subprocess.run(
        [exported["python"], "-c", "import importlib.metadata as m; print(m.version('torchrl'), m.version('torch'))"],
        capture_output=True, text=True, check=True,
    ).stdout.split()
    assert versions[0].startswith("0.11.") and versions[1].startswith("2.13.0"), versions
    result = exported["trained"]
    assert result["frames"] == 1200
    assert result["env_class"] == "vmas_ros.envs.environment"  # BenchMARL stepped our Environment
    assert result["checkpoints"] and all(Path(p).is_file() for p in result["checkpoints"])


def test_onnx_actions_match_benchmarl(exported):
    observations, expected = exported["observations"], exported["actions"]
    assert observations.shape == (90, 3, 18) and expected.shape == (90, 3, 2)  # 6 envs x 15 steps, 3 agents

    policy = OnnxPolicy.load(str(exported["json"]))
    actions = policy.act(observations)
    assert actions.shape == expected.shape
    np.testing.assert_allclose(actions, expected, atol=1e-5, rtol=0)
    assert np.abs(expected).max() > 1e-3  # a real comparison, not zeros against zeros

    meta = json.loads(exported["json"].read_text())
    assert meta["scenario"] == "navigation" and meta["algorithm"] == "mappo"
    assert meta["scenario_kwargs"]["n_agents"] == 3 and meta["scenario_kwargs"]["lidar_range"] == 0.35
    assert meta["max_steps"] == 100 and "max_steps" not in meta["scenario_kwargs"]
    assert meta["agents"] == ["agent_0", "agent_1", "agent_2"]


def test_converted_policy_drives_sim_node(exported):
    """sim_node with ``control: policy``, in a process of its own on loopback DDS."""
    drive = _run([sys.executable, "-c", SIM_NODE_DRIVES.format(json=str(exported["json"]))],
                 env={**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
    moved = json.loads(drive.stdout.strip().splitlines()[-1])
    assert min(moved) > 0.01, moved  # every agent moved under the policy


SIM_NODE_DRIVES = """
import json, rclpy
from vmas_ros.ros.sim_node import SimNode
meta = json.load(open({json!r}))
rclpy.init()
node = SimNode(scenario=meta["scenario"], scenario_kwargs=json.dumps(meta["scenario_kwargs"]), control="policy",
               policy_path={json!r}, num_envs=1)
start = [a.state.pos.clone() for a in node.env.agents]
for _ in range(20):
    node.step_once()
print(json.dumps([float((a.state.pos - s).norm()) for a, s in zip(node.env.agents, start)]))
node.destroy_node()
rclpy.shutdown()
"""


@pytest.mark.ros
def test_converted_policy_runs_as_policy_node(exported, ros, sim_node, sim_log_dir):
    """sim_node (``control: zero``: its agents stand still unless told) and policy_node with
    the converted policy, two processes: the agents move only through policy_node's actions."""
    meta = json.loads(exported["json"].read_text())
    agents = meta["agents"]
    ready = {"/clock": "rosgraph_msgs/msg/Clock", "/agents/poses": "geometry_msgs/msg/PoseArray",
             **{f"/{a}/observation": "std_msgs/msg/Float32MultiArray" for a in agents}}
    poses = ros.collect(PoseArray, "/agents/poses")
    try:
        with sim_node(ready_topics=ready, scenario=meta["scenario"], scenario_kwargs=meta["scenario_kwargs"],
                      control="zero", rate_hz=20.0, seed=3):
            first = poses.wait_for(1)[0]
            ros.spin_for(1.0)
            assert _largest_move(first, poses.latest) < 1e-6, "agents moved before policy_node ran"
            with PolicyProcess(ros, {"policy_path": str(exported["json"]), "rate_hz": 10.0}, sim_log_dir,
                               "benchmarl_policy_node") as node:
                node.wait_publishing([f"/{a}/action" for a in agents])
                ros.spin_until(lambda: _largest_move(first, poses.latest) > 0.05, 20.0,
                               "the agents to move under policy_node")
                assert node.alive(), node.describe()
    finally:
        poses.destroy()


def _largest_move(before, after) -> float:
    return max(((a.position.x - b.position.x) ** 2 + (a.position.y - b.position.y) ** 2) ** 0.5
               for a, b in zip(after.poses, before.poses))


def test_export_from_benchmarl_refuses_clearly(tmp_path):
    missing = subprocess.run([sys.executable, "-m", "vmas_ros.cli", "export", "--from-benchmarl", str(tmp_path),
                              "--out", str(tmp_path / "p"), "--benchmarl-python", str(tmp_path / "nope")],
                             cwd=ROOT, capture_output=True, text=True)
    assert missing.returncode == 2 and "setup_benchmarl.sh" in missing.stderr
    both = subprocess.run([sys.executable, "-m", "vmas_ros.cli", "export", "--from-benchmarl", str(tmp_path),
                           "--checkpoint", str(tmp_path), "--out", str(tmp_path / "p")],
                          cwd=ROOT, capture_output=True, text=True)
    assert both.returncode == 2 and "not allowed with" in both.stderr
