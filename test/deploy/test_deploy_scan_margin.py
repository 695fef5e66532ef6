"""``deploy-eval --scan-margin``: the margin reaches policy_node's adapter_kwargs and every report states it.

As in test_deploy_act_on.py, the fleet run is a stand-in that keeps the
parameters it was given; the engine side runs for real, one short episode.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from test.deploy.test_deploy_act_on import fake_fleet
from test.ros.policy_files import write_policy
from vmas_ros.cli import main
from vmas_ros.deploy import cli as deploy_cli
from vmas_ros.deploy import fleet_side, sweep
from vmas_ros.ros.params import PolicyNodeParams, validate_policy_node


def params(margin, extra=None):
    return deploy_cli.policy_node_params("p.json", "navigation", twist=False, drive="holonomic", scale=0.4, dt=0.1,
                                         act_on="scan", extra=extra or {},
                                         scan={} if margin is None else {"scan_margin": margin})


def test_the_margin_goes_into_policy_nodes_adapter_kwargs():
    argv = fleet_side.node_command("vmas_ros.ros.policy_node", params(0.05))
    given = argv[argv.index("-p", argv.index("--ros-args")):]
    (item,) = [value for flag, value in zip(given[::2], given[1::2]) if value.startswith("adapter_kwargs:=")]
    text = yaml.safe_load(item.removeprefix("adapter_kwargs:="))  # as rcl reads the -p value: a string
    assert validate_policy_node("adapter_kwargs", text) is None
    assert PolicyNodeParams(adapter_kwargs=text).kwargs() == {"scan_margin": 0.05}
    assert "adapter_kwargs" not in params(None)  # no margin given: policy_node's default, as before


@pytest.mark.parametrize("given", ["{scan_yaw: 0.5}", {"scan_yaw": 0.5}])
def test_the_margin_joins_adapter_kwargs_given_as_a_policy_param(given):
    assert params(0.08, {"adapter_kwargs": given})["adapter_kwargs"] == {"scan_yaw": 0.5, "scan_margin": 0.08}
    assert params(None, {"adapter_kwargs": given})["adapter_kwargs"] == {"scan_yaw": 0.5}
    assert params(0.08, {"adapter_kwargs": {"scan_margin": 0.08}})["adapter_kwargs"] == {"scan_margin": 0.08}


@pytest.mark.parametrize("margin, extra, problem", [
    (-0.02, {}, "--scan-margin must be >= 0 m, got -0.02"),
    (math.nan, {}, "--scan-margin must be a finite number of metres, got nan"),
    (math.inf, {}, "--scan-margin must be a finite number of metres, got inf"),
    (0.05, {"adapter_kwargs": "{scan_margin: 0.08}"},
     "--scan-margin 0.05 and --policy-param adapter_kwargs' scan_margin 0.08 disagree; give one of them"),
    (0.05, {"adapter_kwargs": "[1, 2]"}, "--policy-param adapter_kwargs must be a mapping"),
])
def test_a_margin_that_cannot_run_is_refused(margin, extra, problem):
    with pytest.raises(ValueError) as error:
        params(margin, extra)
    assert str(error.value).startswith(problem)


@pytest.fixture
def navigation_policy(tmp_path):
    return write_policy(tmp_path, "still", np.zeros((18, 2)), [0.0, 0.0], agents=("agent_0", "agent_1"),
                        scenario="navigation", scenario_kwargs={"n_agents": 2})


def test_deploy_eval_runs_the_margin_and_reports_it(tmp_path, monkeypatch, navigation_policy):
    seen: list = []
    monkeypatch.setattr(fleet_side, "fleet_episodes", fake_fleet(seen))
    base = ["deploy-eval", "--policy", str(navigation_policy), "--seeds", "0", "--seconds", "0.5", "--quiet"]
    assert main(base + ["--out", str(tmp_path / "m"), "--act-on", "scan", "--scan-margin", "0.05"]) == 0
    assert [p["adapter_kwargs"] for p in seen] == [{"scan_margin": 0.05}]
    heading = json.loads((tmp_path / "m" / "report.json").read_text())["heading"]
    assert heading["scan_margin"] == 0.05
    assert "- scan margin: 0.05 m" in (tmp_path / "m" / "report.md").read_text()

    seen.clear()  # the margin given through adapter_kwargs is the one reported too
    assert main(base + ["--out", str(tmp_path / "p"), "--policy-param", "adapter_kwargs:={scan_margin: 0.03}"]) == 0
    assert [yaml.safe_load(str(p["adapter_kwargs"])) for p in seen] == [{"scan_margin": 0.03}]
    assert json.loads((tmp_path / "p" / "report.json").read_text())["heading"]["scan_margin"] == 0.03

    seen.clear()  # none given: the navigation adapter runs without one, and the report says so
    assert main(base + ["--out", str(tmp_path / "none")]) == 0
    assert "adapter_kwargs" not in seen[0]
    assert json.loads((tmp_path / "none" / "report.json").read_text())["heading"]["scan_margin"] == 0.0
    assert "- scan margin: 0 m" in (tmp_path / "none" / "report.md").read_text()

    seen.clear()
    assert main(base + ["--out", str(tmp_path / "sweep"), "--latency-sweep", "0,0.05", "--scan-margin", "0.08"]) == 0
    assert [p["adapter_kwargs"] for p in seen] == [{"scan_margin": 0.08}] * 2
    assert json.loads((tmp_path / "sweep" / "sweep.json").read_text())["scan_margin"] == 0.08
    assert "- scan margin: 0.08 m" in (tmp_path / "sweep" / "sweep.md").read_text()
    assert "- scan margin: 0.08 m" in (tmp_path / "sweep" / "latency_050ms" / "report.md").read_text()


@pytest.mark.parametrize("margin, problem", [
    ("-0.1", "--scan-margin must be >= 0 m, got -0.1"),
    ("nan", "--scan-margin must be a finite number of metres, got nan"),
    ("0.5", "adapter 'navigation' refused its arguments: scan_margin must be >= 0 m and below the training "
            "lidar's range 0.35 m, got 0.5"),
])
def test_a_bad_margin_is_refused_before_anything_runs(tmp_path, monkeypatch, capsys, navigation_policy, margin,
                                                      problem):
    seen: list = []
    monkeypatch.setattr(fleet_side, "fleet_episodes", fake_fleet(seen))
    code = main(["deploy-eval", "--policy", str(navigation_policy), "--out", str(tmp_path / "o"),
                 "--scan-margin", margin])
    assert code == 2 and not seen and not (tmp_path / "o").exists()
    assert problem in capsys.readouterr().err


def test_a_margin_for_an_adapter_without_scans_is_refused(tmp_path, monkeypatch, capsys):
    policy = write_policy(tmp_path, "spread", np.zeros((14, 2)), [0.0, 0.0])
    seen: list = []
    monkeypatch.setattr(fleet_side, "fleet_episodes", fake_fleet(seen))
    code = main(["deploy-eval", "--policy", str(policy), "--out", str(tmp_path / "o"), "--scan-margin", "0.05"])
    assert code == 2 and not seen
    assert ("--scan-margin is the navigation adapter's scan_margin; scenario 'simple_spread' runs adapter "
            "'simple_spread', which reads no scans") in capsys.readouterr().err


def test_sweep_markdown_states_the_margin_only_where_there_is_one():
    rows = sweep.sweep_rows([{"latency": 0.0, "totals": {"episodes": 1, "engine_success_rate": 1.0,
                                                         "fleet_success_rate": 1.0,
                                                         "engine_collisions_per_episode": 0.0,
                                                         "fleet_collisions_per_episode": 0.0}}])
    assert "- scan margin: 0.05 m" in sweep.markdown(rows, "p", "c", scan={"scan_margin": 0.05})
    assert "scan margin" not in sweep.markdown(rows, "p", "c")
