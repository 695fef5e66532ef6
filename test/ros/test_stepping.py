"""sim_node's step loop (stepping.py): unpaced bursts publish every step, in order, and a fault mid-burst
leaves the steps before it published and recorded (in-process node, real rclpy, the bag read by rosbags)."""
from __future__ import annotations

import pytest
from rclpy.parameter import Parameter

import test.ros.faulty_sim  # noqa: F401 - registers the faulty_spread scenario
from test.ros.fault_tools import assert_whole_steps, read_finished
from vmas_ros.ros import stepping
from vmas_ros.ros.lifecycle import SimulationFault
from vmas_ros.ros.sim_node import SimNode

pytestmark = pytest.mark.ros

DT_NS = 100_000_000  # simple_spread's dt


@pytest.fixture
def make_node(on_test_context):
    """SimNode(**params), unpaced, on the module's rclpy context; destroyed (its bag closed) after the test."""
    nodes = []

    def make(**params):
        nodes.append(SimNode(real_time_factor=0.0, lidar_rays=6, **params))
        return nodes[-1]

    yield make
    for node in nodes:
        node.destroy_node()


def test_a_burst_computes_its_steps_then_publishes_each_in_order(make_node, tmp_path):
    bag = tmp_path / "burst.mcap"
    node = make_node(record_path=str(bag), control="heuristic")
    emitted = []  # (the step emitted, how many steps were computed when it went out)
    emit = node._emit
    node._emit = lambda step: (emitted.append((step.steps, node.steps)), emit(step))[1]
    node._run_steps(stepping.UNPACED_BURST, None)
    assert emitted == [(k, stepping.UNPACED_BURST) for k in range(1, stepping.UNPACED_BURST + 1)]
    pose = node.state_messages.decode("agent_0/pose").pose.position  # the last message is the last step's
    x, y = node.env.world.agents[0].state.pos[0].tolist()
    assert (pose.x, pose.y) == pytest.approx((x, y), abs=1e-6)
    for _ in range(3):
        node._tick()  # unpaced: bursts for about unpaced_batch_ms
    steps = node.steps
    node.destroy_node()
    recorded = read_finished(bag)
    assert_whole_steps(recorded, DT_NS)  # every step, once, stamped 0, dt, 2 dt, ...
    assert len(recorded.steps()) == steps + 1  # and the initial state


@pytest.mark.parametrize("fault, expect", [
    ("raise", "the scenario 'faulty_spread' (Environment.step)"),
    ("nan_state", "no non-finite value was published"),
    ("nan_reward", "NaN in the observations or rewards of env 0"),
])
def test_a_fault_mid_burst_comes_after_the_steps_before_it(make_node, tmp_path, fault, expect):
    bag = tmp_path / f"{fault}.mcap"
    fault_step = 5  # inside the first burst
    node = make_node(scenario="faulty_spread", record_path=str(bag),
                     scenario_kwargs=f'{{"fault": "{fault}", "fault_step": {fault_step}}}')
    with pytest.raises(SimulationFault) as raised:
        node._run_steps(stepping.UNPACED_BURST, None)
    assert str(raised.value).startswith(f"step {fault_step} (t=0.500 s) failed in") and expect in str(raised.value)
    node.destroy_node()
    recorded = read_finished(bag)
    assert_whole_steps(recorded, DT_NS)
    assert len(recorded.steps()) == fault_step, "steps 0..4 recorded, the faulty one not"


def test_unpaced_batch_ms_sets_how_long_a_tick_steps(make_node):
    node = make_node(unpaced_batch_ms=0.0)  # the most responsive: one step per executor round
    for expected in (1, 2, 3):
        node._tick()
        assert node.steps == expected
    result = node.set_parameters([Parameter("unpaced_batch_ms", value=50.0)])  # runtime
    assert result[0].successful and node.params.unpaced_batch_ms == 50.0
    node._tick()
    assert node.steps >= 3 + 2, "50 ms of steps in one tick"
    refused = node.set_parameters([Parameter("unpaced_batch_ms", value=-1.0)])
    # the descriptor's range: rclpy refuses before the node's own check
    assert not refused[0].successful and "unpaced_batch_ms out of range" in refused[0].reason
