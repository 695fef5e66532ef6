"""A SIGINT or SIGTERM in a node's first half second (while it imports torch and rclpy) is a clean stop.

Before the entry points installed their handler first (vmas_ros/ros/signal_guard.py),
such a signal gave a KeyboardInterrupt traceback from inside an import (exit 1
or death by SIGINT; once a process hung on an import lock) or death by
SIGTERM. Now it must give exit code 0, no traceback, one line saying so, and
no bag (none was begun). Importing takes more than a second here, so a signal
0.2 or 0.5 s after the launch lands in the imports. It is sent at that delay
once the process catches SIGTERM, i.e. once the interpreter has started and
run the entry point's first lines (about 50 ms alone; longer when seven start
on two busy cores): no program can catch a signal before it runs.

Both ways a node is started are covered: ``python -m vmas_ros.ros.sim_node``
(and policy_node) and the console script ``sim_node`` (what ``ros2 run``
starts), run through the entry point setup.py declares. All processes start at
once; they are stopped long before they would need ROS.
"""
from __future__ import annotations

import re
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List

import pytest

from test.ros.conftest import REPO, SimProcess, format_param
from test.ros.fault_tools import catches_sigterm

pytestmark = pytest.mark.ros


def console_script(name: str) -> List[str]:
    """The command a console script ``name`` runs: setup.py's ``module:function`` for it, called as pip's
    generated script calls it."""
    found = re.search(rf'"{name} = ([\w.]+):(\w+)"', (REPO / "setup.py").read_text())
    assert found, f"no console script {name} in setup.py"
    module, function = found.groups()
    return [sys.executable, "-c", f"import sys; from {module} import {function}; sys.exit({function}())"]


ENTRIES = {
    "sim_module": ("sim_node", [sys.executable, "-m", "vmas_ros.ros.sim_node"]),
    "sim_script": ("sim_node", console_script("sim_node")),
    "policy_module": ("policy_node", [sys.executable, "-m", "vmas_ros.ros.policy_node"]),
    "policy_script": ("policy_node", console_script("policy_node")),
}


class EarlyProcess(SimProcess):
    """A node started through ``command`` (an entry of ENTRIES) with ``-p`` parameters, in its own namespace."""

    def __init__(self, command: List[str], params: Dict[str, object], log_dir: Path, label: str) -> None:
        self.command, self.label = command, label
        super().__init__(None, params, log_dir, label)

    def argv(self, params: Dict[str, object]) -> List[str]:
        argv = self.command + ["--ros-args", "-r", f"__ns:=/{self.label}"]
        for name, value in params.items():
            argv += ["-p", f"{name}:={format_param(value)}"]
        return argv


@dataclass
class Case:
    entry: str
    sig: int
    delay: float  # seconds after the launch


CASES = {
    "sim_module_sigint_200ms": Case("sim_module", signal.SIGINT, 0.2),
    "sim_module_sigint_500ms": Case("sim_module", signal.SIGINT, 0.5),
    "sim_module_sigterm_500ms": Case("sim_module", signal.SIGTERM, 0.5),
    "sim_script_sigint_200ms": Case("sim_script", signal.SIGINT, 0.2),
    "sim_script_sigterm_500ms": Case("sim_script", signal.SIGTERM, 0.5),
    "policy_module_sigint_200ms": Case("policy_module", signal.SIGINT, 0.2),
    "policy_script_sigterm_500ms": Case("policy_script", signal.SIGTERM, 0.5),
}


@pytest.fixture(scope="module")
def early_runs(tmp_path_factory, sim_log_dir) -> Dict[str, tuple]:
    """Every case at once: launched together, each signalled at its delay, all awaited."""
    bags = tmp_path_factory.mktemp("early_bags")
    processes = {}
    for label, case in CASES.items():
        params = {"record_path": str(bags / f"{label}.mcap")} if case.entry.startswith("sim") else {}
        processes[label] = EarlyProcess(ENTRIES[case.entry][1], params, sim_log_dir, label)
    started = time.monotonic()
    pending, sent = dict(CASES), {}
    try:
        while pending:
            now = time.monotonic()
            for label, case in list(pending.items()):
                # at the delay, once the interpreter has started and the entry point's first lines ran
                # (a process that never catches SIGTERM gets its signal 10 s late, and fails below)
                process = processes[label]
                if now - started >= case.delay and (catches_sigterm(process.proc.pid) or not process.alive()
                                                    or now - started >= case.delay + 10.0):
                    process.send(case.sig)
                    sent[label] = now - started
                    del pending[label]
            time.sleep(0.005)
        codes = {label: process.wait(30.0) for label, process in processes.items()}
    finally:
        for process in processes.values():
            process.kill()
    print("\nsignalled after " + ", ".join(f"{label} {t:.2f} s" for label, t in sent.items()))
    return {label: (processes[label], codes[label], bags) for label in CASES}


@pytest.mark.parametrize("label", list(CASES))
def test_a_signal_during_the_imports_is_a_clean_stop(early_runs, label):
    process, code, bags = early_runs[label]
    case = CASES[label]
    node = ENTRIES[case.entry][0]
    stderr = process.stderr()
    assert code == 0, process.describe()
    assert "Traceback" not in stderr, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    name = signal.Signals(case.sig).name
    assert lines == [f"{node}: stopped by {name} during start-up, before the node existed (nothing was recorded)"], (
        stderr)
    assert not (bags / f"{label}.mcap").exists(), "no bag is begun before the node exists"


RUNNING = """
    import os, signal, sys, time
    from vmas_ros.ros import signal_guard
    signal_guard.guard("probe")
    import rclpy
    from geometry_msgs.msg import Twist
    from vmas_ros.record import McapRecorder
    rclpy.init()  # installs rclpy's handlers, chained in front of the guard
    signal_guard.hand_over()
    recorder = McapRecorder(sys.argv[1])
    recorder.write("/a", "geometry_msgs/msg/Twist", Twist(), 0)  # swapping handlers here would drop rclpy's
    try:
        with recorder.batch():  # a signal during a write is held until the write is complete
            os.kill(os.getpid(), signal.{sig})
            time.sleep(0.2)
            recorder.write("/a", "geometry_msgs/msg/Twist", Twist(), 1)
            print("WRITE COMPLETE", flush=True)
    except KeyboardInterrupt:
        print("HELD, THEN RAISED; rclpy", "shut down" if not rclpy.ok() else "still running", flush=True)
    recorder.close()
"""


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_once_running_a_signal_is_held_during_a_write_and_rclpys_handler_stays(tmp_path, sig):
    """After start-up the guard raises KeyboardInterrupt, but never inside a recorder write; and the
    recorder leaves rclpy's C handler in front of it, which shuts the context down and so wakes the
    executor at once (without it, a stop waited for the node's next timer)."""
    import subprocess
    import textwrap

    code = textwrap.dedent(RUNNING.format(sig=sig))
    result = subprocess.run([sys.executable, "-c", code, str(tmp_path / "held.mcap")], cwd=REPO,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["WRITE COMPLETE", "HELD, THEN RAISED; rclpy shut down"], (
        result.stdout + result.stderr)
