"""Fixtures for sim_node integration tests: a test-side rclpy node and a sim_node process factory.

``ros`` is one rclpy context + node + executor per test module (its own
context, no signal handlers, so pytest's Ctrl-C stays pytest's).
``sim_node(**params)`` starts ``python -m vmas_ros.ros.sim_node`` as a separate
process with those ``-p name:=value`` overrides, in the session's
ROS_DOMAIN_ID, waits until its topics and services are discovered, and is a
context manager: leaving it sends SIGINT and asserts exit code 0. Any process
still running when the module ends is killed, so nothing leaks.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable, Dict, Iterable, List, Optional

import pytest

# ROS 2 is part of the test set-up (the `ros` extra): without it these tests must fail, not vanish
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from vmas_ros.rostools.dds_clean import remove_stuck_segments

REPO = Path(__file__).resolve().parents[2]
DISCOVERY_TIMEOUT = 20.0
NODE = "/sim_node"

#: topics every simple_spread sim_node has (name -> type), for the readiness wait
READY_TOPICS = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/agents/poses": "geometry_msgs/msg/PoseArray",
    "/landmarks/poses": "geometry_msgs/msg/PoseArray",
    "/world/markers": "visualization_msgs/msg/MarkerArray",
    "/agent_0/pose": "geometry_msgs/msg/PoseStamped",
    "/agent_0/odom": "nav_msgs/msg/Odometry",
    "/agent_0/cmd_vel": "geometry_msgs/msg/Twist",
}
READY_SERVICES = {
    f"{NODE}/reset": "std_srvs/srv/Trigger",
    f"{NODE}/pause": "std_srvs/srv/SetBool",
    f"{NODE}/step": "std_srvs/srv/Trigger",
    f"{NODE}/set_parameters": "rcl_interfaces/srv/SetParameters",
}


def stamp_ns(stamp) -> int:
    """builtin_interfaces/Time as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class Collector:
    """Every message received on one topic, with its wall-clock arrival time."""

    def __init__(self, ros: "Ros", msg_type, topic: str, depth: int = 1000) -> None:
        self.ros, self.topic = ros, topic
        self.messages: List = []
        self.arrivals: List[float] = []
        qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
        self.subscription = ros.node.create_subscription(msg_type, topic, self._on_message, qos)

    def _on_message(self, msg) -> None:
        self.messages.append(msg)
        self.arrivals.append(time.monotonic())

    def __len__(self) -> int:
        return len(self.messages)

    @property
    def latest(self):
        return self.messages[-1] if self.messages else None

    def clear(self) -> None:
        self.messages.clear()
        self.arrivals.clear()

    def since(self, wall: float) -> List:
        """Messages that arrived after monotonic time ``wall``."""
        return [m for m, t in zip(self.messages, self.arrivals) if t > wall]

    def wait_for(self, count: int = 1, timeout: float = 10.0) -> List:
        self.ros.spin_until(lambda: len(self.messages) >= count, timeout, f"{count} messages on {self.topic}")
        return self.messages

    def wait_until(self, predicate: Callable, timeout: float = 10.0, what: str = "") -> object:
        """The first message (scanning from the newest backlog on) for which predicate is true."""
        seen = [0]

        def check():
            for msg in self.messages[seen[0]:]:
                seen[0] += 1
                if predicate(msg):
                    return msg
            return None

        return self.ros.spin_until(check, timeout, what or f"a matching message on {self.topic}")

    def destroy(self) -> None:
        self.ros.node.destroy_subscription(self.subscription)


