"""policy_node + sim_node in separate processes: the loop closes over real ROS topics.

sim_node runs with ``control: zero`` (agents stand still unless commanded);
policy_node runs ``seek_landmark`` (steer to landmark 0), once on sim_node's
observation topics publishing raw actions, once through the simple_spread
adapter (odometry + landmark poses) publishing cmd_vel. Either way the agents
must close in on landmark 0, and only because of policy_node.
"""
from __future__ import annotations

import signal
import time

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray, Twist
from std_msgs.msg import Float32MultiArray
from std_srvs.srv import SetBool, Trigger

from test.ros.conftest import NODE, killed_at_end, wait_all
from test.ros.policy_files import constant_push, seek_landmark
from test.ros.policy_process import PolicyProcess

pytestmark = [pytest.mark.ros, pytest.mark.slow]

AGENTS = ["agent_0", "agent_1", "agent_2"]
SEED = 1  # the first layout is far from covered: every agent starts > 0.5 m from landmark 0


def positions(array: PoseArray) -> np.ndarray:
    return np.array([[p.position.x, p.position.y] for p in array.poses])


@pytest.fixture(scope="module")
def policy_node(ros, sim_log_dir):
    """Factory: ``with policy_node(policy_path=...) as node: ...`` (a policy_node process)."""
    yield from killed_at_end(lambda index, **params: PolicyProcess(ros, params, sim_log_dir, f"policy_node_{index}"))


@pytest.fixture(scope="module")
def world(ros, sim_node):
    with sim_node(scenario="simple_spread", seed=SEED, control="zero", rate_hz=20.0) as sim:
        yield sim


def agents_close_in_on_landmark_0(ros, timeout: float = 20.0) -> tuple:
    """Wait until every agent is much closer to landmark 0 (or all crowd around it); (before, after) distances.

    Three discs of radius 0.15 can all get within 0.4 m of one point, not all onto it.
    """
    agents = ros.collect(PoseArray, "/agents/poses")
    landmarks = ros.collect(PoseArray, "/landmarks/poses")
    try:
        agents.wait_for(1)
        landmarks.wait_for(1)
        goal = positions(landmarks.latest)[0]
        before = np.linalg.norm(positions(agents.latest) - goal, axis=1)

        def close():
            after = np.linalg.norm(positions(agents.latest) - goal, axis=1)
            return (after,) if (after < 0.6 * before).all() or (after < 0.4).all() else None

        try:
            (after,) = ros.spin_until(close, timeout, "the agents to close in on landmark 0")
        except AssertionError:
            raise AssertionError(f"from {before} to {np.linalg.norm(positions(agents.latest) - goal, axis=1)}")
        return before, after
    finally:
        agents.destroy()
        landmarks.destroy()


def fresh_layout(ros) -> None:
    assert ros.call(Trigger, f"{NODE}/reset").success
    ros.spin_for(0.5)


class TestClosedLoop:
    def test_policy_node_drives_sim_node_through_observation_and_action_topics(self, ros, world, policy_node,
                                                                                tmp_path):
        path = seek_landmark(tmp_path, "seek")
        actions = ros.collect(Float32MultiArray, "/agent_0/action")
        try:
            with policy_node(policy_path=str(path), rate_hz=10.0, observation_timeout=0.5) as node:
                node.wait_publishing([f"/{n}/action" for n in AGENTS])
                fresh_layout(ros)
                before, _ = agents_close_in_on_landmark_0(ros)
                assert (before > 0.5).any(), before
                assert len(actions) >= 5 and len(actions.latest.data) == 2

                # stale observations: with sim_node paused, policy_node stops acting and says why
                assert ros.call(SetBool, f"{NODE}/pause", SetBool.Request(data=True)).success
                ros.spin_for(1.2)
                pause_seen = time.monotonic()
                ros.spin_for(0.8)
                assert not actions.since(pause_seen), "acted on observations older than observation_timeout"
                stale = "no command for agent_0: agent_0/observation is older than observation_timeout (0.5 s)"
                ros.spin_until(lambda: stale in node.output(), 5, "the stale-observation warning")
                assert ros.call(SetBool, f"{NODE}/pause", SetBool.Request(data=False)).success
                resumed = time.monotonic()
                ros.spin_until(lambda: actions.since(resumed), 5, "actions once observations flow again")
                assert node.alive()
                node.stop(signal.SIGTERM)
                assert node.returncode == 0, node.describe()
        finally:
            actions.destroy()

    def test_adapter_and_cmd_vel_output(self, ros, world, policy_node, tmp_path):
        path = seek_landmark(tmp_path, "seek")
        twists = ros.collect(Twist, "/agent_1/cmd_vel")
        try:
            with policy_node(policy_path=str(path), output="cmd_vel", cmd_vel_scale=0.5,
                             adapter="vmas_ros.ros.adapters:SimpleSpreadAdapter") as node:
                node.wait_publishing([f"/{n}/cmd_vel" for n in AGENTS])
                fresh_layout(ros)
                agents_close_in_on_landmark_0(ros)
                assert twists.wait_for(5)
                speeds = [np.hypot(t.linear.x, t.linear.y) for t in twists.messages]
                assert max(speeds) <= 0.5 * np.sqrt(2) + 1e-6, "cmd_vel_scale x an action in [-1, 1]"
                assert max(speeds) > 0.1
            assert node.returncode == 0, node.describe()  # SIGINT on leaving the block
        finally:
            twists.destroy()


# ============================================================== refused at start
@pytest.fixture(scope="class")
def refused(policy_node, tmp_path_factory):
    directory = tmp_path_factory.mktemp("policy_node_bad")
    good = str(constant_push(directory, "good", [0.1, 0.0]))
    tampered = constant_push(directory, "tampered", [0.1, 0.0])
    tampered.with_suffix(".onnx").write_bytes(b"not an onnx model")
    cases = {
        "policy_path": {"policy_path": str(directory / "missing.json")},
        "policy_path SHA-256": {"policy_path": str(tampered)},
        "output rate_hz": {"policy_path": good, "output": "twist", "rate_hz": 0.0},  # both named at once
        "adapter": {"policy_path": good, "adapter": "vmas_ros.ros.adapters:NoSuchAdapter"},
    }
    processes = {name: policy_node(**params) for name, params in cases.items()}
    codes = wait_all(processes.values(), timeout=60.0)
    return {name: (processes[name], code) for name, code in zip(processes, codes)}


class TestRefused:
    @pytest.mark.parametrize("name", ["policy_path", "policy_path SHA-256", "output rate_hz", "adapter"])
    def test_bad_parameters_exit_2_with_the_reason(self, refused, name):
        process, code = refused[name]
        assert code == 2, process.describe()
        stderr = process.stderr()
        assert "policy_node: refused parameters" in stderr, stderr
        assert all(part in stderr for part in name.split()), stderr
        assert "Traceback" not in stderr, stderr
