"""sim_node's default compile_physics (auto): it compiles in the background and never stops publishing.

A real node process, with the default mode on (the suite's VMAS_ROS_COMPILE=0
is lifted for it): /clock must advance by exactly one step at a time through
the switch to the compiled step, and no wait between two /clock messages may
come near the time the compile took.
"""
from __future__ import annotations

import re

import pytest
from rosgraph_msgs.msg import Clock

from test.ros.conftest import stamp_ns
from vmas_ros.simulator.compile_default import compiler_missing

pytestmark = [pytest.mark.ros, pytest.mark.serial]  # it times the waits between /clock messages

RATE_HZ = 100.0  # paced: a compile that held the node would leave a wait of its whole length between two ticks
READY = re.compile(r"compile_physics: compiled step in use from step (\d+) \(compiled in ([0-9.]+) s\)")


@pytest.mark.slow
def test_the_node_switches_to_the_compiled_step_without_a_clock_gap(ros, sim_node, monkeypatch):
    if compiler_missing("cpu"):
        pytest.fail(f"the test machine needs a C++ compiler: {compiler_missing('cpu')}")
    monkeypatch.setenv("VMAS_ROS_COMPILE", "auto")  # the node's default mode, as users get it
    clock = ros.collect(Clock, "/clock", depth=100_000)
    with sim_node(scenario="simple_spread", scenario_kwargs={"n_agents": 4}, rate_hz=RATE_HZ,
                  lidar_rays=12) as sim:
        assert "compile_physics: auto: compiling the step in the background" in sim.output()
        ros.spin_until(lambda: READY.search(sim.output()), 600, "the node's compiled step in use")
        switch_step, compile_s = (float(g) for g in READY.search(sim.output()).groups())
        ros.spin_for(1.0)  # steps after the switch
    dt_ns = 100_000_000  # simple_spread's dt (0.1 s)
    times = [stamp_ns(m.clock) for m in clock.messages]
    steps = [t // dt_ns for t in times]
    assert len(steps) > switch_step + 20, f"only {len(steps)} /clock messages around the switch at {switch_step:.0f}"
    # every step published once, in order: no step lost or repeated at the switch
    assert all(t % dt_ns == 0 for t in times)
    assert steps == list(range(steps[0], steps[0] + len(steps)))
    assert steps[0] <= switch_step <= steps[-1]
    # the node kept publishing while it compiled: no wait between two messages near the compile's length
    gaps = [b - a for a, b in zip(clock.arrivals, clock.arrivals[1:])]
    assert compile_s > 1.0, f"a compile of {compile_s} s cannot tell a pause from none"
    assert max(gaps) < min(1.0, compile_s / 2), f"longest wait between /clock messages {max(gaps):.3f} s"