class Ros:
    """A test-side rclpy node in its own context, spun on demand."""

    def __init__(self) -> None:
        remove_stuck_segments()  # as sim_env() does for child processes
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(f"vmas_ros_test_{os.getpid()}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    # ------------------------------------------------------------------ spinning
    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.executor.spin_once(timeout_sec=min(left, 0.05))

    def spin_until(self, predicate: Callable, timeout: float, what: str = "condition"):
        """Spin until ``predicate()`` is truthy; return its value, or fail after ``timeout`` s."""
        end = time.monotonic() + timeout
        while True:
            value = predicate()
            if value:
                return value
            if time.monotonic() > end:
                raise AssertionError(f"timed out after {timeout:.1f} s waiting for {what}")
            self.executor.spin_once(timeout_sec=0.02)

    # --------------------------------------------------------------------- graph
    def topics(self) -> Dict[str, List[str]]:
        return dict(self.node.get_topic_names_and_types())

    def services(self) -> Dict[str, List[str]]:
        return dict(self.node.get_service_names_and_types())

    # ------------------------------------------------------------ communication
    def collect(self, msg_type, topic: str, depth: int = 1000) -> Collector:
        return Collector(self, msg_type, topic, depth)

    def publish_for(self, msg_type, topic: str, message, seconds: float, period: float = 0.05) -> None:
        """Publish ``message`` on ``topic`` every ``period`` s for ``seconds``, spinning meanwhile
        (a command held, as a teleop would); the publisher is gone afterwards."""
        publisher = self.node.create_publisher(msg_type, topic, 10)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            publisher.publish(message)
            self.spin_for(period)
        self.node.destroy_publisher(publisher)

    def call(self, srv_type, name: str, request=None, timeout: float = 10.0):
        client = self.node.create_client(srv_type, name)
        try:
            self.spin_until(client.service_is_ready, timeout, f"service {name}")
            future = client.call_async(request if request is not None else srv_type.Request())
            self.spin_until(future.done, timeout, f"a response from {name}")
            return future.result()
        finally:
            self.node.destroy_client(client)

    def set_parameters(self, node: str, **values):
        """SetParameters on ``node`` (e.g. "/sim_node"); one SetParametersResult per value."""
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        request = SetParameters.Request()
        request.parameters = [Parameter(name, value=value).to_parameter_msg() for name, value in values.items()]
        return self.call(SetParameters, f"{node}/set_parameters", request).results

    def get_parameters(self, node: str, *names: str) -> list:
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python

        request = GetParameters.Request(names=list(names))
        return [parameter_value_to_python(v) for v in self.call(GetParameters, f"{node}/get_parameters", request).values]


def format_param(value) -> str:
    """A ``-p`` value as YAML that rcl parses to the intended type (strings single-quoted)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, dict):
        value = json.dumps(value)
    return "'" + str(value).replace("'", "''") + "'"


def sim_env() -> Dict[str, str]:
    """The environment of a ROS process a test starts; first sweeps away Fast DDS segments that a
    killed process left half made, which would hang the new process at start-up (every process
    start in the tests builds its environment here)."""
    remove_stuck_segments()
    env = dict(os.environ)
    env["RMW_IMPLEMENTATION"] = "rmw_fastrtps_cpp"
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    assert env.get("ROS_DOMAIN_ID"), "the session conftest sets ROS_DOMAIN_ID"
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


def sim_argv(params: Dict[str, object]) -> List[str]:
    argv = [sys.executable, "-m", "vmas_ros.ros.sim_node", "--ros-args"]
    for name, value in params.items():
        argv += ["-p", f"{name}:={format_param(value)}"]
    return argv


class SimProcess:
    """One ``sim_node`` process; stdout and stderr go to files under ``log_dir``."""

    #: run in the child before the node starts (e.g. to set a resource limit); None: nothing
    preexec: Optional[Callable[[], None]] = None

    def __init__(self, ros: Optional[Ros], params: Dict[str, object], log_dir: Path, label: str) -> None:
        self.ros, self.params = ros, dict(params)
        log_dir.mkdir(parents=True, exist_ok=True)
        self.stdout_path = log_dir / f"{label}.stdout.log"
        self.stderr_path = log_dir / f"{label}.stderr.log"
        self._stdout = open(self.stdout_path, "wb")
        self._stderr = open(self.stderr_path, "wb")
        self.started = time.monotonic()
        self.proc = subprocess.Popen(
            self.argv(self.params), cwd=REPO, env=sim_env(),
            stdin=subprocess.DEVNULL, stdout=self._stdout, stderr=self._stderr, preexec_fn=self.preexec,
        )
        self.returncode: Optional[int] = None

    # ----------------------------------------------------------------- output
    @staticmethod
    def argv(params: Dict[str, object]) -> List[str]:
        """The command line of the node this class runs (subclasses run other nodes)."""
        return sim_argv(params)

    def stdout(self) -> str:  # the child writes through its own descriptors: nothing to flush here
        return self.stdout_path.read_text(errors="replace")

    def stderr(self) -> str:
        return self.stderr_path.read_text(errors="replace")

    def output(self) -> str:
        return self.stdout() + self.stderr()

    def describe(self) -> str:
        tail = "\n".join(self.output().splitlines()[-30:])
        return f"sim_node {self.params} (pid {self.proc.pid}, rc {self.proc.poll()}); output tail:\n{tail}"

    # ------------------------------------------------------------- lifecycle
    def alive(self) -> bool:
        return self.proc.poll() is None

    def wait_ready(self, topics: Dict[str, str] = READY_TOPICS, services: Dict[str, str] = READY_SERVICES,
                   timeout: float = DISCOVERY_TIMEOUT) -> None:
        ros = self.ros

        def ready():
            if not self.alive():
                raise AssertionError(f"sim_node exited during start-up: {self.describe()}")
            found = ros.topics()
            if any(t not in found.get(name, []) for name, t in topics.items()):
                return False
            if any(ros.node.count_publishers(name) == 0 for name in topics if not name.endswith("cmd_vel")):
                return False
            if any(ros.node.count_subscribers(name) == 0 for name in topics if name.endswith("cmd_vel")):
                return False
            found = ros.services()
            return all(t in found.get(name, []) for name, t in services.items())

        try:
            ros.spin_until(ready, timeout, "sim_node's topics and services")
        except AssertionError as error:
            raise AssertionError(f"{error}\n{self.describe()}") from None

    def send(self, sig: int) -> None:
        if self.alive():
            self.proc.send_signal(sig)

    def wait(self, timeout: float) -> int:
        """Exit code, spinning the test node meanwhile; fails (after a kill) on timeout."""
        end = time.monotonic() + timeout
        while self.alive() and time.monotonic() < end:
            if self.ros is not None:
                self.ros.spin_for(0.05)
            else:
                time.sleep(0.05)
        if self.alive():
            self.kill()
            raise AssertionError(f"sim_node did not exit within {timeout} s: {self.describe()}")
        self.returncode = self.proc.returncode
        self._close_logs()
        return self.returncode

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        """Signal it, wait for the exit, then for its endpoints to leave the graph."""
        if self.returncode is None:
            self.send(sig)
            self.wait(timeout)
            self._wait_gone()
        return self.returncode

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        self._close_logs()

    def _close_logs(self) -> None:
        for f in (self._stdout, self._stderr):
            if not f.closed:
                f.close()

    def _wait_gone(self, timeout: float = 10.0) -> None:
        # The next process in this domain reuses every name: don't let it be
        # "discovered" through this one's lingering endpoints.
        if self.ros is None:
            return
        try:
            self.ros.spin_until(
                lambda: self.ros.node.count_publishers("/clock") == 0 and f"{NODE}/reset" not in self.ros.services(),
                timeout, "the stopped sim_node to leave the ROS graph",
            )
        except AssertionError:
            pass  # discovery of the next node also checks liveness; not worth failing teardown

    # -------------------------------------------------------- context manager
    def __enter__(self) -> "SimProcess":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.returncode is not None:
            return
        try:
            code = self.stop(signal.SIGINT)
        finally:
            self.kill()
        assert code == 0, f"sim_node exited with {code} after SIGINT: {self.describe()}"


@pytest.fixture(scope="module")
def ros():
    harness = Ros()
    yield harness
    harness.close()


@pytest.fixture(scope="module")
def rclpy_context():
    """An rclpy context of the module's own, for nodes built in the test process (no signal handlers)."""
    remove_stuck_segments()  # as sim_env() does for child processes
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    yield context
    rclpy.shutdown(context=context)


@pytest.fixture
def on_test_context(rclpy_context, monkeypatch):
    """Nodes built during the test join ``rclpy_context`` (SimNode builds its rclpy Node on the default one)."""
    init = rclpy.node.Node.__init__

    def on_context(self, *args, **kwargs):
        kwargs.setdefault("context", rclpy_context)
        return init(self, *args, **kwargs)

    monkeypatch.setattr(rclpy.node.Node, "__init__", on_context)
    return rclpy_context


@pytest.fixture(scope="module")
def sim_log_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("sim_node_logs")


def killed_at_end(make: Callable[..., object]):
    """A factory fixture's body: yields ``start(**params)``, which calls ``make(index, **params)``
    (``index`` counts the processes started so far) and keeps the process it returns; every
    one of them is killed when the fixture ends, whatever the test did."""
    started: list = []

    def start(**params):
        process = make(len(started), **params)
        started.append(process)
        return process

    try:
        yield start
    finally:
        for process in started:
            process.kill()


@pytest.fixture(scope="module")
def sim_node(ros, sim_log_dir):
    """Factory: ``with sim_node(seed=5, lidar_rays=12) as sim: ...`` (started and discovered)."""
    def make(index: int, ready_topics: Optional[Dict[str, str]] = None, **params) -> SimProcess:
        process = SimProcess(ros, params, sim_log_dir, f"sim_node_{index}")
        try:
            process.wait_ready(READY_TOPICS if ready_topics is None else ready_topics)
        except BaseException:
            process.kill()
            raise
        return process

    yield from killed_at_end(make)


@pytest.fixture(scope="module")
def sim_process(sim_log_dir):
    """Factory for processes expected to fail at start: no discovery wait, killed at the end."""
    yield from killed_at_end(lambda index, **params: SimProcess(None, params, sim_log_dir, f"bad_sim_node_{index}"))


def wait_all(processes: Iterable[SimProcess], timeout: float) -> List[int]:
    end = time.monotonic() + timeout
    return [p.wait(max(0.1, end - time.monotonic())) for p in processes]
