"""sim_node as a real ROS 2 process: topics, stamps, scans, cmd_vel, services, parameters, signals.

Each class starts one ``python -m vmas_ros.ros.sim_node`` process (class-scoped
fixture) and groups the checks that process can answer, so the module starts
four running nodes plus three that must refuse their parameters. The test side is an
rclpy node in the same ROS_DOMAIN_ID (see conftest.py). The engine itself is
the reference: scans and layouts are recomputed in-process with
``vmas_ros.make_env`` and compared with what the node published.
"""
from __future__ import annotations

import math
import signal
import time

import numpy as np
import pytest
import torch
from geometry_msgs.msg import PoseArray, PoseStamped, Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

import vmas_ros
from test.ros.conftest import NODE, stamp_ns, wait_all
from vmas_ros.simulator.sensors import Lidar

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SCENARIO = "simple_spread"
DT = float(vmas_ros.make_env(SCENARIO, num_envs=1).world.dt)  # 0.1 s
DT_NS = int(round(DT * 1e9))
AGENTS = ["agent_0", "agent_1", "agent_2"]

SPREAD_SEED = 5  # agents apart (no contact) and 5 of the 36 rays hit another agent
LIDAR_RAYS, LIDAR_RANGE = 12, 2.0
BATCH_SEED = 2  # no two agents touch in any of the 4 envs: a zero-control layout stays put
HEURISTIC_SEED = 1  # the layout after one reset is far from covered (sum of distances 2.7 m)


# ------------------------------------------------------------------- helpers
def yaw_of(orientation) -> float:
    return 2.0 * math.atan2(orientation.z, orientation.w)


def xy(pose) -> np.ndarray:
    return np.array([pose.position.x, pose.position.y])


def positions(array: PoseArray) -> np.ndarray:
    return np.array([[p.position.x, p.position.y] for p in array.poses])


def coverage(agents: np.ndarray, landmarks: np.ndarray) -> float:
    """Sum over landmarks of the distance to the closest agent (simple_spread's coverage)."""
    return float(np.linalg.norm(landmarks[:, None, :] - agents[None, :, :], axis=-1).min(axis=1).sum())


def engine(seed: int, num_envs: int = 1, resets: int = 1, **kwargs):
    """The env the node builds (make_env, then reset), plus ``resets - 1`` further resets."""
    env = vmas_ros.make_env(SCENARIO, num_envs=num_envs, seed=seed, **kwargs)
    for _ in range(resets):
        env.reset()
    return env


def layout(env, index: int):
    agents = np.array([a.state.pos[index].tolist() for a in env.world.agents])
    landmarks = np.array([lm.state.pos[index].tolist() for lm in env.world.landmarks])
    return agents, landmarks


def angle_between(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2 * math.pi))


def speed(odom: Odometry) -> float:
    return math.hypot(odom.twist.twist.linear.x, odom.twist.twist.linear.y)


def pause(ros, on: bool):
    response = ros.call(SetBool, f"{NODE}/pause", SetBool.Request(data=on))
    assert response.success, response.message
    return response


def max_clock(clock) -> int:
    return max((stamp_ns(m.clock) for m in clock.messages), default=-1)


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


# ================================================= one agent, driven by cmd_vel
CMD_TIMEOUT = 0.3


@pytest.fixture(scope="class")
def single(ros, sim_node):
    with sim_node(scenario=SCENARIO, scenario_kwargs={"n_agents": 1}, seed=0, control="zero", real_time_factor=1.0,
                  cmd_vel_timeout=CMD_TIMEOUT) as sim:
        yield sim


