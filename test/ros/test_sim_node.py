"""sim_node as a real ROS 2 process: topics, stamps, scans, services, signals, refused start parameters.

Each class starts one ``python -m vmas_ros.ros.sim_node`` process (class-scoped
fixture) and groups the checks that process can answer, so the module starts
one running node plus three that must refuse their parameters. The test side is an
rclpy node in the same ROS_DOMAIN_ID (see conftest.py). The engine itself is
the reference: scans are recomputed in-process with ``vmas_ros.make_env`` and
compared with what the node published. cmd_vel is in test_sim_node_cmd_vel.py;
env_index and heuristic control in test_sim_node_control.py; shared helpers in
sim_node_helpers.py.
"""
from __future__ import annotations

import math
import signal
import time

import numpy as np
import pytest
import torch
from geometry_msgs.msg import PoseArray, PoseStamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from test.ros.conftest import NODE, stamp_ns, wait_all
from test.ros.sim_node_helpers import (AGENTS, DT, DT_NS, LIDAR_RANGE, LIDAR_RAYS, SCENARIO, SPREAD_SEED, engine,
                                       max_clock, pause, positions, xy, yaw_of)
from vmas_ros.simulator.sensors import Lidar

pytestmark = [pytest.mark.ros, pytest.mark.slow]


# ============================================================ simple_spread
@pytest.fixture(scope="class")
def spread(ros, sim_node):
    """3 agents, 12-ray lidars; /clock is recorded from before the node starts."""
    clock = ros.collect(Clock, "/clock", depth=10000)
    with sim_node(scenario=SCENARIO, seed=SPREAD_SEED, lidar_rays=LIDAR_RAYS, lidar_range=LIDAR_RANGE,
                  control="zero") as sim:
        sim.clock = clock
        yield sim
    clock.destroy()


