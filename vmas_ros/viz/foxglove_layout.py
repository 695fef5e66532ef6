"""Foxglove layouts for a sim_node: a 3D scene, a Teleop panel and a rewards plot.

The shipped ``config/foxglove_layout.json`` is this module's layout for a node
at the root namespace with agents ``agent_0`` to ``agent_2``. A node in a
namespace prefixes its frames (``swarm_a/world``), and other scenarios name
other agents, so ``vmas-ros foxglove-layout`` writes the layout that matches a
given node: its world frame, one scan layer per agent, Teleop on the first
agent, and each agent's reward in the plot.

Foxglove reads a panel's title from ``foxglovePanelTitle``; the panel keys
(``3D!``, ``Teleop!``, ``Plot!``) name the panel types.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import List, Optional, Sequence

__all__ = ["DEFAULT_AGENTS", "MAX_PLOTTED_AGENTS", "foxglove_layout", "layout_command", "layout_json",
           "parse_agents"]

#: the agents of the shipped layout (simple_spread's default team)
DEFAULT_AGENTS = ("agent_0", "agent_1", "agent_2")
#: a plot with more lines than this is unreadable: further agents' rewards are left out (the total stays)
MAX_PLOTTED_AGENTS = 8
#: the Teleop panel's speed while a button is held (m/s)
TELEOP_SPEED = 0.5
#: Teleop republishes this often: faster than sim_node's default cmd_vel_timeout lets a command lapse
TELEOP_RATE_HZ = 10


def _rgba(red: int, green: int, blue: int, alpha: int) -> str:
    """A colour as Foxglove's panels take it: ``#rrggbbaa``."""
    return f"#{red:02x}{green:02x}{blue:02x}{alpha:02x}"


SCAN_COLOUR = _rgba(230, 50, 50, 255)  # scan hits in red, apart from the scene's colours
GRID_COLOUR = _rgba(36, 142, 255, 64)  # a faint blue under the scene



def _three_d(world_frame: str, agents: Sequence[str]) -> dict:
    topics = {"/scene": {"visible": True}}
    for agent in agents:
        topics[f"/{agent}/scan"] = {"visible": True, "pointSize": 6, "colorMode": "flat", "flatColor": SCAN_COLOUR}
    for agent in agents:
        topics[f"/{agent}/pose"] = {"visible": False}  # the scene already draws each agent
    camera = {"distance": 5, "perspective": False, "phi": 0, "thetaOffset": 0, "target": [0, 0, 0],
              "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1], "fovy": 45, "near": 0.01, "far": 1000}
    grid = {"layerId": "foxglove.Grid", "instanceId": "vmas_grid", "label": "Grid", "visible": True,
            "frameId": world_frame, "size": 4, "divisions": 8, "lineWidth": 1, "color": GRID_COLOUR,
            "position": [0, 0, 0], "rotation": [0, 0, 0], "order": 1}
    return {"foxglovePanelTitle": "Scene (env_index)", "followTf": world_frame, "fixedFrame": world_frame,
            "followMode": "follow-pose", "cameraState": camera, "layers": {"vmas_grid": grid}, "topics": topics}


def _teleop(agent: str) -> dict:
    def button(field: str, value: float) -> dict:
        return {"field": field, "value": value}

    return {"foxglovePanelTitle": f"Drive {agent}", "topic": f"/{agent}/cmd_vel", "publishRate": TELEOP_RATE_HZ,
            "upButton": button("linear-x", TELEOP_SPEED), "downButton": button("linear-x", -TELEOP_SPEED),
            "leftButton": button("linear-y", TELEOP_SPEED), "rightButton": button("linear-y", -TELEOP_SPEED)}


def _plot(agents: Sequence[str]) -> dict:
    paths = [{"value": f"/rewards.{label}", "enabled": True, "timestampMethod": "receiveTime", "label": label}
             for label in ("total", *agents[:MAX_PLOTTED_AGENTS])]
    return {"foxglovePanelTitle": "Rewards", "paths": paths, "showXAxisLabels": True, "showYAxisLabels": True,
            "showLegend": True, "legendDisplay": "floating", "isSynced": True, "xAxisVal": "timestamp",
            "followingViewWidth": 30}


def foxglove_layout(world_frame: str = "world", agents: Sequence[str] = DEFAULT_AGENTS) -> dict:
    """The layout for a node whose world frame is ``world_frame`` and whose agents are ``agents``.

    ``world_frame`` is sim_node's ``frame_prefix`` + ``frame_id`` (``world``,
    ``swarm_a/world``); ``agents`` are names as the node publishes them (at
    least one). Raises ValueError naming a bad value.
    """
    from vmas_ros.rostools.graph import ToolError, resolve_name

    if not isinstance(world_frame, str) or not world_frame or world_frame.startswith("/"):
        raise ValueError(f"the world frame must be a frame name not starting with '/' (e.g. 'swarm_a/world'), "
                         f"got {world_frame!r}")
    agents = tuple(agents)
    if not agents:
        raise ValueError("a layout needs at least one agent (Teleop drives the first)")
    for agent in agents:  # each names topics such as /<agent>/cmd_vel
        try:
            resolve_name(f"{agent}/cmd_vel")
        except (ToolError, AttributeError, TypeError):
            raise ValueError(f"agent names must be ROS name tokens (letters, digits, '_'), got {agent!r}") from None
    panels = {"3D!vmas_scene": _three_d(world_frame, agents), f"Teleop!{agents[0]}": _teleop(agents[0]),
              "Plot!rewards": _plot(agents)}
    arrangement = {"direction": "row", "first": "3D!vmas_scene",
                   "second": {"direction": "column", "first": f"Teleop!{agents[0]}", "second": "Plot!rewards",
                              "splitPercentage": 40},
                   "splitPercentage": 65}
    return {"configById": panels, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1},
            "layout": arrangement}


