"""policy_node with ``act_on: scan``: its commands follow the scans' arrival, not its timer.

The test node plays two robots: odometry and goals at 20 Hz, and scans at a
rate of the test's choosing. Every set of scans carries a tag: all ranges of
scan number ``k`` read ``0.34 - 0.01 (k mod 20)`` m, and the policy's x action
is the mean lidar proximity (``0.35 - range``), so each command says which
scan it was computed from. That makes "one command per set, none twice from
the same scan" a check on the commands themselves, whatever the delays of a
loaded machine. Timings are only asserted with wide margins (a lower bound
where the node must wait, a median where it must not).
"""
from __future__ import annotations

import math
import statistics
import time
from typing import Dict, List, Sequence, Tuple

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan

from test.ros.conftest import killed_at_end, wait_all
from test.ros.policy_files import constant_push, write_policy
from test.ros.policy_process import PolicyProcess
from vmas_ros.ros.convert import fill_odometry

pytestmark = [pytest.mark.ros, pytest.mark.slow]

AGENTS = ("agent_0", "agent_1")
STEP, TAGS = 0.01, 20  # range step between tags, and how many distinct tags there are
N_RAYS = 12  # navigation with 2 agents and an 18-value observation: 6 values, then 12 lidar rays
ODOM_PERIOD = 0.05


@pytest.fixture(scope="module")
def policy_node(ros, sim_log_dir):
    yield from killed_at_end(lambda index, **params: PolicyProcess(ros, params, sim_log_dir, f"scan_{index}"))


def tagging_policy(directory):
    """x action = the mean of the 12 lidar proximities; y action 0."""
    weight = np.zeros((6 + N_RAYS, 2))
    weight[6:, 0] = 1.0 / N_RAYS
    return write_policy(directory, "tagging", weight, [0.0, 0.0], agents=AGENTS, scenario="navigation",
                        scenario_kwargs={"n_agents": 2})


def tagged_scan(seq: int) -> LaserScan:
    scan = LaserScan()
    scan.header.frame_id = "agent/base_link"
    scan.angle_min, scan.angle_increment = -math.pi, 2 * math.pi / 360
    scan.angle_max = math.pi - scan.angle_increment
    scan.range_min, scan.range_max = 0.12, 3.5
    scan.ranges = [0.34 - STEP * (seq % TAGS)] * 360
    return scan


def tag_of(command: TwistStamped) -> int:
    """The scan number (mod TAGS) a command was computed from: its x is 0.35 - range = 0.01 (1 + tag)."""
    return round(command.twist.linear.x / STEP) - 1


