"""Bad input to real sim_node and policy_node processes: refused with the reason, nothing changes.

Covers what test_sim_node*.py, test_policy_sim_node.py and test_policy_node.py
do not: huge (finite) Twist components, per-agent warnings that name the
value, Foxglove twists with huge values, publishers on topics of agents that
do not exist or with the wrong message type (sim_node's commands, policy_node's
observations), runtime parameter changes that are ill-typed, out of range or
read-only (paths included), and start-up refusals for wrong types, ranges,
typos, nested keys, corrupt or missing parameter files, corrupt policy files
and worlds too large to build.
"""
from __future__ import annotations

import asyncio
import math
import socket
import time
from pathlib import Path
from typing import List

import pytest
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float32MultiArray

from test.foxglove_client import FoxClient
from test.ros.conftest import NODE, SimProcess, sim_argv, stamp_ns, wait_all
from test.ros.policy_files import constant_push
from test.ros.policy_process import PolicyProcess

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SEED = 2  # simple_spread: no two agents touch, so agents without a command stay exactly still


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def speed(m: Odometry) -> float:
    return math.hypot(m.twist.twist.linear.x, m.twist.twist.linear.y)


def finite(m: Odometry) -> bool:
    p, t = m.pose.pose.position, m.twist.twist.linear
    return all(math.isfinite(v) for v in (p.x, p.y, t.x, t.y, m.twist.twist.angular.z))


def twist(vx=0.0, vy=0.0, wz=0.0) -> Twist:
    msg = Twist()
    msg.linear.x, msg.linear.y, msg.angular.z = vx, vy, wz
    return msg


# ================================================================ one running sim_node
@pytest.fixture(scope="module")
def port() -> int:
    return free_port()


@pytest.fixture(scope="module")
def sim(ros, sim_node, port):
    """simple_spread, control zero, Foxglove exposed on every interface (to check the warning)."""
    with sim_node(scenario="simple_spread", seed=SEED, control="zero", rate_hz=20.0,
                  foxglove_port=port, foxglove_host="0.0.0.0") as process:
        yield process


