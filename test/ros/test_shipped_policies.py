"""The policies under ``policies/`` as a user first runs them: in sim_node, and through policy_node on robot_fleet.

sim_node starts with only ``control: policy`` and the shipped file (its
scenario and kwargs come from the policy's JSON) and its agents do their
task: navigation's agents close in on their goals, simple_spread's cover the
landmarks. Each navigation policy then drives robot_fleet's robots (its own
drive, 50 ms latency, 0.1 s lag, odometry noise) through policy_node, by
``vmas-ros deploy-eval``, from a start the engine also runs.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray
from std_srvs.srv import SetBool, Trigger

from test.ros.conftest import NODE, REPO, stamp_ns
from vmas_ros.cli import main

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SHIPPED = sorted((REPO / "policies").glob("*.json"))
NAVIGATION = [path for path in SHIPPED if path.stem.startswith("navigation")]
SIM_SECONDS = 12.0


def xy(array: PoseArray) -> np.ndarray:
    return np.array([[p.position.x, p.position.y] for p in array.poses])


def task_error(agents: np.ndarray, landmarks: np.ndarray, per_agent_goals: bool) -> np.ndarray:
    """Navigation: each agent's distance to its goal [n]; coverage tasks: each landmark's distance to the nearest
    agent [g]."""
    if per_agent_goals:
        return np.linalg.norm(agents - landmarks, axis=1)
    return np.linalg.norm(landmarks[:, None] - agents[None], axis=-1).min(axis=1)


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_sim_node_runs_a_shipped_policy_from_its_file_alone(ros, sim_node, path):
    per_agent_goals = path.stem.startswith("navigation")
    with sim_node(control="policy", policy_path=str(path), seed=7, rate_hz=40.0):
        agents, landmarks = ros.collect(PoseArray, "/agents/poses"), ros.collect(PoseArray, "/landmarks/poses")
        try:
            agents.wait_for(1)
            landmarks.wait_for(1)
            # the policy has been driving since the node started: start the task afresh, held still
            assert ros.call(SetBool, f"{NODE}/pause", SetBool.Request(data=True)).success
            assert ros.call(Trigger, f"{NODE}/reset").success
            ros.spin_for(0.5)
            first = agents.latest
            start = task_error(xy(first), xy(landmarks.latest), per_agent_goals)
            assert ros.call(SetBool, f"{NODE}/pause", SetBool.Request(data=False)).success

            def elapsed():
                return (stamp_ns(agents.latest.header.stamp) - stamp_ns(first.header.stamp)) / 1e9

            ros.spin_until(lambda: elapsed() >= SIM_SECONDS, 60, f"{SIM_SECONDS} s of simulated time")
            end = task_error(xy(agents.latest), xy(landmarks.latest), per_agent_goals)
        finally:
            agents.destroy()
            landmarks.destroy()
    assert start.max() > 0.3, f"the start is too close to the goals to tell: {start}"
    if per_agent_goals:
        assert (end < 0.15).all(), f"{path.stem}: every agent within 0.15 m of its goal, from {start}: {end}"
    else:  # agents held still would keep the start's figure
        assert end.mean() < 0.75 * start.mean(), f"{path.stem}: landmarks covered, from {start}: {end}"


@pytest.mark.parametrize("path", NAVIGATION, ids=lambda p: p.stem)
def test_policy_node_drives_robot_fleet_with_a_shipped_navigation_policy(tmp_path, path):
    drive = "diff_drive" if "diff_drive" in path.stem else "holonomic"
    out = tmp_path / "eval"
    code = main(["deploy-eval", "--policy", str(path), "--drive", drive, "--seeds", "3", "--seconds", "20",
                 "--end-at-done", "--out", str(out), "--quiet"])
    assert code == 0, (out / "robot_fleet.log").read_text() if (out / "robot_fleet.log").exists() else ""
    fleet = json.loads((out / "fleet_summary.json").read_text())
    episode = fleet["episodes"][0]
    assert fleet["parameters"]["drive"] == drive and fleet["parameters"]["command_latency"] == 0.05
    start = np.linalg.norm(np.array(episode["start"]["robots"])[:, :2] - np.array(episode["start"]["goals"]), axis=1)
    final = np.array(episode["final_distance"])
    assert start.max() > 0.3, f"the start is too close to the goals to tell: {start}"
    assert (final < 0.2).all(), f"{path.stem} on {drive} robots: every robot near its goal, from {start}: {final}"