class Robots:
    """The two robots' publishers, and every scan sent: agent -> [(seq, monotonic time)]."""

    def __init__(self, ros) -> None:
        self.ros = ros
        self.pubs = {(a, kind): ros.node.create_publisher(cls, f"/{a}/{kind}", 10)
                     for a in AGENTS for kind, cls in (("odom", Odometry), ("scan", LaserScan), ("goal", PoseStamped))}
        self.odom = Odometry()
        self.odom.header.frame_id, self.odom.child_frame_id = "odom", "agent/base_link"
        fill_odometry(self.odom, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        self.sent: Dict[str, List[Tuple[int, float]]] = {a: [] for a in AGENTS}
        self.seq = 0

    def feed(self, seconds: float, scan_period: float, scanning: Sequence[str] = AGENTS,
             until=lambda: False) -> None:
        """Odometry and goals every ODOM_PERIOD; every ``scan_period`` one tagged scan per robot in ``scanning``
        (for ``seconds``, or until ``until()``)."""
        end = time.monotonic() + seconds
        next_scan = time.monotonic()
        while (now := time.monotonic()) < end and not until():
            for a in AGENTS:
                self.pubs[a, "odom"].publish(self.odom)
                self.pubs[a, "goal"].publish(PoseStamped())
            if now >= next_scan:
                for a in scanning:
                    self.pubs[a, "scan"].publish(tagged_scan(self.seq))
                    self.sent[a].append((self.seq, time.monotonic()))
                self.seq += 1
                next_scan += scan_period
            self.ros.spin_for(min(ODOM_PERIOD, max(0.0, next_scan - time.monotonic())) or 0.001)

    def since(self, agent: str, start: float) -> List[Tuple[int, float]]:
        return [(seq, t) for seq, t in self.sent[agent] if t >= start]


def acted_on(commands, sent: List[Tuple[int, float]], start: float) -> List[Tuple[int, float]]:
    """(seq of the scan each command since ``start`` came from, the delay from that scan to the command).

    A command's tag names the scan among the last TAGS sent before it arrived (the newest with that tag).
    """
    found = []
    for msg, arrived in zip(commands.messages, commands.arrivals):
        if arrived < start:
            continue
        before = [(seq, t) for seq, t in sent if t <= arrived and seq % TAGS == tag_of(msg)]
        assert before, f"a command tagged {tag_of(msg)} at {arrived:.3f} matches no scan sent before it"
        seq, t = before[-1]
        found.append((seq, arrived - t))
    return found


def test_commands_follow_complete_sets_of_scans_not_the_timer(ros, policy_node, tmp_path):
    commands = {a: ros.collect(TwistStamped, f"/{a}/cmd_vel") for a in AGENTS}
    robots = Robots(ros)
    with policy_node(policy_path=str(tagging_policy(tmp_path)), adapter="navigation", output="cmd_vel",
                     use_stamped_cmd_vel=True, act_on="scan", rate_hz=10.0, observation_timeout=1.0) as node:
        node.wait_publishing([f"/{a}/cmd_vel" for a in AGENTS])
        # odometry and goals but no scans: nothing acts, and the node still says what is missing
        missing = "no command for agent_0: nothing received on agent_0/scan yet"
        robots.feed(15.0, scan_period=10.0, scanning=(), until=lambda: missing in node.output())
        assert missing in node.output(), node.describe()
        assert not any(len(c) for c in commands.values()), "acted without any scan"
        robots.feed(15.0, scan_period=0.3, until=lambda: all(len(c) >= 3 for c in commands.values()))
        assert "on every complete set of new scans on ['agent_0/scan', 'agent_1/scan']" in node.output()

        # scans at ~3.3 Hz, slower than the 10 Hz timer: one command per set, straight after it
        start = time.monotonic()
        robots.feed(3.0, scan_period=0.3)
        robots.feed(0.3, scan_period=10.0, scanning=())  # the last set's commands arrive
        for a in AGENTS:
            sent, acts = robots.since(a, start), acted_on(commands[a], robots.sent[a], start)
            seqs = [seq for seq, _ in acts]
            assert len(seqs) == len(set(seqs)), f"{a}: acted more than once on a scan: {seqs}"
            assert seqs == sorted(seqs), f"{a}: commands out of the scans' order: {seqs}"
            assert len(acts) >= len(sent) - 2, f"{a}: {len(acts)} commands for {len(sent)} sets\n{node.describe()}"
            assert len(acts) <= len(sent) + 1, f"{a}: {len(acts)} commands for {len(sent)} sets: the timer's rate?"

        # runtime changes: act_on is start-only; a 1 Hz rate_hz only moves the deadline, which complete
        # sets never wait for: still one command per set, each long before a period is up
        refused, = ros.set_parameters("/policy_node", act_on="timer")
        assert not refused.successful and "read-only" in refused.reason
        ros.spin_until(lambda: "refused parameter change: act_on is start-only" in node.output(), 5.0,
                       "the node's own word on the refusal")
        changed, = ros.set_parameters("/policy_node", rate_hz=1.0)
        assert changed.successful, changed.reason
        start = time.monotonic()
        robots.feed(2.5, scan_period=0.25)
        robots.feed(0.3, scan_period=10.0, scanning=())
        for a in AGENTS:
            sent, acts = robots.since(a, start), acted_on(commands[a], robots.sent[a], start)
            assert len(acts) >= len(sent) - 2 and len({seq for seq, _ in acts}) == len(acts), (a, acts, len(sent))
            assert statistics.median(d for _, d in acts) < 0.5, f"{a}: waited for the 1 s deadline: {acts}"
    assert node.returncode == 0, node.describe()
    for collector in commands.values():
        collector.destroy()


def test_a_silent_robot_holds_the_others_back_one_period_at_most(ros, policy_node, tmp_path):
    commands = {a: ros.collect(TwistStamped, f"/{a}/cmd_vel") for a in AGENTS}
    robots = Robots(ros)
    timeout, period = 1.5, 0.25
    with policy_node(policy_path=str(tagging_policy(tmp_path)), adapter="navigation", output="cmd_vel",
                     use_stamped_cmd_vel=True, act_on="scan", rate_hz=1.0 / period,
                     observation_timeout=timeout) as node:
        node.wait_publishing([f"/{a}/cmd_vel" for a in AGENTS])
        robots.feed(15.0, scan_period=0.4, until=lambda: all(len(c) >= 3 for c in commands.values()))
        assert all(len(c) >= 3 for c in commands.values()), node.describe()

        # agent_1 goes silent; within observation_timeout of its last scan agent_0's sets wait for it, one
        # period each, then act with what there is (agent_1: its last scan, still young enough)
        silent_from = time.monotonic()
        last_of_1 = robots.sent["agent_1"][-1][0]
        robots.feed(timeout - 0.3, scan_period=0.4, scanning=("agent_0",))
        waited_until = time.monotonic()
        sent = robots.since("agent_0", silent_from)
        acts = acted_on(commands["agent_0"], robots.sent["agent_0"], silent_from)
        acts = [(seq, d) for seq, d in acts if seq in {s for s, _ in sent}]
        assert len(acts) >= len(sent) - 1 and len(sent) >= 2, (acts, sent, node.describe())
        assert all(d >= 0.8 * period for _, d in acts), f"acted before the deadline, not waiting for agent_1: {acts}"
        assert all(d <= period + 0.6 for _, d in acts), f"agent_0 waited more than about one period: {acts}"
        stale_1 = [tag_of(m) for m in commands["agent_1"].since(silent_from)]
        assert set(stale_1) <= {last_of_1 % TAGS}, f"agent_1 was commanded from a scan it never sent: {stale_1}"

        # past observation_timeout agent_1 is not scanning: agent_0 acts at once, agent_1 gets nothing
        robots.feed(silent_from + timeout + 0.2 - time.monotonic(), scan_period=0.4, scanning=("agent_0",))
        free_from = time.monotonic()
        robots.feed(2.0, scan_period=0.4, scanning=("agent_0",))
        robots.feed(0.3, scan_period=10.0, scanning=())
        acts = acted_on(commands["agent_0"], robots.sent["agent_0"], free_from)
        assert len(acts) >= len(robots.since("agent_0", free_from)) - 1, acts
        assert statistics.median(d for _, d in acts) < 0.8 * period, f"still waiting for agent_1: {acts}"
        late = commands["agent_1"].since(silent_from + timeout + 0.3)
        assert not late, f"{len(late)} commands for agent_1 after its scan went stale"
        assert waited_until < free_from
    log = node.output()
    assert f"no command for agent_1: agent_1/scan is older than observation_timeout ({timeout:g} s)" in log, log
    for collector in commands.values():
        collector.destroy()


# ============================================================== refused at start
@pytest.fixture(scope="module")
def refused(policy_node, tmp_path_factory):
    directory = tmp_path_factory.mktemp("act_on_bad")
    spread = str(constant_push(directory, "spread", [0.1, 0.0], obs_size=10))
    cases = {
        "bad value": {"policy_path": str(tagging_policy(directory)), "adapter": "navigation", "act_on": "sometimes"},
        "no scans": {"policy_path": spread, "adapter": "simple_spread", "adapter_kwargs": {"obs_agents": False},
                     "act_on": "scan"},
    }
    processes = {name: policy_node(**params) for name, params in cases.items()}
    codes = wait_all(processes.values(), timeout=60.0)
    return {name: (processes[name], code) for name, code in zip(processes, codes)}


@pytest.mark.parametrize("case, expected", [
    ("bad value", "act_on must be one of timer, scan, got 'sometimes'"),
    ("no scans", "act_on: scan needs scans to act on, but adapter simple_spread reads no sensor_msgs/LaserScan "
                 "topic (it reads agent_0/odom, agent_1/odom, agent_2/odom, landmarks/poses); use act_on: timer"),
])
def test_act_on_is_refused_with_the_reason(refused, case, expected):
    process, code = refused[case]
    stderr = process.stderr()
    assert code == 2, process.describe()
    assert "policy_node: refused parameters" in stderr and expected in stderr, stderr
    assert "Traceback" not in stderr, stderr
