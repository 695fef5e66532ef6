"""``deploy-eval --scan-lead``: the lead reaches policy_node's adapter_kwargs beside a margin, and the reports state it.

The fleet run is the stand-in of test_deploy_act_on.py, which keeps the
parameters it was given; the engine side runs for real, one short episode.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from test.deploy.test_deploy_act_on import fake_fleet
from test.deploy.test_deploy_scan_margin import navigation_policy  # noqa: F401 (fixture: a still 2-agent policy)
from test.ros.policy_files import write_policy
from vmas_ros.cli import main
from vmas_ros.deploy import cli as deploy_cli
from vmas_ros.deploy import fleet_side, report, sweep


def params(scan, extra=None):
    return deploy_cli.policy_node_params("p.json", "navigation", twist=False, drive="holonomic", scale=0.4, dt=0.1,
                                         act_on="scan", extra=extra or {}, scan=scan)


def test_lead_and_margin_go_into_adapter_kwargs_together():
    assert params({"scan_lead": 0.3})["adapter_kwargs"] == {"scan_lead": 0.3}
    both = params({"scan_margin": 0.02, "scan_lead": 0.3}, {"adapter_kwargs": "{scan_yaw: 0.5}"})
    assert both["adapter_kwargs"] == {"scan_yaw": 0.5, "scan_margin": 0.02, "scan_lead": 0.3}


@pytest.mark.parametrize("lead, extra, problem", [
    (-0.2, {}, "--scan-lead must be >= 0 s, got -0.2"),
    (math.nan, {}, "--scan-lead must be a finite number of seconds, got nan"),
    (0.3, {"adapter_kwargs": "{scan_lead: 0.5}"},
     "--scan-lead 0.3 and --policy-param adapter_kwargs' scan_lead 0.5 disagree; give one of them"),
])
def test_a_lead_that_cannot_run_is_refused(lead, extra, problem):
    with pytest.raises(ValueError) as error:
        params({"scan_lead": lead}, extra)
    assert str(error.value) == problem


def test_deploy_eval_runs_the_lead_and_reports_it(tmp_path, monkeypatch, navigation_policy):
    seen: list = []
    monkeypatch.setattr(fleet_side, "fleet_episodes", fake_fleet(seen))
    base = ["deploy-eval", "--policy", str(navigation_policy), "--seeds", "0", "--seconds", "0.5", "--quiet"]
    assert main(base + ["--out", str(tmp_path / "l"), "--act-on", "scan", "--scan-lead", "0.3"]) == 0
    assert [p["adapter_kwargs"] for p in seen] == [{"scan_lead": 0.3}]
    heading = json.loads((tmp_path / "l" / "report.json").read_text())["heading"]
    assert heading["scan_lead"] == 0.3 and heading["scan_margin"] == 0.0
    text = (tmp_path / "l" / "report.md").read_text()
    assert "- scan lead: 0.3 s" in text and "- scan margin: 0 m" in text

    seen.clear()
    assert main(base + ["--out", str(tmp_path / "s"), "--latency-sweep", "0,0.1", "--scan-lead", "0.2"]) == 0
    assert [p["adapter_kwargs"] for p in seen] == [{"scan_lead": 0.2}] * 2
    assert json.loads((tmp_path / "s" / "sweep.json").read_text())["scan_lead"] == 0.2
    assert "- scan lead: 0.2 s" in (tmp_path / "s" / "sweep.md").read_text()


def test_a_lead_for_an_adapter_without_scans_is_refused(tmp_path, monkeypatch, capsys):
    policy = write_policy(tmp_path, "spread", np.zeros((14, 2)), [0.0, 0.0])
    seen: list = []
    monkeypatch.setattr(fleet_side, "fleet_episodes", fake_fleet(seen))
    code = main(["deploy-eval", "--policy", str(policy), "--out", str(tmp_path / "o"), "--scan-lead", "0.3"])
    assert code == 2 and not seen
    assert ("--scan-lead is the navigation adapter's scan_lead; scenario 'simple_spread' runs adapter "
            "'simple_spread', which reads no scans") in capsys.readouterr().err


def test_the_notes_name_only_what_ran():
    assert report.scan_lines({}) == [] and report.scan_note({"scan_margin": None, "scan_lead": None}) == ""
    assert report.scan_note({"scan_margin": 0.0, "scan_lead": 0.0}) == ", scan margin 0 m"
    assert report.scan_note({"scan_margin": 0.0, "scan_lead": 0.3}) == ", scan margin 0 m, scan lead 0.3 s"
    rows = sweep.sweep_rows([{"latency": 0.0, "totals": {"episodes": 1, "engine_success_rate": 1.0,
                                                         "fleet_success_rate": 1.0,
                                                         "engine_collisions_per_episode": 0.0,
                                                         "fleet_collisions_per_episode": 0.0}}])
    assert "- scan lead: 0.3 s" in sweep.markdown(rows, "p", "c", scan={"scan_lead": 0.3})
