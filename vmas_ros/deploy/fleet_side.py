"""The same episodes on ``robot_fleet``, driven by ``policy_node``: two processes on this machine's ROS graph.

policy_node starts first; robot_fleet then starts with ``wait_for_commands``
(its first episode's clock runs only once every robot's cmd_vel has
policy_node as a publisher) and ``exit_after_last``, runs every episode of
the episodes file for ``episode_seconds`` and writes its summary. Both
processes log to files in the output folder; policy_node is stopped with
SIGINT once the fleet has exited. DDS discovery stays on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless the environment sets it).
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

#: seconds given to each process to start (imports, ONNX load, DDS discovery) before the run counts as stuck
START_ALLOWANCE_S = 60.0


def ros_value(value: Any) -> str:
    """A ``-p name:=value`` value as YAML that rcl parses to the intended type (strings single-quoted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, (dict, list)):
        value = json.dumps(value)
    return "'" + str(value).replace("'", "''") + "'"


def node_command(module: str, params: Dict[str, Any]) -> List[str]:
    """``python -m module --ros-args -p name:=value ...`` with every value as rcl wants it."""
    argv = [sys.executable, "-m", module, "--ros-args"]
    for name, value in params.items():
        argv += ["-p", f"{name}:={ros_value(value)}"]
    return argv


def _environment() -> Dict[str, str]:
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    return env


class _Process:
    """One node process with its output in ``<folder>/<label>.log``."""

    def __init__(self, argv: List[str], folder: Path, label: str) -> None:
        self.label, self.log_path = label, folder / f"{label}.log"
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT,
                                     env=_environment())

    def alive(self) -> bool:
        return self.proc.poll() is None

    def tail(self, lines: int = 15) -> str:
        return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])

    def stop(self, timeout: float = 15.0) -> Optional[int]:
        if self.alive():
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self._log.close()
        return self.proc.returncode


def fleet_episodes(folder: Path, starts: List[dict], seconds: float, fleet_params: Dict[str, Any],
                   policy_params: Dict[str, Any], progress: bool = True) -> Dict[str, Any]:
    """Run ``starts`` (robot_fleet's episode form) on the fleet under policy_node; returns the fleet's summary.

    Raises RuntimeError naming the process and its last log lines when either
    exits early or the fleet does not finish in time.
    """
    from tqdm import tqdm

    folder.mkdir(parents=True, exist_ok=True)
    episodes_path, summary_path = folder / "episodes.json", folder / "fleet_summary.json"
    episodes_path.write_text(json.dumps({"episodes": starts}, indent=1))
    summary_path.unlink(missing_ok=True)
    fleet_params = {**fleet_params, "episodes_file": str(episodes_path), "episode_seconds": float(seconds),
                    "summary_path": str(summary_path), "exit_after_last": True, "wait_for_commands": True}
    policy = _Process(node_command("vmas_ros.ros.policy_node", policy_params), folder, "policy_node")
    fleet = None
    try:
        fleet = _Process(node_command("vmas_ros.fleet.node", fleet_params), folder, "robot_fleet")
        deadline = time.monotonic() + START_ALLOWANCE_S + len(starts) * (seconds + 1.0)
        with tqdm(total=len(starts), desc="fleet episodes", unit="episode", disable=not progress) as bar:
            while fleet.alive():
                if not policy.alive():
                    raise RuntimeError(f"policy_node exited (code {policy.proc.returncode}) during the fleet run:\n"
                                       f"{policy.tail()}")
                if time.monotonic() > deadline:
                    raise RuntimeError(f"robot_fleet did not finish {len(starts)} episodes in time:\n{fleet.tail()}")
                bar.update(_episodes_done(summary_path) - bar.n)
                time.sleep(0.2)
            bar.update(_episodes_done(summary_path) - bar.n)
        if fleet.proc.returncode != 0:
            raise RuntimeError(f"robot_fleet exited with code {fleet.proc.returncode}:\n{fleet.tail()}")
    finally:
        if fleet is not None:
            fleet.stop()
        policy.stop()
    summary = json.loads(summary_path.read_text())
    if not summary.get("complete"):
        raise RuntimeError(f"robot_fleet's summary {summary_path} is incomplete: {len(summary['episodes'])} of "
                           f"{len(starts)} episodes")
    return summary


def _episodes_done(path: Path) -> int:
    try:
        return len(json.loads(path.read_text())["episodes"])
    except (OSError, ValueError, KeyError):
        return 0  # not written yet, or being replaced this instant