class Drive:
    """Publish one Twist at 20 Hz for ``seconds``, then record until the agent has (nearly) stopped."""

    def __init__(self, ros, vx: float, vy: float, seconds: float = 2.0, settle: float = 3.0) -> None:
        self.command = (vx, vy)
        publisher = ros.node.create_publisher(Twist, "/agent_0/cmd_vel", 10)
        self.odom = ros.collect(Odometry, "/agent_0/odom")
        self.pose = ros.collect(PoseStamped, "/agent_0/pose")
        try:
            ros.spin_until(lambda: publisher.get_subscription_count() > 0, 10, "sim_node's cmd_vel subscription")
            self.odom.wait_for(2)
            self.pose.wait_for(2)
            msg = Twist()
            msg.linear.x, msg.linear.y = float(vx), float(vy)
            self.start = time.monotonic()
            due = self.start
            while time.monotonic() - self.start < seconds:
                if time.monotonic() >= due:
                    publisher.publish(msg)
                    due += 0.05
                ros.executor.spin_once(timeout_sec=max(0.0, min(0.01, due - time.monotonic())))
            self.stop = time.monotonic()
            slow = 0.1 * math.hypot(vx, vy)
            self.stopped = self.odom.wait_until(lambda m: speed(m) < slow and self.arrived(m) > self.stop,
                                                timeout=settle, what="the agent to slow below 10% of the command")
            self.stop_delay = self.arrived(self.stopped) - self.stop
        finally:
            ros.node.destroy_publisher(publisher)
            self.odom.destroy()
            self.pose.destroy()

    def arrived(self, msg) -> float:
        for collector in (self.odom, self.pose):
            for m, t in zip(collector.messages, collector.arrivals):
                if m is msg:
                    return t
        raise KeyError(msg)

    def during(self, collector):
        """(message, arrival) pairs received while the command was being published."""
        return [(m, t) for m, t in zip(collector.messages, collector.arrivals) if self.start < t < self.stop]

    def check(self, dt: float = DT):
        """Steady body-frame twist after 1 s of sim time, and world displacement along the command."""
        vx, vy = self.command
        commanded = math.hypot(vx, vy)
        along = np.array([vx, vy]) / commanded
        moving = [m for m, _ in self.during(self.odom)
                  if np.dot([m.twist.twist.linear.x, m.twist.twist.linear.y], along) > 0.25 * commanded]
        assert moving, "the agent never moved"
        first = stamp_ns(moving[0].header.stamp) - int(dt * 1e9)  # the step that first used the command
        steady = [m for m in moving if stamp_ns(m.header.stamp) >= first + 1_000_000_000]
        assert len(steady) >= 3, f"only {len(steady)} odometry messages after 1 s of commanded motion"
        for m in steady:
            twist = m.twist.twist
            assert twist.linear.x == pytest.approx(vx, abs=0.05 * commanded), twist
            assert twist.linear.y == pytest.approx(vy, abs=0.05 * commanded), twist
            assert twist.angular.z == pytest.approx(0.0, abs=1e-6)
        before = [m for m in self.pose.messages if stamp_ns(m.header.stamp) <= first]
        during = [m for m, _ in self.during(self.pose) if stamp_ns(m.header.stamp) > first]
        assert before and len(during) >= 10
        start, end = before[-1], during[-1]
        heading = yaw_of(start.pose.orientation)
        displacement = xy(end.pose) - xy(start.pose)
        elapsed = (stamp_ns(end.header.stamp) - stamp_ns(start.header.stamp)) / 1e9
        assert np.linalg.norm(displacement) > 0.6 * commanded * elapsed, (displacement, elapsed)
        expected_direction = heading + math.atan2(vy, vx)  # body frame -> world frame (REP 103)
        assert angle_between(math.atan2(displacement[1], displacement[0]), expected_direction) < math.radians(2)
        # positions move at the commanded speed in the world frame too
        steady_poses = [m for m in during if stamp_ns(m.header.stamp) >= first + 1_000_000_000]
        for a, b in zip(steady_poses, steady_poses[1:]):
            step = (stamp_ns(b.header.stamp) - stamp_ns(a.header.stamp)) / 1e9
            world_speed = np.linalg.norm(xy(b.pose) - xy(a.pose)) / step
            assert world_speed == pytest.approx(commanded, rel=0.05)


@pytest.fixture(scope="class")
def forward(ros, single):
    return Drive(ros, 0.3, 0.0)


