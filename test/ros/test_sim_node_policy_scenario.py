"""sim_node's scenario from the policy it runs, as real ROS 2 processes; and lidar geometry refused at start.

A linear policy exported for navigation with two agents (policy_files.py).
Started with only ``control: policy`` and its ``policy_path``, the node runs
navigation with those kwargs and says so; given ``scenario:=simple_spread``
on the command line (the default's value, given explicitly) it keeps that and
refuses the policy, which does not fit. A start with a lidar whose
``lidar_angle_max`` is below its ``lidar_angle_min`` exits with code 2, naming
both values.
"""
from __future__ import annotations

import json
import time

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray

from test.ros.conftest import NODE, wait_all
from test.ros.policy_files import write_policy

pytestmark = [pytest.mark.ros, pytest.mark.slow]

KWARGS = {"n_agents": 2, "lidar_range": 0.5}
OBS_SIZE = 2 + 2 + 2 + 12  # navigation: position, velocity, to the goal, 12 lidar rays


@pytest.fixture(scope="module")
def navigation_policy(tmp_path_factory):
    return write_policy(tmp_path_factory.mktemp("policy"), "navigation", np.zeros((OBS_SIZE, 2)), [0.0, 0.0],
                        agents=("agent_0", "agent_1"), scenario="navigation", scenario_kwargs=KWARGS)


@pytest.fixture(scope="module")
def refused(sim_process, navigation_policy):
    """The processes that must refuse their start, started together and awaited together."""
    processes = {
        "simple_spread given": sim_process(scenario="simple_spread", control="policy",
                                           policy_path=str(navigation_policy)),
        "lidar angles": sim_process(lidar_angle_min=1.0, lidar_angle_max=0.5),
    }
    codes = wait_all(processes.values(), timeout=60.0)
    return {name: (process, code) for (name, process), code in zip(processes.items(), codes)}


def test_the_policys_scenario_and_kwargs_when_none_is_given(ros, sim_node, navigation_policy):
    with sim_node(control="policy", policy_path=str(navigation_policy)) as sim:
        scenario, kwargs = ros.get_parameters(NODE, "scenario", "scenario_kwargs")
        assert scenario == "navigation" and json.loads(kwargs) == KWARGS
        agents = ros.collect(PoseArray, "/agents/poses")
        try:
            assert len(agents.wait_for(1)[-1].poses) == 2
        finally:
            agents.destroy()
        expected = (f"scenario navigation and scenario_kwargs {json.dumps(KWARGS)} from the policy's metadata "
                    f"{navigation_policy}")
        deadline = time.monotonic() + 5.0
        while expected not in sim.output() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert expected in sim.output(), sim.describe()
        assert "the policy was trained" not in sim.output(), "no warning: the policy's own scenario and kwargs"


def test_a_scenario_given_explicitly_is_kept(refused):
    process, code = refused["simple_spread given"]
    output = process.output()
    assert code == 2, process.describe()
    assert "from the policy's metadata" not in output
    assert "does not fit scenario" in output and "observation_size 18" in output, output


def test_lidar_angles_out_of_order_exit_2_naming_both(refused):
    process, code = refused["lidar angles"]
    assert code == 2, process.describe()
    stderr = process.stderr()
    assert "lidar_angle_max must be greater than lidar_angle_min, got 0.5 <= 1.0" in stderr, stderr
    assert "Traceback" not in stderr