def publish_for(ros, publishers_messages, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for publisher, msg in publishers_messages:
            publisher.publish(msg)
        ros.spin_for(0.05)


class TestCommands:
    def test_foxglove_twist_with_huge_values_is_dropped(self, ros, sim, port):
        # first in the class: later tests drive agent_0, which could then bump into agent_2
        # the warning is logged while the node starts: wait for it rather than race the output pipe
        ros.spin_until(lambda: "Foxglove server listens on 0.0.0.0: anyone who reaches that address" in sim.output(),
                       10, "the exposed-port warning")

        async def main():
            async with FoxClient(port) as client:
                await client.wait_for(lambda: client.server_info is not None)
                await client.advertise(1, "/agent_2/cmd_vel")
                await client.publish(1, b'{"linear": {"x": 1e300, "y": 0, "z": 0}, "angular": {"z": 0}}')
                await asyncio.sleep(0.3)

        asyncio.run(asyncio.wait_for(main(), 20))
        ros.spin_until(lambda: "huge values for agent_2 (Foxglove): linear.x=1e+300" in sim.output(), 5,
                       "the Foxglove warning")
        odom = ros.collect(Odometry, "/agent_2/odom")
        try:
            odom.wait_for(3)
            assert all(finite(m) and speed(m) < 1e-6 for m in odom.messages)
        finally:
            odom.destroy()

    def test_huge_and_non_finite_twists_are_dropped_per_agent(self, ros, sim):
        odom = {a: ros.collect(Odometry, f"/{a}/odom") for a in ("agent_0", "agent_1")}
        pubs = {a: ros.node.create_publisher(Twist, f"/{a}/cmd_vel", 10) for a in ("agent_0", "agent_1")}
        try:
            ros.spin_until(lambda: all(p.get_subscription_count() for p in pubs.values()), 10, "cmd_vel matching")
            for c in odom.values():
                c.wait_for(1)
            # 1e300 is a finite double but overflows float32: it used to become inf, then NaN in the controller
            bad = [(pubs["agent_0"], twist(vx=1e30)), (pubs["agent_0"], twist(vy=1e300)),
                   (pubs["agent_1"], twist(vx=0.2, wz=-math.inf))]
            publish_for(ros, bad, 1.0)
            log = lambda: sim.output()  # noqa: E731
            ros.spin_until(lambda: "huge values for agent_0" in log() and "NaN or inf for agent_1" in log(), 5,
                           "a warning for each agent")
            text = log()
            assert "dropped a cmd_vel with huge values for agent_0 (/agent_0/cmd_vel): linear.x=1e+30; " \
                   "expected finite values with |value| <= 1e+06" in text, text
            assert "dropped a cmd_vel with NaN or inf for agent_1 (/agent_1/cmd_vel): angular.z=-inf" in text, text
            assert text.count("with huge values for agent_0") == 1, "throttled per agent"
            for c in odom.values():
                c.wait_for(len(c) + 3)
                assert all(finite(m) for m in c.messages)
                assert max(speed(m) for m in c.messages) < 1e-6, "a dropped command must not move the agent"
            publish_for(ros, [(pubs["agent_0"], twist(vx=1e5))], 0.6)  # huge but allowed: clamped force
            odom["agent_0"].wait_until(lambda m: speed(m) > 0.05, 5, "a large valid command to act")
            assert all(finite(m) for m in odom["agent_0"].messages)
        finally:
            for p in pubs.values():
                ros.node.destroy_publisher(p)
            for c in odom.values():
                c.destroy()

    def test_subscribers_asking_more_than_the_node_offers_are_named(self, ros, sim):
        """The state topics have no per-round QoS event handlers (they cost every executor round); the
        node's QoS audit names a subscriber that can never receive instead (here: transient-local on a
        volatile topic), once."""
        from rclpy.qos import DurabilityPolicy, QoSProfile

        wants_history = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        subscription = ros.node.create_subscription(Odometry, "/agent_1/odom", lambda _msg: None, wants_history)
        try:
            warning = (f"the subscriber /{ros.node.get_name()} of /agent_1/odom receives nothing: it requests "
                       "transient-local durability and the topic is volatile")
            ros.spin_until(lambda: warning in sim.output(), 10, "the QoS warning")
            ros.spin_for(4.5)  # two more audits: still one warning
            assert sim.output().count(warning) == 1
        finally:
            ros.node.destroy_subscription(subscription)

    def test_publishers_of_unknown_agents_and_wrong_types_are_named(self, ros, sim):
        publishers = [
            ros.node.create_publisher(Twist, "/agent_9/cmd_vel", 10),
            ros.node.create_publisher(TwistStamped, "/agent_1/cmd_vel", 10),
            ros.node.create_publisher(Twist, "/agent_2/action", 10),
            ros.node.create_publisher(Float32MultiArray, "/agent_1/action", 10),
        ]
        try:
            expected = [
                "ignoring a publisher of geometry_msgs/msg/Twist on /agent_9/cmd_vel: there is no agent 'agent_9' "
                "(agents: agent_0, agent_1, agent_2)",
                "ignoring a publisher of geometry_msgs/msg/TwistStamped on /agent_1/cmd_vel: expected "
                "geometry_msgs/msg/Twist",
                "ignoring a publisher of geometry_msgs/msg/Twist on /agent_2/action: expected "
                "std_msgs/msg/Float32MultiArray",
            ]
            ros.spin_until(lambda: all(e in sim.output() for e in expected), 10, "warnings naming each publisher")
            ros.spin_until(lambda: publishers[3].get_subscription_count() > 0, 10, "the action subscription")
            wrong = Float32MultiArray(data=[0.5, 0.0, 0.25, 9.0, 1.0])  # another agent's (or no) layout
            publish_for(ros, [(publishers[3], wrong)], 0.5)
            ros.spin_until(lambda: "dropped an action for agent_1 on /agent_1/action: expected 2 finite values, "
                                   "got 5 values ([0.5, 0, 0.25, 9, 1])" in sim.output(), 5, "the action warning")
            text = sim.output()
            assert "Float32MultiArray on /agent_1/action" not in text, "a matching publisher is not reported"
            assert sum(e in text for e in expected) == 3 and text.count("/agent_9/cmd_vel") == 1, "once each"
            assert sim.alive()
        finally:
            for p in publishers:
                ros.node.destroy_publisher(p)


class TestRuntimeParameters:
    BAD = [
        ("rate_hz", 1e-12, "[0.001, 1e+06]"),  # rclpy cannot hold 1e12 s in int64 ns: used to kill the timer
        ("rate_hz", "fast", "finite number"),
        ("real_time_factor", 1e9, "[0.001, 1e+06]"),
        ("cmd_vel_timeout", True, "finite number"),
        ("env_index", 1.5, "integer"),
        ("control", 3, "string"),
        ("record_path", "/tmp/elsewhere.mcap", "read-only"),  # start-only: read-only descriptors
        ("policy_path", "/etc/passwd", "read-only"),
        ("foxglove_host", "0.0.0.0", "read-only"),
        ("foxglove_port", 9999, "read-only"),
        ("num_envs", 1_000_000_000_000, "read-only"),
    ]

    def test_refused_with_a_reason_and_nothing_changes(self, ros, sim):
        names = sorted({name for name, _, _ in self.BAD})
        before = dict(zip(names, ros.get_parameters(NODE, *names)))
        clock = ros.collect(Clock, "/clock")
        try:
            for name, value, fragment in self.BAD:
                result, = ros.set_parameters(NODE, **{name: value})
                assert not result.successful, (name, value)
                assert name in result.reason and fragment in result.reason, (name, value, result.reason)
            result, = ros.set_parameters(NODE, bogus_parameter=1)
            assert not result.successful, "an undeclared parameter is refused"
            # atomically, several at once: one bad value refuses the whole set
            request = SetParametersAtomically.Request(parameters=[
                Parameter("cmd_vel_timeout", value=0.7).to_parameter_msg(),
                Parameter("rate_hz", value=-1.0).to_parameter_msg()])
            result = ros.call(SetParametersAtomically, f"{NODE}/set_parameters_atomically", request).result
            assert not result.successful and "rate_hz must be 0 (off) or in" in result.reason, result.reason
            assert dict(zip(names, ros.get_parameters(NODE, *names))) == before
            assert ros.get_parameters(NODE, "cmd_vel_timeout") == [0.5]
            start = stamp_ns(clock.wait_for(1)[-1].clock)
            ros.spin_for(1.0)
            advanced = (stamp_ns(clock.latest.clock) - start) / 1e9
            assert advanced >= 0.5, f"still stepping at 20 Hz after the refusals ({advanced:.2f} sim s in 1 s)"
            assert "refused parameter change: rate_hz must be 0 (off) or in [0.001, 1e+06], got 1e-12" in sim.output()
            assert sim.alive()
        finally:
            clock.destroy()


# =========================================================== refused at start (sim_node)
@pytest.fixture(scope="module")
def bad_files(tmp_path_factory) -> dict:
    d = tmp_path_factory.mktemp("bad_input")
    corrupt_yaml = d / "corrupt.yaml"
    corrupt_yaml.write_text("sim_node:\n  ros__parameters:\n    num_envs: [1, 2\n")
    nested_yaml = d / "nested.yaml"
    nested_yaml.write_text("sim_node:\n  ros__parameters:\n    num_envs: {a: 1}\n")
    corrupt_policy = d / "corrupt_policy.json"
    corrupt_policy.write_text('{"format": "vmas_ros.policy", "version": ')
    link = d / "link.mcap"
    link.symlink_to(d / "elsewhere" / "target.mcap")  # dangling: the recorder would create the target
    return dict(dir=d, corrupt_yaml=corrupt_yaml, nested_yaml=nested_yaml, corrupt_policy=corrupt_policy,
                link=link, good_policy=constant_push(d, "good", [0.1, 0.0]))


class ParamsFileProcess(SimProcess):
    """sim_node started with ``--params-file params["__file"]`` and then the other ``-p`` values."""

    @staticmethod
    def argv(params):
        values = {k: v for k, v in params.items() if k != "__file"}
        return sim_argv(values) + ["--params-file", params["__file"]]


@pytest.fixture(scope="module")
def refused(sim_process, sim_log_dir, bad_files):
    """Every refusing process, started together and awaited together (start-up dominates the time)."""
    f = bad_files
    # every bad value in one node (a file with a nested key, then -p values): the refusal lists each
    values = dict(__file=str(f["nested_yaml"]), num_envs="four", lidar_range=-1.0, foxglove_port=70000,
                  rate_hz=1e-12, seed=-1, lidar_rays=100000, scenario="nope", record_path=str(f["link"]),
                  policy_path=str(f["dir"] / "model.pt"), num_env=4)
    processes = {
        "values": ParamsFileProcess(None, values, sim_log_dir, "params_values"),
        "corrupt policy": sim_process(policy_path=str(f["corrupt_policy"])),
        "huge world": sim_process(scenario_kwargs={"n_agents": 1_000_000_000}),  # refused before it is built
        "corrupt_yaml": ParamsFileProcess(None, {"__file": str(f["corrupt_yaml"])}, sim_log_dir, "params_corrupt"),
        "missing_yaml": ParamsFileProcess(None, {"__file": str(f["dir"] / "missing.yaml")}, sim_log_dir,
                                          "params_missing"),
        "policy_node values": PolicyProcess(
            None, {"policy_path": str(f["good_policy"]), "rate_hz": "fast", "cmd_vel_scale": -1.0,
                   "outptu": "cmd_vel"}, sim_log_dir, "policy_bad_values"),
    }
    try:
        codes = wait_all(processes.values(), timeout=90.0)
    finally:
        for p in processes.values():
            p.kill()
    return {name: (p, code) for (name, p), code in zip(processes.items(), codes)}


START_CASES = {
    "values": ["sim_node: refused parameters:",
               "num_envs must be an integer, got 'four'", "lidar_range must be > 0, got -1.0",
               "foxglove_port must be in [0, 65535] (0: off), got 70000",
               "rate_hz must be 0 (off) or in [0.001, 1e+06], got 1e-12", "seed must be in [0, 4294967295], got -1",
               "lidar_rays must be in [1, 4096], got 100000", "unknown scenario 'nope'; valid scenarios: asym_joint, balance,",
               "simple_spread", "is a symlink", "policy_path must end in .json or .onnx",
               "unknown parameter 'num_env' (did you mean 'num_envs'?)",
               "num_envs must be a single value, got a nested key 'num_envs.a'"],
    "corrupt policy": ["refused parameters: policy_path: cannot load policy", "not valid JSON"],
    "huge world": ["sim_node: refused parameters: cannot build scenario 'simple_spread': scenario kwarg "
                   "n_agents=1,000,000,000 is over the limit of 10,000; set VMAS_ROS_ALLOW_LARGE_WORLDS=1"],
    "corrupt_yaml": ["sim_node: refused arguments:", "Couldn't parse params file", "corrupt.yaml"],
    "missing_yaml": ["sim_node: refused arguments:", "missing.yaml"],
    "policy_node values": ["policy_node: refused parameters:", "unknown parameter 'outptu' (did you mean 'output'?)",
                           "rate_hz must be a finite number, got 'fast'", "cmd_vel_scale must be > 0, got -1.0"],
}


@pytest.mark.parametrize("case", list(START_CASES))
def test_refused_at_start_with_code_2_and_the_reason(refused, case):
    process, code = refused[case]
    assert code == 2, process.describe()
    stderr = process.stderr()
    missing: List[str] = [fragment for fragment in START_CASES[case] if fragment not in stderr]
    assert not missing, f"{missing} not in:\n{stderr}"
    assert "Traceback" not in stderr, stderr


# ====================================================== policy_node at runtime
def test_policy_node_refuses_bad_runtime_parameters(ros, sim_log_dir, bad_files):
    with PolicyProcess(ros, {"policy_path": str(bad_files["good_policy"])}, sim_log_dir, "policy_runtime") as node:
        node.wait_publishing(["/agent_0/action"])
        for name, value, fragment in [("rate_hz", 1e-12, "out of range"), ("rate_hz", "x", "finite number"),
                                      ("cmd_vel_scale", -2.0, "> 0"), ("output", "cmd_vel", "read-only"),
                                      ("policy_path", "/etc/passwd", "read-only"), ("adapter", "os:system", "read-only")]:
            result, = ros.set_parameters("/policy_node", **{name: value})
            assert not result.successful and name in result.reason and fragment in result.reason, result.reason
        assert ros.get_parameters("/policy_node", "rate_hz", "cmd_vel_scale", "output") == [10.0, 1.0, "action"]
        assert "refused parameter change: rate_hz must be in [0.001, 1000], got 1e-12" in node.output()
        assert node.alive()


def test_policy_node_names_publishers_of_the_wrong_type_on_its_inputs(ros, sim_log_dir, bad_files):
    """ROS never delivers a Twist to policy_node's Float32MultiArray observation subscription: say so, once."""
    wrong = ros.node.create_publisher(Twist, "/agent_1/observation", 10)
    right = ros.node.create_publisher(Float32MultiArray, "/agent_0/observation", 10)
    try:
        with PolicyProcess(ros, {"policy_path": str(bad_files["good_policy"])}, sim_log_dir, "policy_audit") as node:
            node.wait_publishing(["/agent_0/action"])
            warning = ("ignoring a publisher of geometry_msgs/msg/Twist on /agent_1/observation: expected "
                       "std_msgs/msg/Float32MultiArray; policy_node never receives its messages")
            ros.spin_until(lambda: warning in node.output(), 10, "the wrong-type warning")
            ros.spin_for(4.5)  # two more audits: still one warning
            text = node.output()
            assert text.count("ignoring a publisher") == 1, text
            assert "on /agent_0/observation" not in text, "a publisher of the right type is not reported"
            assert node.alive()
    finally:
        ros.node.destroy_publisher(wrong)
        ros.node.destroy_publisher(right)
