"""sim_node's runtime control as a real ROS 2 process: env_index switches, refused values, heuristic control.

Two ``python -m vmas_ros.ros.sim_node`` processes (class-scoped fixtures): four
envs whose published one switches at runtime, and three agents the scenario's
heuristic drives to the landmarks without any command. The engine is the
reference for each env's layout (sim_node_helpers.py).
"""
from __future__ import annotations

import math
import signal
import time

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray
from std_srvs.srv import Trigger

from test.ros.conftest import NODE, stamp_ns
from test.ros.sim_node_helpers import (BATCH_SEED, DT_NS, HEURISTIC_SEED, SCENARIO, coverage, engine, layout, pause,
                                       positions)

pytestmark = [pytest.mark.ros, pytest.mark.slow]


# ====================================================== 4 envs, env_index switch
@pytest.fixture(scope="class")
def batched(ros, sim_node):
    with sim_node(scenario=SCENARIO, num_envs=4, seed=BATCH_SEED, control="zero") as sim:
        yield sim


class TestEnvIndex:
    def test_switch_env_index_at_runtime(self, ros, batched):
        env = engine(BATCH_SEED, num_envs=4)
        agents0, landmarks0 = layout(env, 0)
        agents2, landmarks2 = layout(env, 2)
        assert np.abs(agents0 - agents2).max() > 0.05
        agents = ros.collect(PoseArray, "/agents/poses")
        landmarks = ros.collect(PoseArray, "/landmarks/poses")
        try:
            agents.wait_for(3)
            landmarks.wait_for(3)
            published0 = positions(agents.latest)
            assert np.allclose(published0, agents0, atol=1e-6), "env 0 is published first"
            assert np.allclose(positions(landmarks.latest), landmarks0, atol=1e-6)

            result, = ros.set_parameters(NODE, env_index=2)
            assert result.successful, result.reason
            switched = agents.wait_until(lambda m: np.allclose(positions(m), agents2, atol=1e-6), 5,
                                         "poses of env 2")
            later = stamp_ns(switched.header.stamp)
            agents.wait_until(lambda m: stamp_ns(m.header.stamp) >= later + 3 * DT_NS, 5)
            for m in agents.messages:
                if stamp_ns(m.header.stamp) >= later:
                    assert np.allclose(positions(m), agents2, atol=1e-6)
                    assert not np.allclose(positions(m), published0, atol=1e-3)
            landmarks.wait_until(lambda m: np.allclose(positions(m), landmarks2, atol=1e-6), 5,
                                 "landmark poses of env 2")
            assert ros.get_parameters(NODE, "env_index") == [2]
        finally:
            agents.destroy()
            landmarks.destroy()

    @pytest.mark.parametrize("name, value", [
        ("env_index", 9), ("env_index", 4), ("env_index", -1), ("env_index", "2"),
        ("control", "bogus"), ("cmd_vel_timeout", -1.0), ("real_time_factor", math.nan),
    ])
    def test_bad_runtime_value_is_refused(self, ros, batched, name, value):
        old = ros.get_parameters(NODE, name)
        result, = ros.set_parameters(NODE, **{name: value})
        assert not result.successful
        assert name in result.reason, result.reason
        assert ros.get_parameters(NODE, name) == old
        assert batched.alive()

    @pytest.mark.parametrize("name, value", [("num_envs", 8), ("scenario", "waterfall"), ("seed", 3)])
    def test_non_runtime_parameter_is_refused(self, ros, batched, name, value):
        old = ros.get_parameters(NODE, name)
        result, = ros.set_parameters(NODE, **{name: value})
        assert not result.successful
        assert name in result.reason and "read-only" in result.reason, result.reason  # start-only
        assert ros.get_parameters(NODE, name) == old


# ========================================================== heuristic control
@pytest.fixture(scope="class")
def heuristic_sim(ros, sim_node):
    with sim_node(scenario=SCENARIO, seed=HEURISTIC_SEED, control="heuristic") as sim:
        yield sim


class TestHeuristic:
    def test_heuristic_covers_landmarks_without_commands(self, ros, heuristic_sim):
        agents = ros.collect(PoseArray, "/agents/poses")
        landmarks = ros.collect(PoseArray, "/landmarks/poses")
        try:
            # by the time it is discovered the heuristic may have finished: start from a fresh layout
            pause(ros, True)
            ros.spin_for(0.3)
            agents.clear()
            landmarks.clear()
            assert ros.call(Trigger, f"{NODE}/reset").success
            start_agents, start_landmarks = agents.wait_for(1)[0], landmarks.wait_for(1)[0]
            start = stamp_ns(start_agents.header.stamp)
            before = coverage(positions(start_agents), positions(start_landmarks))
            assert before > 1.0
            pause(ros, False)
            end_agents = agents.wait_until(lambda m: stamp_ns(m.header.stamp) >= start + 3_000_000_000, 10,
                                           "3 s of simulated time")
            end_landmarks = landmarks.wait_until(
                lambda m: stamp_ns(m.header.stamp) == stamp_ns(end_agents.header.stamp), 5)
            after = coverage(positions(end_agents), positions(end_landmarks))
            assert np.allclose(positions(end_landmarks), positions(start_landmarks)), "landmarks stay put"
            assert after < 0.5 * before, f"coverage {before:.3f} m -> {after:.3f} m in 3 s"
            # and it got there steadily: coverage sampled every second does not go up
            samples = [coverage(positions(m), positions(start_landmarks)) for m in agents.messages
                       if (stamp_ns(m.header.stamp) - start) % 1_000_000_000 == 0]
            assert samples == sorted(samples, reverse=True), samples
        finally:
            pause(ros, False)
            agents.destroy()
            landmarks.destroy()

    def test_sigterm_exits_cleanly(self, ros, heuristic_sim):
        started = time.monotonic()
        assert heuristic_sim.stop(signal.SIGTERM, timeout=5.0) == 0, heuristic_sim.describe()
        assert time.monotonic() - started < 5.0
        assert "Traceback" not in heuristic_sim.stderr(), heuristic_sim.describe()
