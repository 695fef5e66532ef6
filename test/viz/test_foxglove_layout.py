"""``vmas-ros foxglove-layout``: a layout that matches a node's frames and agents."""
from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest

from vmas_ros.cli import main
from vmas_ros.viz.foxglove_layout import MAX_PLOTTED_AGENTS, foxglove_layout, layout_command

ROOT = Path(__file__).resolve().parents[2]


def test_the_shipped_layout_is_the_root_nodes_layout():
    assert json.loads((ROOT / "config" / "foxglove_layout.json").read_text()) == foxglove_layout()


def test_a_namespaced_layout_follows_the_prefixed_world_frame_and_the_agents():
    layout = foxglove_layout("swarm_a/world", ["blue_0", "blue_1"])
    scene = layout["configById"]["3D!vmas_scene"]
    assert scene["followTf"] == scene["fixedFrame"] == scene["layers"]["vmas_grid"]["frameId"] == "swarm_a/world"
    assert [t for t, c in scene["topics"].items() if c["visible"]] == ["/scene", "/blue_0/scan", "/blue_1/scan"]
    assert layout["configById"]["Teleop!blue_0"]["topic"] == "/blue_0/cmd_vel"
    assert layout["layout"]["second"]["first"] == "Teleop!blue_0"
    plotted = [p["label"] for p in layout["configById"]["Plot!rewards"]["paths"]]
    assert plotted == ["total", "blue_0", "blue_1"]


def test_a_large_team_plots_the_total_and_the_first_agents_only():
    agents = [f"agent_{i}" for i in range(20)]
    paths = foxglove_layout("world", agents)["configById"]["Plot!rewards"]["paths"]
    assert [p["label"] for p in paths] == ["total", *agents[:MAX_PLOTTED_AGENTS]]


@pytest.mark.parametrize("frame, agents, word", [
    ("/world", ["agent_0"], "'/world'"), ("", ["agent_0"], "got ''"), ("world", [], "at least one agent"),
    ("world", ["agent 0"], "'agent 0'"), ("world", ["agent_0", "a/"], "'a/'"),
])
def test_bad_frames_and_agents_are_refused_naming_them(frame, agents, word):
    with pytest.raises(ValueError, match=word):
        foxglove_layout(frame, agents)


def test_the_command_writes_the_layout_and_keeps_an_existing_file(tmp_path, capsys):
    out = tmp_path / "layout.json"
    assert main(["foxglove-layout", "--frame-prefix", "swarm_b/", "--agents", "2", "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == foxglove_layout("swarm_b/world", ["agent_0", "agent_1"])
    assert f"wrote {out}" in capsys.readouterr().out
    out.write_text("{}")
    assert main(["foxglove-layout", "--out", str(out)]) == 2
    assert "exists; pass --force" in capsys.readouterr().err and out.read_text() == "{}"
    assert main(["foxglove-layout", "--out", str(out), "--force", "--agents", "red,blue", "--frame-id", "map"]) == 0
    assert json.loads(out.read_text()) == foxglove_layout("map", ["red", "blue"])


@pytest.mark.parametrize("args, message", [
    (["--agents", "0"], "--agents must be a count >= 1 or comma-separated names, got '0'"),
    (["--frame-prefix", "/swarm_a/"], "frame_prefix '/swarm_a/' is not a frame name prefix"),
])
def test_the_command_refuses_bad_arguments(args, message, capsys):
    assert main(["foxglove-layout", *args]) == 2
    assert message in capsys.readouterr().err


def test_the_command_a_node_logs_makes_its_layout(tmp_path):
    assert layout_command("", "world", ["agent_0", "agent_1", "agent_2"]) is None  # the shipped file fits
    command = layout_command("swarm_a/", "world", ["agent_0", "agent_1"])
    assert command == "vmas-ros foxglove-layout --frame-prefix swarm_a/ --agents 2 --out layout.json"
    argv = shlex.split(layout_command("", "odom", ["red", "blue"]))
    assert argv[:1] == ["vmas-ros"] and "--frame-id" in argv
    argv[argv.index("--out") + 1] = str(tmp_path / "layout.json")
    assert main(argv[1:]) == 0
    assert json.loads((tmp_path / "layout.json").read_text()) == foxglove_layout("odom", ["red", "blue"])
