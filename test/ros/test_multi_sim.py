"""Two sim_nodes in one ROS graph: namespaces keep topics, commands and tools apart, and one node owns /clock."""
from __future__ import annotations

import math
import os
import signal

import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry

from test.ros.fault_tools import FaultProcess, assert_whole_steps, read_finished
from test.ros.test_sim_node_foxglove import _free_port, _wait_listening
from test.ros.sim_node_helpers import DT_NS
from test.ros.test_rostools import vmas_ros_cli
from vmas_ros.rostools import param

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _moved(start: PoseStamped, end: PoseStamped) -> float:
    return math.hypot(end.pose.position.x - start.pose.position.x, end.pose.position.y - start.pose.position.y)


def test_two_namespaced_nodes_share_one_clock_and_keep_commands_apart(ros, sim_log_dir, tmp_path):
    bag = tmp_path / "follower.mcap"
    port = _free_port()
    owner = FaultProcess(ros, {"seed": 1, "foxglove_port": port, "record_path": str(tmp_path / "owner.mcap")},
                         sim_log_dir, "swarm_a")
    follower = None
    try:
        owner.wait_ready(timeout=60.0)
        _wait_listening(port)
        # a third node asking for the owner's Foxglove port or bag path is refused up front, naming the owner
        for clash, what in (({"foxglove_port": port}, "the port is in use by pid"),
                            ({"record_path": str(tmp_path / "owner.mcap"), "record_overwrite": True},
                             "is being recorded by pid")):
            refused = FaultProcess(ros, clash, sim_log_dir, "swarm_c")
            assert refused.wait(60) == 2, refused.describe()
            message = refused.stderr()
            assert f"{what} {owner.proc.pid} (" in message and "__ns:=/swarm_a" in message, message[-2000:]
        follower = FaultProcess(ros, {"seed": 2, "publish_clock": False, "record_path": str(bag)}, sim_log_dir,
                                "swarm_b")
        follower.wait_ready(timeout=60.0)
        poses = {label: ros.collect(PoseStamped, f"/{label}/agent_0/pose", depth=100)
                 for label in ("swarm_a", "swarm_b")}
        odometry = {label: ros.collect(Odometry, f"/{label}/agent_0/odom", depth=5) for label in ("swarm_a", "swarm_b")}
        for collected in [*poses.values(), *odometry.values()]:
            collected.wait_for(1, timeout=30.0)
        # each node's frames carry its namespace (frame_prefix: auto), so one TF tree holds both
        for label, collected in odometry.items():
            odom = collected.latest
            assert (odom.header.frame_id, odom.child_frame_id) == (f"{label}/world", f"{label}/agent_0/base_link")
            assert poses[label].latest.header.frame_id == f"{label}/world"
        # one clock in the graph: the owner's; the follower's topics sit under its own namespace
        assert ros.node.count_publishers("/clock") == 1
        topics = ros.topics()
        assert {"/swarm_a/agent_0/pose", "/swarm_b/agent_0/pose", "/swarm_b/agent_0/cmd_vel"} <= set(topics)
        # the pip users' ROS tools tell the two apart: absolute names and --namespace
        before = {label: collected.latest for label, collected in poses.items()}
        done = vmas_ros_cli("drive", "/swarm_a/agent_0", "--vx", "0.5", "--seconds", "1")
        assert done.returncode == 0 and "Twists to /swarm_a/agent_0/cmd_vel (1 subscriber)" in done.stdout, done
        ros.spin_for(0.5)
        after = {label: collected.latest for label, collected in poses.items()}
        assert _moved(before["swarm_a"], after["swarm_a"]) > 0.02, "the commanded node's agent_0 did not move"
        assert _moved(before["swarm_b"], after["swarm_b"]) < 1e-6, "a command for swarm_a moved swarm_b's agent"
        echo = vmas_ros_cli("echo", "agent_0/odom", "--namespace", "/swarm_b", "--count", "1")
        assert echo.returncode == 0 and "child_frame_id: 'swarm_b/agent_0/base_link'" in echo.stdout, echo
        assert [param.get_parameter(f"/{label}/sim_node", "publish_clock", out=print)
                for label in ("swarm_a", "swarm_b")] == [True, False]
        missing = vmas_ros_cli("drive", "agent_9", "--namespace", "/swarm_b", "--vx", "0.1", "--seconds", "0.1")
        assert missing.returncode == 1 and "nothing subscribes to /swarm_b/agent_9/cmd_vel" in missing.stderr, missing
        assert follower.stop(signal.SIGINT, timeout=30.0) == 0, follower.describe()
        assert owner.stop(signal.SIGINT, timeout=30.0) == 0, owner.describe()
    finally:
        owner.kill()
        if follower is not None:
            follower.kill()
    assert "publish_clock is false: /clock comes from another node" in follower.stderr()
    # the Foxglove owner says how to make a layout for its prefixed frames
    assert "make it with: vmas-ros foxglove-layout --frame-prefix swarm_a/ --agents" in owner.stderr()
    # the follower's bag keeps its own steps on /clock, though it never published one
    recorded = read_finished(bag)
    assert recorded.count("/clock") > 0
    assert_whole_steps(recorded, DT_NS, namespace="/swarm_b")
    _stamp, scan = recorded.messages["/swarm_b/agent_0/scan"][0]
    assert scan.header.frame_id == "swarm_b/agent_0/base_link"
    assert {t.header.frame_id for _, m in recorded.messages["/tf"] for t in m.transforms} == {"swarm_b/world"}


@pytest.mark.parametrize("value, refused", [("auto", False), ("", False), ("robot_a/", False), ("a/b_2/", False),
                                            ("/robot_a/", True), ("robot a/", True), ("a//b", True)])
def test_frame_prefix_values(value, refused):
    from vmas_ros.rostools.graph import frame_prefix_error

    message = frame_prefix_error(value)
    assert (message is not None) == refused
    if refused:
        assert repr(value) in message and "'robot_a/'" in message


def test_the_listener_of_a_port_is_named():
    import socket

    from vmas_ros.ros.port_owner import listener_of

    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        assert listener_of(port).startswith(f"pid {os.getpid()} (")
    assert listener_of(port) is None


def test_multi_sim_launch_file_starts_namespaced_nodes_with_known_parameters():
    """launch_scripts/multi_sim.launch.py, checked without `launch` (no PyPI wheels): its shape and parameters."""
    import ast
    from pathlib import Path

    from vmas_ros.ros.params import SimParams

    tree = ast.parse((Path(__file__).resolve().parents[2] / "launch_scripts" / "multi_sim.launch.py").read_text())
    assert "generate_launch_description" in {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Node"]
    assert len(calls) == 1
    keywords = {k.arg: k.value for k in calls[0].keywords}
    assert ast.literal_eval(keywords["executable"]) == "sim_node" and "namespace" in keywords
    keys = {k.value for node in ast.walk(tree) if isinstance(node, ast.Dict) for k in node.keys
            if isinstance(k, ast.Constant)}
    assert {"scenario", "seed", "publish_clock", "foxglove_port"} == keys and keys <= set(SimParams.names())
    arguments = {ast.literal_eval(node.args[0]) for node in ast.walk(tree)
                 if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "DeclareLaunchArgument"}
    assert arguments == {"count", "prefix", "scenario", "config", "seed", "foxglove_port"}
