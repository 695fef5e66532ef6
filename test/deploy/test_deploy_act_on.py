"""``deploy-eval --act-on``: policy_node's act_on reaches the node's command line and every report says which ran.

The fleet run itself is replaced by a stand-in that keeps the parameters it
was given and answers with a fleet summary of the engine's own episodes (a
real fleet run is test_deploy_eval.py's); the engine side runs for real, for
one short episode.
"""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from test.ros.policy_files import write_policy
from vmas_ros.cli import main
from vmas_ros.deploy import cli as deploy_cli
from vmas_ros.deploy import fleet_side, sweep


def test_act_on_goes_into_policy_nodes_command_line():
    params = deploy_cli.policy_node_params("p.json", "navigation", twist=False, drive="holonomic", scale=1.0,
                                           dt=0.1, act_on="scan", extra={"lookahead": 0.2})
    argv = fleet_side.node_command("vmas_ros.ros.policy_node", params)
    assert argv[argv.index("act_on:='scan'") - 1] == "-p"
    assert "rate_hz:=10.0" in argv and "lookahead:=0.2" in argv and "adapter:='navigation'" in argv


@pytest.mark.parametrize("option, extra, expected", [
    (None, {}, "timer"), ("scan", {}, "scan"), (None, {"act_on": "scan"}, "scan"),
    ("scan", {"act_on": "scan"}, "scan"),
])
def test_act_on_comes_from_either_option(option, extra, expected):
    assert deploy_cli.act_on_of(option, extra) == expected


def test_two_different_act_on_values_are_refused():
    with pytest.raises(ValueError, match="--act-on timer and --policy-param act_on:=scan disagree"):
        deploy_cli.act_on_of("timer", {"act_on": "scan"})


def test_the_option_takes_only_policy_nodes_values(capsys):
    parser = argparse.ArgumentParser()
    deploy_cli.add_arguments(parser)
    assert parser.parse_args(["--policy", "p", "--out", "o", "--act-on", "scan"]).act_on == "scan"
    with pytest.raises(SystemExit):
        parser.parse_args(["--policy", "p", "--out", "o", "--act-on", "scans"])
    assert "invalid choice: 'scans'" in capsys.readouterr().err


def fake_fleet(seen: list):
    """A fleet_episodes stand-in: records policy_node's parameters, replays the engine's starts as done."""
    def fleet_episodes(folder, starts, seconds, fleet_params, policy_params, progress=True):
        seen.append(policy_params)
        episodes = [{"plan_index": k, "ended_by": "time", "coverage": 0.1, "collisions": {"robot_robot": 0},
                     "all_at_goal_time": None, "start": start} for k, start in enumerate(starts)]
        return {"parameters": {**fleet_params, "scan_rate_hz": 10.0}, "episodes": episodes, "complete": True}
    return fleet_episodes


def test_deploy_eval_runs_policy_node_with_act_on_and_reports_it(tmp_path, monkeypatch):
    weight = np.zeros((18, 2))
    policy = write_policy(tmp_path, "still", weight, [0.0, 0.0], agents=("agent_0", "agent_1"),
                          scenario="navigation", scenario_kwargs={"n_agents": 2})
    seen: list = []
    monkeypatch.setattr(fleet_side, "fleet_episodes", fake_fleet(seen))
    out = tmp_path / "eval"
    code = main(["deploy-eval", "--policy", str(policy), "--seeds", "0", "--seconds", "0.5", "--out", str(out),
                 "--quiet", "--act-on", "scan"])
    assert code == 0
    assert [p["act_on"] for p in seen] == ["scan"]
    heading = json.loads((out / "report.json").read_text())["heading"]
    assert heading["act_on"] == "scan" and "act_on" not in heading["policy_node"]
    text = (out / "report.md").read_text()
    assert "- policy_node acts on: scan; parameters: adapter navigation" in text and "scan_rate_hz 10.0" in text

    seen.clear()
    code = main(["deploy-eval", "--policy", str(policy), "--seeds", "0", "--seconds", "0.5", "--out",
                 str(tmp_path / "sweep"), "--quiet", "--latency-sweep", "0,0.05"])
    assert code == 0 and [p["act_on"] for p in seen] == ["timer", "timer"]
    assert json.loads((tmp_path / "sweep" / "sweep.json").read_text())["act_on"] == "timer"
    assert "- policy_node acts on: timer" in (tmp_path / "sweep" / "sweep.md").read_text()
    assert "- policy_node acts on: timer" in (tmp_path / "sweep" / "latency_050ms" / "report.md").read_text()


def test_a_disagreement_is_refused_before_anything_runs(tmp_path, monkeypatch, capsys):
    seen: list = []
    monkeypatch.setattr(fleet_side, "fleet_episodes", fake_fleet(seen))
    code = main(["deploy-eval", "--policy", str(tmp_path / "missing.json"), "--out", str(tmp_path / "o"),
                 "--act-on", "scan", "--policy-param", "act_on:=timer"])
    assert code == 2 and not seen and not (tmp_path / "o").exists()
    assert "--act-on scan and --policy-param act_on:=timer disagree" in capsys.readouterr().err


def test_sweep_markdown_names_the_mode():
    rows = sweep.sweep_rows([{"latency": 0.0, "totals": {"episodes": 1, "engine_success_rate": 1.0,
                                                         "fleet_success_rate": 1.0,
                                                         "engine_collisions_per_episode": 0.0,
                                                         "fleet_collisions_per_episode": 0.0}}])
    assert "- policy_node acts on: scan" in sweep.markdown(rows, "p", "c", act_on="scan")
