"""sim_node's learning interface as a real process: observation/reward topics, raw actions, ``control: policy``.

The Environment is the reference: the tests replay the node's env in-process
(same seed, same resets, same actions) and compare what the node published.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from geometry_msgs.msg import PoseArray
from std_msgs.msg import Float32, Float32MultiArray
from std_srvs.srv import SetBool, Trigger

import vmas_ros
from test.ros.conftest import NODE, stamp_ns, wait_all
from test.ros.policy_files import constant_push

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SCENARIO = "simple_spread"
AGENTS = ["agent_0", "agent_1", "agent_2"]
SEED = 2  # no two agents touch: agents without an action stay put


def call(ros, srv, name, request=None):
    response = ros.call(srv, f"{NODE}/{name}", request)
    assert response.success, response.message
    return response


def positions(array: PoseArray) -> np.ndarray:
    return np.array([[p.position.x, p.position.y] for p in array.poses])


def action_msg(values) -> Float32MultiArray:
    msg = Float32MultiArray()
    msg.data = [float(v) for v in values]
    return msg


@pytest.fixture(scope="module")
def policies(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("policies")


# ============================================ paused node, stepped through ~/step
@pytest.fixture(scope="class")
def stepped(ros, sim_node):
    """Pause, reset, one zero step, then five steps with agent_1 driven by an external action.

    Returns everything the node published, one entry per service call, and the
    node itself (for its log).
    """
    obs = {n: ros.collect(Float32MultiArray, f"/{n}/observation") for n in AGENTS}
    rewards = {n: ros.collect(Float32, f"/{n}/reward") for n in AGENTS}
    publishers = {n: ros.node.create_publisher(Float32MultiArray, f"/{n}/action", 10) for n in AGENTS}
    with sim_node(scenario=SCENARIO, seed=SEED, control="zero", cmd_vel_timeout=5.0, rate_hz=20.0) as sim:
        for c in obs.values():
            c.wait_for(1)
        call(ros, SetBool, "pause", SetBool.Request(data=True))
        ros.spin_for(0.3)

        def after(service: str):
            for c in (*obs.values(), *rewards.values()):
                c.clear()
            call(ros, Trigger, service)
            for c in obs.values():
                c.wait_for(1)
            if service == "step":
                for c in rewards.values():
                    c.wait_for(1)
            ros.spin_for(0.1)
            assert all(len(c) == 1 for c in obs.values()), "a paused node publishes once per call"
            return (np.array([np.asarray(obs[n].latest.data) for n in AGENTS]),
                    {n: rewards[n].latest.data for n in AGENTS if rewards[n].latest is not None},
                    obs["agent_0"].latest)

        result = {"reset": after("reset"), "step": after("step")}
        ros.spin_until(lambda: all(p.get_subscription_count() > 0 for p in publishers.values()), 10, "action subs")
        for _ in range(3):  # good, out-of-range (clamped), wrong length and NaN
            publishers["agent_1"].publish(action_msg([5.0, 0.0]))
            publishers["agent_2"].publish(action_msg([1.0]))
            publishers["agent_0"].publish(action_msg([math.nan, 0.0]))
            ros.spin_for(0.1)
        result["driven"] = [after("step") for _ in range(5)]
        result["sim"] = sim
        yield result
    for c in (*obs.values(), *rewards.values()):
        c.destroy()
    for p in publishers.values():
        ros.node.destroy_publisher(p)


def replay():
    """The node's env: built, reset at start, reset by the ~/reset call."""
    env = vmas_ros.make_env(SCENARIO, num_envs=1, seed=SEED)
    env.reset()
    return env, env.reset()


def stacked(obs) -> np.ndarray:
    return torch.stack([o[0] for o in obs]).numpy()


class TestObservationRewardAndActionTopics:
    def test_observation_after_reset_is_the_environments(self, stepped):
        published, rewards, msg = stepped["reset"]
        _, obs = replay()
        np.testing.assert_allclose(published, stacked(obs), atol=1e-6)
        assert rewards == {}, "no reward before the first step after a reset"
        assert [d.label for d in msg.layout.dim] == ["observation"] and msg.layout.dim[0].size == 14

    def test_observation_and_reward_after_a_step_are_the_environments(self, stepped):
        published, rewards, _ = stepped["step"]
        env, _ = replay()
        obs, rews, _, _ = env.step([torch.zeros(1, 2)] * 3)
        np.testing.assert_allclose(published, stacked(obs), atol=1e-6)
        for name, r in zip(AGENTS, rews):
            assert rewards[name] == pytest.approx(float(r[0]), abs=1e-5)
        assert rewards["agent_0"] < 0  # simple_spread: minus the coverage distance

    def test_external_action_drives_its_agent_clamped(self, stepped):
        env, _ = replay()
        env.step([torch.zeros(1, 2)] * 3)
        # agent_1's 5.0 is clamped to the action range; the NaN and the short vector are dropped
        action = [torch.zeros(1, 2), torch.tensor([[1.0, 0.0]]), torch.zeros(1, 2)]
        for published, _, _ in stepped["driven"]:
            obs, _, _, _ = env.step(action)
            np.testing.assert_allclose(published, stacked(obs), atol=1e-5)
        first, last = stepped["driven"][0][0], stepped["driven"][-1][0]
        assert last[1, 0] - first[1, 0] > 0.05, "agent_1 moves along +x"
        for k in (0, 2):
            np.testing.assert_allclose(last[k, :4], first[k, :4], atol=1e-6)  # the others stay put

    def test_bad_actions_are_dropped_with_a_warning(self, ros, stepped):
        sim = stepped["sim"]
        ros.spin_until(lambda: "agent_2" in sim.output() and "agent_0 on" in sim.output(), 5, "the warnings")
        log = sim.output()
        assert "dropped an action for agent_2 on /agent_2/action: expected 2 finite values, got 1 values" in log
        assert "dropped an action for agent_0 on /agent_0/action: expected 2 finite values, got NaN or inf" in log
        assert log.count("dropped an action for agent_2") == 1, "throttled: three bad messages, one warning"
        assert sim.alive()


