"""``vmas-ros deploy-eval`` end to end: the engine's episodes, then the same starts on robot_fleet under a
policy_node process, and a report that puts them side by side."""
from __future__ import annotations

import json

import numpy as np
import pytest

from test.ros.policy_files import write_policy
from vmas_ros.cli import main

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_a_navigation_policy_runs_in_the_engine_and_on_the_fleet_from_the_same_starts(tmp_path):
    weight = np.zeros((18, 2))
    weight[4, 0] = weight[5, 1] = -1.5  # towards the own goal
    weight[2, 0] = weight[3, 1] = -1.0
    policy = write_policy(tmp_path, "seek", weight, [0.0, 0.0], agents=("agent_0", "agent_1"),
                          scenario="navigation", scenario_kwargs={"n_agents": 2})
    out = tmp_path / "eval"
    code = main(["deploy-eval", "--policy", str(policy), "--seeds", "2", "--episodes-per-seed", "2",
                 "--seconds", "4", "--end-at-done", "--out", str(out), "--quiet",
                 "--policy-param", "observation_timeout:=0.3"])
    assert code == 0, (out / "robot_fleet.log").read_text() if (out / "robot_fleet.log").exists() else ""
    found = json.loads((out / "report.json").read_text())
    rows, totals = found["rows"], found["totals"]
    assert [r["episode"] for r in rows] == ["seed 2 env 0", "seed 2 env 1"]
    fleet = json.loads((out / "fleet_summary.json").read_text())
    engine = json.loads((out / "engine.json").read_text())
    # the fleet ran the engine's starts: same positions and goals (headings drawn: holonomic agents never turn)
    for start, episode in zip(engine["starts"], fleet["episodes"]):
        assert np.allclose(np.array(start["robots"])[:, :2], np.array(episode["start"]["robots"])[:, :2])
        assert np.allclose(start["goals"], episode["start"]["goals"])
        # --end-at-done: an episode ends at 4 s, or where every robot first stood on its goal
        if episode["ended_by"] == "goals":
            assert episode["duration"] == pytest.approx(episode["all_at_goal_time"]) < 4.0
        else:
            assert episode["ended_by"] == "time" and episode["duration"] == pytest.approx(4.0)
    parameters = fleet["parameters"]
    assert parameters["command_latency"] == 0.05 and parameters["use_stamped_cmd_vel"] and parameters["end_on_goals"]
    # the policy drove the fleet's robots towards their goals, as in the engine
    for row, ours, theirs in zip(rows, engine["episodes"], fleet["episodes"]):
        start = np.linalg.norm(np.array(theirs["start"]["robots"])[:, :2] - np.array(theirs["start"]["goals"]), axis=1)
        assert (np.array(theirs["final_distance"]) < start).all(), theirs
        assert row["engine_coverage"] == pytest.approx(ours["coverage"])
    assert totals["episodes"] == 2 and totals["coverage_ratio"] is not None
    text = (out / "report.md").read_text()
    assert "| seed 2 env 0 |" in text and "command_latency 0.05" in text
    assert (out / "comparison.png").stat().st_size > 1000