def layout_json(layout: dict) -> str:
    """The layout as a file's text (two-space indent, as config/foxglove_layout.json)."""
    return json.dumps(layout, indent=2) + "\n"


def parse_agents(text: str) -> List[str]:
    """``--agents`` as given: a count N (``agent_0`` to ``agent_N-1``) or comma-separated names."""
    text = text.strip()
    if text.isdigit():
        count = int(text)
        if count < 1:
            raise ValueError(f"--agents must be a count >= 1 or comma-separated names, got {text!r}")
        return [f"agent_{i}" for i in range(count)]
    return [name.strip() for name in text.split(",") if name.strip()]


def layout_command(frame_prefix: str, frame_id: str, agents: Sequence[str]) -> Optional[str]:
    """The ``vmas-ros foxglove-layout`` command for a node, or None where the shipped layout fits it."""
    if frame_prefix + frame_id == "world" and tuple(agents) == DEFAULT_AGENTS:
        return None
    numbered = list(agents) == [f"agent_{i}" for i in range(len(agents))]
    parts = ["vmas-ros foxglove-layout"]
    if frame_prefix:
        parts.append(f"--frame-prefix {frame_prefix}")
    if frame_id != "world":
        parts.append(f"--frame-id {frame_id}")
    parts.append(f"--agents {len(agents) if numbered else ','.join(agents)}")
    parts.append("--out layout.json")
    return " ".join(parts)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frame-prefix", default="",
                        help="the node's frame_prefix, e.g. swarm_a/ for a node in /swarm_a (default: none)")
    parser.add_argument("--frame-id", default="world", help="the node's frame_id (default world)")
    parser.add_argument("--agents", default=str(len(DEFAULT_AGENTS)),
                        help="a count N (agent_0 to agent_N-1) or comma-separated agent names (default 3)")
    parser.add_argument("--out", default=None, help="write the layout here (default: print it)")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")


def run(args: argparse.Namespace) -> int:
    from vmas_ros.rostools.graph import frame_prefix_error

    try:
        refused = frame_prefix_error(args.frame_prefix)  # the node's own rule for its frame_prefix
        if refused:
            raise ValueError(refused)
        text = layout_json(foxglove_layout(args.frame_prefix + args.frame_id, parse_agents(args.agents)))
    except ValueError as error:
        print(f"vmas-ros foxglove-layout: {error}", file=sys.stderr)
        return 2
    if args.out is None:
        sys.stdout.write(text)
        return 0
    out = Path(args.out)
    if out.exists() and not args.force:
        print(f"vmas-ros foxglove-layout: {out} exists; pass --force to replace it", file=sys.stderr)
        return 2
    out.write_text(text, encoding="utf-8")
    print(f"wrote {out}: import it in Foxglove with Layouts -> Import from file")
    return 0