class TestSpread:
    def test_topics_and_services_discovered(self, ros, spread):
        expected = {
            "/clock": "rosgraph_msgs/msg/Clock",
            "/agents/poses": "geometry_msgs/msg/PoseArray",
            "/landmarks/poses": "geometry_msgs/msg/PoseArray",
            "/world/markers": "visualization_msgs/msg/MarkerArray",
        }
        for name in AGENTS:
            expected[f"/{name}/pose"] = "geometry_msgs/msg/PoseStamped"
            expected[f"/{name}/odom"] = "nav_msgs/msg/Odometry"
            expected[f"/{name}/scan"] = "sensor_msgs/msg/LaserScan"
            expected[f"/{name}/cmd_vel"] = "geometry_msgs/msg/Twist"
        ros.spin_until(lambda: set(expected) <= set(ros.topics()), 10, f"topics {sorted(expected)}")
        topics = ros.topics()
        for name, msg_type in expected.items():
            assert topics[name] == [msg_type], (name, topics[name])
        for name in AGENTS:  # the node publishes agent topics and subscribes cmd_vel, not the reverse
            assert ros.node.count_publishers(f"/{name}/pose") == 1
            assert ros.node.count_subscribers(f"/{name}/cmd_vel") == 1
        assert not [t for t in topics if t.startswith("/landmark_")], "landmarks get no per-entity topics"
        services = ros.services()
        for name, srv_type in {"reset": "std_srvs/srv/Trigger", "pause": "std_srvs/srv/SetBool",
                               "step": "std_srvs/srv/Trigger"}.items():
            assert services.get(f"{NODE}/{name}") == [srv_type], (name, services.get(f"{NODE}/{name}"))
        assert services.get(f"{NODE}/set_parameters") == ["rcl_interfaces/srv/SetParameters"]

    def test_streams_frames_and_stamps(self, ros, spread):
        poses = {n: ros.collect(PoseStamped, f"/{n}/pose") for n in AGENTS}
        odoms = {n: ros.collect(Odometry, f"/{n}/odom") for n in AGENTS}
        scans = {n: ros.collect(LaserScan, f"/{n}/scan") for n in AGENTS}
        agents = ros.collect(PoseArray, "/agents/poses")
        landmarks = ros.collect(PoseArray, "/landmarks/poses")
        markers = ros.collect(MarkerArray, "/world/markers")
        collectors = [*poses.values(), *odoms.values(), *scans.values(), agents, landmarks, markers]
        try:
            for c in collectors:
                c.wait_for(5, timeout=15)
            clock_stamps = {stamp_ns(m.clock) for m in spread.clock.messages}
            first_clock = min(clock_stamps)
            for n in AGENTS:
                for msg in poses[n].messages:
                    assert msg.header.frame_id == "world"
                for msg in odoms[n].messages:
                    assert msg.header.frame_id == "world"
                    assert msg.child_frame_id == f"{n}/base_link"
                for msg in scans[n].messages:
                    assert msg.header.frame_id == f"{n}/base_link"
                for c in (poses[n], odoms[n], scans[n]):
                    stamps = [stamp_ns(m.header.stamp) for m in c.messages]
                    assert stamps == sorted(set(stamps)), f"{c.topic} stamps not strictly increasing"
                    late = [s for s in stamps if s >= first_clock]
                    assert late and set(late) <= clock_stamps, f"{c.topic} stamps that /clock never carried"
                # pose and odometry of one step agree
                by_stamp = {stamp_ns(m.header.stamp): m for m in odoms[n].messages}
                common = [m for m in poses[n].messages if stamp_ns(m.header.stamp) in by_stamp]
                assert common
                for m in common:
                    o = by_stamp[stamp_ns(m.header.stamp)]
                    assert np.allclose(xy(m.pose), xy(o.pose.pose), atol=1e-9)
                    assert math.isclose(yaw_of(m.pose.orientation), yaw_of(o.pose.pose.orientation), abs_tol=1e-9)
            for array in (agents, landmarks):
                for msg in array.messages:
                    assert msg.header.frame_id == "world" and len(msg.poses) == 3
            # the array and the per-agent topics carry the same positions for the same step
            per_agent = {n: {stamp_ns(m.header.stamp): xy(m.pose) for m in poses[n].messages} for n in AGENTS}
            checked = 0
            for msg in agents.messages:
                s = stamp_ns(msg.header.stamp)
                if all(s in per_agent[n] for n in AGENTS):
                    expected = np.array([per_agent[n][s] for n in AGENTS])
                    assert np.allclose(positions(msg), expected, atol=1e-9)
                    checked += 1
            assert checked
            marker_msg = markers.latest
            assert len(marker_msg.markers) == 6  # 3 landmarks + 3 agents
            assert len({(m.ns, m.id) for m in marker_msg.markers}) == 6
            assert all(m.header.frame_id == "world" for m in marker_msg.markers)
        finally:
            for c in collectors:
                c.destroy()

    def test_clock_strictly_increases_by_dt(self, ros, spread):
        clock = spread.clock
        clock.wait_for(15, timeout=15)
        stamps = [stamp_ns(m.clock) for m in clock.messages]
        assert all(s % DT_NS == 0 for s in stamps), f"stamps not multiples of dt={DT}: {stamps[:20]}"
        steps = np.diff(stamps)
        assert (steps > 0).all(), "/clock went backwards or repeated"
        # nothing paused it yet, and a reliable subscriber misses nothing: one dt per message
        assert (steps == DT_NS).all(), f"steps between /clock messages: {sorted(set(steps.tolist()))}"

    def test_scan_geometry(self, ros, spread):
        scans = {n: ros.collect(LaserScan, f"/{n}/scan") for n in AGENTS}
        try:
            hits = misses = 0
            for n in AGENTS:
                scan = scans[n].wait_for(1, timeout=10)[-1]
                count = round((scan.angle_max - scan.angle_min) / scan.angle_increment) + 1
                assert len(scan.ranges) == count == LIDAR_RAYS
                assert scan.angle_min == pytest.approx(0.0, abs=1e-6)
                assert scan.angle_increment == pytest.approx(2 * math.pi / LIDAR_RAYS, rel=1e-6)
                assert scan.range_max == pytest.approx(LIDAR_RANGE, rel=1e-7)
                assert scan.range_min == 0.0
                for r in scan.ranges:
                    assert r == math.inf or 0.0 <= r < scan.range_max, r
                hits += sum(r < scan.range_max for r in scan.ranges)
                misses += sum(r == math.inf for r in scan.ranges)
            assert hits > 0 and misses > 0, "seed chosen so that some rays hit another agent and some don't"
        finally:
            for c in scans.values():
                c.destroy()

    def test_scan_matches_engine(self, ros, spread):
        scans = {n: ros.collect(LaserScan, f"/{n}/scan") for n in AGENTS}
        agents = ros.collect(PoseArray, "/agents/poses")
        landmarks = ros.collect(PoseArray, "/landmarks/poses")
        collectors = [*scans.values(), agents, landmarks]
        try:
            for c in collectors:
                c.wait_for(1, timeout=10)
            pause(ros, True)
            ros.spin_for(0.3)  # let messages of the last running step arrive
            for c in collectors:
                c.clear()
            stepped = ros.call(Trigger, f"{NODE}/step")
            assert stepped.success, stepped.message
            for c in collectors:
                c.wait_for(1, timeout=10)
            # paused: exactly one new message per topic, all of the same step
            assert {stamp_ns(c.latest.header.stamp) for c in collectors} == {stamp_ns(agents.latest.header.stamp)}
            assert all(len(c) == 1 for c in collectors)

            env = engine(SPREAD_SEED)
            world = env.world
            for agent, pose in zip(world.agents, agents.latest.poses):
                agent.set_pos(torch.tensor(xy(pose), dtype=torch.float32), batch_index=0)
                agent.set_rot(torch.tensor([yaw_of(pose.orientation)], dtype=torch.float32), batch_index=0)
            for landmark, pose in zip(world.landmarks, landmarks.latest.poses):
                landmark.set_pos(torch.tensor(xy(pose), dtype=torch.float32), batch_index=0)
            for name, agent in zip(AGENTS, world.agents):
                lidar = Lidar(world, n_rays=LIDAR_RAYS, max_range=LIDAR_RANGE,
                              entity_filter=lambda e, me=agent: e.collides(me) and me.collides(e))
                agent.add_sensor(lidar)
                expected = lidar.measure()[0].double().numpy()
                expected[expected >= LIDAR_RANGE] = np.inf
                published = np.array(scans[name].latest.ranges, dtype=np.float64)
                assert np.array_equal(np.isinf(published), np.isinf(expected)), (name, published, expected)
                finite = ~np.isinf(expected)
                assert np.allclose(published[finite], expected[finite], atol=1e-4, rtol=0), (name, published, expected)
        finally:
            pause(ros, False)
            for c in collectors:
                c.destroy()

    def test_pause_step_and_resume(self, ros, spread):
        clock = spread.clock
        try:
            response = pause(ros, True)
            assert response.message == "paused"
            ros.spin_for(0.3)  # in-flight /clock of the step before the pause
            frozen = max_clock(clock)
            ros.spin_for(1.0)
            assert max_clock(clock) == frozen, "/clock advanced while paused"

            before = len(clock)
            stepped = ros.call(Trigger, f"{NODE}/step")
            assert stepped.success, stepped.message
            ros.spin_until(lambda: max_clock(clock) > frozen, 5, "the stepped /clock")
            ros.spin_for(0.3)
            new = [stamp_ns(m.clock) for m in clock.messages[before:]]
            assert new == [frozen + DT_NS], f"one step advances exactly dt: {new} after {frozen}"

            assert pause(ros, False).message == "running"
            ros.spin_until(lambda: max_clock(clock) >= frozen + 3 * DT_NS, 5, "/clock to run again")
            refused = ros.call(Trigger, f"{NODE}/step")
            assert not refused.success and "paused" in refused.message
        finally:
            pause(ros, False)

    def test_real_time_factor_changes_at_runtime(self, ros, spread):
        """Speed simulated time up tenfold (a runtime parameter) to reach t = 18.5 s; dt per step stays."""
        clock = spread.clock
        pause(ros, False)
        clock.wait_for(1)
        result, = ros.set_parameters(NODE, real_time_factor=10.0)
        assert result.successful, result.reason
        try:
            mark, wall = max_clock(clock), time.monotonic()
            target = max(mark + 20 * DT_NS, 18_500_000_000)
            ros.spin_until(lambda: max_clock(clock) >= target, 30, f"/clock to reach {target / 1e9} s")
            rate = (max_clock(clock) - mark) / 1e9 / (time.monotonic() - wall)
            # a lower bound well below 10: the machine is shared, but 1.0 would be no speed-up at all
            assert rate > 2.0, f"simulated {rate:.2f} s per wall second at real_time_factor 10"
        finally:
            result, = ros.set_parameters(NODE, real_time_factor=1.0)
            assert result.successful, result.reason
        ns = [stamp_ns(m.clock) for m in clock.messages]
        assert all(b - a == DT_NS for a, b in zip(ns, ns[1:])), "every step advances exactly dt"

    def test_stamps_are_normalized(self, ros, spread):
        """builtin_interfaces/Time wants nanosec in [0, 1e9); needs /clock recorded over t = 5 ... 18 s."""
        stamps = [m.clock for m in spread.clock.messages]
        ns = [stamp_ns(s) for s in stamps]
        if not ns or ns[0] > 4_000_000_000 or ns[-1] < 18_100_000_000:
            pytest.skip(f"/clock recorded over [{ns[0] / 1e9 if ns else None}, {ns[-1] / 1e9 if ns else None}] s "
                        "only: run with test_real_time_factor_changes_at_runtime")
        bad = [(s.sec, s.nanosec) for s in stamps if s.nanosec >= 1_000_000_000]
        assert not bad, f"non-normalized stamps (sec, nanosec): {bad}"

    def test_sigint_exits_cleanly(self, ros, spread):
        started = time.monotonic()
        assert spread.stop(signal.SIGINT, timeout=5.0) == 0, spread.describe()
        assert time.monotonic() - started < 5.0
        assert "Traceback" not in spread.stderr(), spread.describe()


# ======================================================== bad start parameters
BAD_START = {
    "num_envs": {"num_envs": 0},
    "scenario": {"scenario": "nope"},
    "control": {"control": "bogus"},
}


@pytest.fixture(scope="class")
def refused(sim_process):
    """The three refusing processes, started together and awaited together."""
    processes = {name: sim_process(**params) for name, params in BAD_START.items()}
    started = time.monotonic()
    codes = wait_all(processes.values(), timeout=40.0)
    elapsed = time.monotonic() - started
    return {name: (p, code, elapsed) for (name, p), code in zip(processes.items(), codes)}


class TestBadStartParameters:
    @pytest.mark.parametrize("name", list(BAD_START))
    def test_refused_at_start(self, refused, name):
        process, code, elapsed = refused[name]
        assert code not in (0, None), process.describe()
        assert code == 2, process.describe()  # README: "exits with code 2"
        assert elapsed < 30.0, "a refused start should not hang"
        stderr = process.stderr()
        assert name in stderr and "refused parameters" in stderr, stderr
        assert "Traceback" not in stderr, stderr