class TestCmdVel:
    def test_forward_command_moves_along_heading(self, forward):
        forward.check()

    def test_command_times_out_and_drag_stops_the_agent(self, forward):
        drag = float(engine(0, n_agents=1).world.drag)
        assert forward.stop_delay < 2.0, f"took {forward.stop_delay:.2f} s to drop below 10% of the command"
        # after the timeout no force acts: speed decays by (1 - drag) per step
        after = [m for m in forward.odom.messages if forward.arrived(m) > forward.stop]
        decaying = [(a, b) for a, b in zip(after, after[1:])
                    if 0.01 < speed(b) < speed(a) < 0.95 * 0.3
                    and stamp_ns(b.header.stamp) - stamp_ns(a.header.stamp) == DT_NS]
        assert len(decaying) >= 3, [speed(m) for m in after]
        for a, b in decaying:
            assert speed(b) / speed(a) == pytest.approx(1 - drag, abs=0.01)

    def test_negative_linear_y_moves_to_the_right(self, ros, single):
        drive = Drive(ros, 0.0, -0.2)
        drive.check()
        moving = [m for m, _ in drive.during(drive.odom) if speed(m) > 0.15]
        assert moving and all(m.twist.twist.linear.y < 0 for m in moving), "REP 103: +y is left, so -y is right"

    def test_nan_command_is_dropped(self, ros, single):
        clock = ros.collect(Clock, "/clock")
        odom = ros.collect(Odometry, "/agent_0/odom")
        publisher = ros.node.create_publisher(Twist, "/agent_0/cmd_vel", 10)
        try:
            ros.spin_until(lambda: publisher.get_subscription_count() > 0, 10, "cmd_vel subscription")
            odom.wait_for(1)
            bad = [Twist(), Twist(), Twist()]
            bad[0].linear.x = math.nan
            bad[1].linear.y = math.inf
            bad[2].linear.x, bad[2].angular.z = 0.3, math.nan
            end = time.monotonic() + 0.6
            while time.monotonic() < end:
                for msg in bad:
                    publisher.publish(msg)
                ros.spin_for(0.05)
            start = time.monotonic()
            ros.spin_until(lambda: "dropped a cmd_vel with NaN or inf for agent_0" in single.stderr(), 5,
                           "the NaN warning in sim_node's log")
            ros.spin_until(lambda: len(clock.since(start)) >= 3, 5, "/clock to keep running")
            assert single.alive()
            for m in odom.messages:
                p, t = m.pose.pose.position, m.twist.twist.linear
                assert all(math.isfinite(v) for v in (p.x, p.y, t.x, t.y)), m
                assert speed(m) < 0.05, "a dropped command must not move the agent"
            # and a good command still drives it afterwards
            good = Twist()
            good.linear.x = 0.3
            end = time.monotonic() + 0.8
            while time.monotonic() < end:
                publisher.publish(good)
                ros.spin_for(0.05)
            odom.wait_until(lambda m: m.twist.twist.linear.x > 0.2, 3, "a valid command after the NaNs to act")
        finally:
            ros.node.destroy_publisher(publisher)
            clock.destroy()
            odom.destroy()

    def test_reset_jumps_to_a_fresh_layout(self, ros, single):
        agents = ros.collect(PoseArray, "/agents/poses")
        landmarks = ros.collect(PoseArray, "/landmarks/poses")
        odom = ros.collect(Odometry, "/agent_0/odom")
        collectors = (agents, landmarks, odom)
        initial, _ = layout(engine(0, n_agents=1), 0)
        try:
            for c in collectors:  # subscribed and matched while it still publishes
                c.wait_for(1)
            pause(ros, True)
            ros.spin_for(0.3)
            if np.linalg.norm(positions(agents.latest) - initial) < 0.2:  # run alone: drive it away first
                pause(ros, False)
                Drive(ros, 0.3, 0.0, seconds=1.0)
                pause(ros, True)
                ros.spin_for(0.3)
            before = positions(agents.latest)
            assert np.linalg.norm(before - initial) > 0.2
            for c in collectors:
                c.clear()
            response = ros.call(Trigger, f"{NODE}/reset")
            assert response.success, response.message
            for c in collectors:
                c.wait_for(1)
            after_agents, after_landmarks = positions(agents.latest), positions(landmarks.latest)
            assert np.linalg.norm(after_agents - before) > 1e-3, "reset did not move the agent"
            # a fresh layout: the env's next random layout (the second reset of the seeded env)
            expected_agents, expected_landmarks = layout(engine(0, resets=2, n_agents=1), 0)
            assert np.allclose(after_agents, expected_agents, atol=1e-6)
            assert np.allclose(after_landmarks, expected_landmarks, atol=1e-6)
            assert np.all(np.abs(after_agents) <= 1.0) and np.all(np.abs(after_landmarks) <= 1.0)
            assert speed(odom.latest) == 0.0
        finally:
            pause(ros, False)
            for c in collectors:
                c.destroy()


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
        assert name in result.reason and "restart" in result.reason, result.reason
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