# ================================================================ control: policy
@pytest.fixture(scope="class")
def driven(ros, sim_node, policies):
    path = constant_push(policies, "push", [0.6, 0.0])
    with sim_node(scenario=SCENARIO, seed=SEED, control="policy", policy_path=str(path), rate_hz=20.0) as sim:
        yield sim


def sim_seconds(first: PoseArray, last: PoseArray) -> float:
    return (stamp_ns(last.header.stamp) - stamp_ns(first.header.stamp)) / 1e9


class TestControlPolicy:
    # a 0.6 push against drag 0.25 settles at 0.18 m/s; full reverse (-1) at -0.3 m/s.
    # Speeds are measured per simulated second, so a slow (loaded) machine only takes longer.
    def test_policy_drives_every_agent(self, ros, driven):
        agents = ros.collect(PoseArray, "/agents/poses")
        try:
            first = agents.wait_for(1)[-1]
            ros.spin_until(lambda: sim_seconds(first, agents.latest) >= 3.0, 20, "3 s of simulated time")
            moved = positions(agents.latest) - positions(first)
            speed = moved / sim_seconds(first, agents.latest)
            assert (speed[:, 0] > 0.1).all(), f"every agent moves along +x: {speed} m/s"
            assert (np.abs(moved[:, 1]) < 0.05 * moved[:, 0]).all(), f"and only along x: {moved}"
        finally:
            agents.destroy()

    def test_live_action_wins_over_the_policy_then_times_out(self, ros, driven):
        agents = ros.collect(PoseArray, "/agents/poses")
        publisher = ros.node.create_publisher(Float32MultiArray, "/agent_0/action", 10)
        try:
            ros.spin_until(lambda: publisher.get_subscription_count() > 0, 10, "the action subscription")
            first = agents.wait_for(1)[-1]
            end = time.monotonic() + 20.0
            while sim_seconds(first, agents.latest) < 3.0 and time.monotonic() < end:
                publisher.publish(action_msg([-1.0, 0.0]))
                ros.spin_for(0.05)
            released = agents.latest
            speed = (positions(released) - positions(first)) / sim_seconds(first, released)
            assert speed[0, 0] < -0.1, f"agent_0 follows its action, backwards: {speed} m/s"
            assert (speed[1:, 0] > 0.1).all(), f"the others follow the policy: {speed} m/s"
            # no more actions: after cmd_vel_timeout the policy takes agent_0 forward again
            x_released = positions(released)[0, 0]
            ros.spin_until(lambda: positions(agents.latest)[0, 0] > x_released + 0.05, 20,
                           "agent_0 to move +x again after its action timed out")
        finally:
            ros.node.destroy_publisher(publisher)
            agents.destroy()


# ====================================================== policies refused at start
def bad_policies(directory: Path) -> dict:
    """Case -> (sim_node parameters, a fragment its refusal must contain)."""
    corrupt = constant_push(directory, "corrupt", [0.1, 0.0])
    with open(corrupt.with_suffix(".onnx"), "ab") as f:
        f.write(b"tampered")
    return {
        "missing file": ({"control": "policy", "policy_path": str(directory / "missing.json")}, "existing file"),
        "no policy_path": ({"control": "policy"}, "needs policy_path"),
        "agent names": ({"policy_path": str(constant_push(directory, "names", [0.1, 0.0], agents=("a", "b", "c")))},
                        "agents ['a', 'b', 'c']"),
        "tampered onnx": ({"policy_path": str(corrupt)}, "SHA-256"),
    }


@pytest.fixture(scope="class")
def refused(sim_process, policies):
    cases = bad_policies(policies / "bad")
    processes = {name: sim_process(scenario=SCENARIO, **params) for name, (params, _) in cases.items()}
    codes = wait_all(processes.values(), timeout=60.0)
    return {name: (processes[name], code, cases[name][1]) for name, code in zip(processes, codes)}


class TestBadPolicies:
    # every kind of mismatch is covered by test_policy_units.py::test_check_policy_finds_every_mismatch;
    # here one of each path to exit code 2: parameter check, cross-check, metadata mismatch, unreadable file
    @pytest.mark.parametrize("case", ["missing file", "no policy_path", "agent names", "tampered onnx"])
    def test_refused_at_start(self, refused, case):
        process, code, fragment = refused[case]
        assert code == 2, process.describe()
        stderr = process.stderr()
        assert "refused parameters" in stderr and "policy_path" in stderr and fragment in stderr, stderr
        assert "Traceback" not in stderr, stderr
