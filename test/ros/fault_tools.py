"""Shared pieces of the fault tests (test_faults_*.py): namespaced sim_node processes and bag checks.

Several sim_node processes run at once in one ROS domain to keep the fault
tests short, so each gets its own namespace (``-r __ns:=/<label>``): its
topics and services do not mix with the others' (only ``/clock`` is shared).

Bags are judged with independent readers: ``rosbags`` (which refuses a file
without its end magic, i.e. an unfinished one) deserialises every message,
and ``mcap``'s reader must find a summary whose statistics agree.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Set

from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from test.ros.conftest import NODE, READY_SERVICES, READY_TOPICS, SimProcess, format_param

MCAP_MAGIC = b"\x89MCAP0\r\n"
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
#: topics with exactly one message per recorded step (simple_spread, 3 agents; relative to the namespace)
PER_STEP = ("/tf", "/agents/poses", "/landmarks/poses", "/world/markers",
            *(f"/agent_{i}/{kind}" for i in range(3) for kind in ("pose", "odom", "scan", "observation")))


class FaultProcess(SimProcess):
    """sim_node (or ``module``, e.g. test.ros.faulty_sim) in namespace ``/<label>``."""

    def __init__(self, ros, params: Dict[str, object], log_dir: Path, label: str,
                 module: str = "vmas_ros.ros.sim_node") -> None:
        self.module, self.namespace = module, f"/{label}"
        super().__init__(ros, params, log_dir, label)

    def argv(self, params: Dict[str, object]) -> List[str]:  # an instance's own module and namespace
        argv = [sys.executable, "-m", self.module, "--ros-args", "-r", f"__ns:={self.namespace}"]
        for name, value in params.items():
            argv += ["-p", f"{name}:={format_param(value)}"]
        return argv

    def topic(self, name: str) -> str:
        return name if name == "/clock" else f"{self.namespace}{name}"

    def wait_ready(self, timeout: float = 30.0, **_) -> None:
        topics = {self.topic(t): kind for t, kind in READY_TOPICS.items()}
        services = {f"{self.namespace}{name}": kind for name, kind in READY_SERVICES.items()}
        super().wait_ready(topics, services, timeout)

    def _wait_gone(self, timeout: float = 10.0) -> None:
        service = f"{self.namespace}{NODE}/reset"
        end = time.monotonic() + timeout
        while service in self.ros.services() and time.monotonic() < end:
            self.ros.spin_for(0.05)


# ------------------------------------------------------------------ bag checks
@dataclass
class Bag:
    """What a finished bag holds: messages per topic, in order, deserialised."""

    path: Path
    messages: Dict[str, list] = field(default_factory=dict)  # topic -> [(log time ns, message)]
    types: Dict[str, str] = field(default_factory=dict)

    def count(self, topic: str) -> int:
        return len(self.messages.get(topic, []))

    @property
    def total(self) -> int:
        return sum(len(m) for m in self.messages.values())

    def steps(self) -> List[int]:
        """Log times of /clock: one per recorded step."""
        return [t for t, _ in self.messages.get("/clock", [])]


def is_finished(path: Path) -> bool:
    """Ends with the MCAP magic (the footer was written)."""
    with open(path, "rb") as f:
        if f.seek(0, 2) < 2 * len(MCAP_MAGIC):
            return False
        f.seek(-len(MCAP_MAGIC), 2)
        return f.read() == MCAP_MAGIC


def read_finished(path: Path) -> Bag:
    """Every message of a finished bag, read and deserialised by rosbags; fails on anything less.

    Also checks what makes the bag usable by ``ros2 bag`` and Foxglove without
    a rescan: the footer, and a summary whose statistics count the same messages.
    """
    path = Path(path)
    assert is_finished(path), f"{path} has no MCAP footer/end magic: it was not finished"
    bag = Bag(path)
    with AnyReader([path], default_typestore=TYPESTORE) as reader:
        bag.types = {c.topic: c.msgtype for c in reader.connections}
        for connection, timestamp, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            bag.messages.setdefault(connection.topic, []).append((timestamp, message))
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None, f"{path}: no summary section"
    assert summary.statistics.message_count == bag.total, (
        f"{path}: summary counts {summary.statistics.message_count} messages, rosbags read {bag.total}")
    return bag


def assert_whole_steps(bag: Bag, dt_ns: int, namespace: str = "") -> None:
    """Every recorded step is complete (no half step at the end) and steps follow each other by dt."""
    steps = bag.steps()
    assert steps == [k * dt_ns for k in range(len(steps))], f"{bag.path}: /clock log times are not 0, dt, 2 dt, ..."
    for topic in PER_STEP:
        topic = "/tf" if topic == "/tf" else f"{namespace}{topic}"
        times = [t for t, _ in bag.messages.get(topic, [])]
        assert times == steps, f"{bag.path}: {topic} has {len(times)} messages for {len(steps)} steps"


def recover_with_cli(path_in: Path, path_out: Path) -> dict:
    """``python -m vmas_ros.record.recover_cli IN OUT --json`` as a user runs it; returns its report."""
    import json
    import subprocess

    result = subprocess.run([sys.executable, "-m", "vmas_ros.record.recover_cli", str(path_in), str(path_out), "--json"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, f"bag-recover failed ({result.returncode}): {result.stderr}"
    return json.loads(result.stdout)


def sweep(directory: Path, killed: Iterable[str] = (), min_files: int = 1) -> Dict[str, str]:
    """No corrupted file left behind: every file under ``directory`` is a finished bag
    rosbags reads completely, or a log, or (named in ``killed``, from a SIGKILL) an
    unfinished bag that ``recover`` turns into a readable one. Returns name -> verdict."""
    from vmas_ros.record import recover

    killed_names: Set[str] = set(killed)
    verdicts: Dict[str, str] = {}
    files = sorted(p for p in Path(directory).rglob("*") if p.is_file())
    for path in files:
        name = path.name
        if name.endswith(".log"):
            continue
        assert name.endswith(".mcap"), f"unexpected file left behind: {path}"
        if name in killed_names:
            assert not is_finished(path), f"{path} was expected unfinished (SIGKILL)"
            out = path.parent.parent / f"sweep_{name}"
            out.unlink(missing_ok=True)
            report = recover(path, out)
            assert report["messages"] > 0, f"nothing recoverable in {path}: {report}"
            assert read_finished(out).total == report["messages"]
            out.unlink()
            verdicts[name] = f"recoverable ({report['messages']} messages)"
        else:
            verdicts[name] = f"finished ({read_finished(path).total} messages)"
    assert len(verdicts) >= min_files, f"expected at least {min_files} bags under {directory}, found {verdicts}"
    missing = killed_names - set(verdicts)
    assert not missing, f"killed bags not found: {missing}"
    return verdicts


def catches_sigterm(pid: int) -> bool:
    """Whether process ``pid`` has a handler for SIGTERM (Linux: the SigCgt mask in /proc/<pid>/status).

    Python itself catches only SIGINT; a node's entry point installs its SIGTERM (and SIGINT) handler
    first thing (vmas_ros/ros/signal_guard.py). Until then the interpreter is still starting, which no
    program can guard: tests that signal a node "during its imports" wait for this too."""
    import signal

    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("SigCgt:"):
                    return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    except (FileNotFoundError, ProcessLookupError):
        pass
    return False


def last_clock_ns(messages: list) -> Optional[int]:
    """Sim time of the newest rosgraph_msgs/Clock in ``messages`` (None if empty)."""
    if not messages:
        return None
    clock = messages[-1].clock
    return int(clock.sec) * 1_000_000_000 + int(clock.nanosec)
