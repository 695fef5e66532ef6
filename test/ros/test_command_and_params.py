"""cmd_vel -> action translation, message conversion and parameter rules (no ROS graph needed)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from vmas_ros.ros import convert
from vmas_ros.simulator import env_snapshot
from vmas_ros.ros.command import command_to_action
from vmas_ros.ros.params import SimParams, validate
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.dynamics.diff_drive import DiffDrive
from vmas_ros.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation
from vmas_ros.simulator.dynamics.kinematic_bicycle import KinematicBicycle


def _world(device, dynamics_factory=None, yaw=0.0, u_range=1.0, drag=0.25):
    world = World(batch_dim=3, device=device, drag=drag)
    agent = Agent(name="robot", shape=Sphere(0.1), u_range=u_range,
                  dynamics=dynamics_factory(world) if dynamics_factory else None)
    world.add_agent(agent)
    agent.set_rot(torch.tensor([yaw], device=device), batch_index=None)
    return world, agent


def _drive(world, agent, env_index, linear, wz, seconds):
    """Apply the translated command to one env for ``seconds`` of simulated time."""
    for _ in range(round(seconds / world.dt)):
        u = torch.zeros(world.batch_dim, agent.action_size, device=world.device)
        u[env_index] = command_to_action(agent, world, env_index, linear, wz)
        agent.action.u = u * agent.action.u_multiplier_tensor
        agent.dynamics.check_and_process_action()
        world.step()


@pytest.mark.parametrize("yaw", [0.0, math.pi / 2, -2.0])
def test_holonomic_agent_reaches_body_frame_velocity_within_a_second(device, yaw):
    world, agent = _world(device, yaw=yaw)
    _drive(world, agent, 1, (0.3, -0.2), 0.0, seconds=1.0)
    c, s = math.cos(yaw), math.sin(yaw)
    expected = torch.tensor([0.3 * c + 0.2 * s, 0.3 * s - 0.2 * c], device=device)
    assert torch.allclose(agent.state.vel[1], expected, rtol=0.05, atol=1e-3)
    assert torch.equal(agent.state.vel[0], torch.zeros(2, device=device)), "other envs are not commanded"


def test_force_limits_show_as_slower_approach(device):
    world, agent = _world(device, u_range=0.1)
    _drive(world, agent, 0, (1.0, 0.0), 0.0, seconds=0.2)
    assert 0 < float(agent.state.vel[0, 0]) < 0.5, "a weak agent cannot reach 1 m/s in 0.2 s"


def test_holonomic_with_rotation_tracks_yaw_rate(device):
    world, agent = _world(device, lambda w: HolonomicWithRotation())
    _drive(world, agent, 2, (0.0, 0.0), 0.5, seconds=1.0)
    assert abs(float(agent.state.ang_vel[2, 0]) - 0.5) < 0.025


def test_diff_drive_takes_forward_speed_and_yaw_rate(device):
    world, agent = _world(device, lambda w: DiffDrive(w))
    action = command_to_action(agent, world, 0, (0.4, 0.9), 0.3)  # at rest: no drag share yet
    torch.testing.assert_close(action, torch.tensor([0.4, 0.3], device=device))
    _drive(world, agent, 0, (0.2, 0.0), 0.0, seconds=1.0)
    assert float(agent.state.vel[0, 0]) == pytest.approx(0.2, rel=0.05)
    assert abs(float(agent.state.pos[0, 1])) < 1e-4, "no sideways motion"
    _drive(world, agent, 0, (0.2, 0.0), 0.5, seconds=1.0)
    assert float(agent.state.ang_vel[0, 0]) == pytest.approx(0.5, rel=0.05)


def test_bicycle_steering_gives_the_commanded_yaw_rate(device):
    world, agent = _world(
        device, lambda w: KinematicBicycle(w, width=0.1, l_f=0.1, l_r=0.1, max_steering_angle=math.pi / 4)
    )
    _drive(world, agent, 0, (0.3, 0.0), 0.4, seconds=1.0)
    assert abs(float(agent.state.ang_vel[0, 0]) - 0.4) < 0.04


def test_laser_scan_geometry_and_no_return_is_inf():
    class FakeLidar:  # only the two attributes ScanGeometry reads
        angles = torch.linspace(0, 2 * math.pi, 13)[:12].unsqueeze(0)
        max_range = 2.0

    geometry = env_snapshot.ScanGeometry.of(FakeLidar())
    count = round((geometry.angle_max - geometry.angle_min) / geometry.angle_increment) + 1
    assert count == 12
    from sensor_msgs.msg import LaserScan

    msg = LaserScan()
    ranges = np.full(12, 2.0, dtype=np.float32)
    ranges[3] = 0.5
    convert.fill_scan(msg, geometry, ranges)
    assert len(msg.ranges) == 12 and msg.ranges[3] == pytest.approx(0.5)
    assert all(math.isinf(r) for i, r in enumerate(msg.ranges) if i != 3)
    assert msg.range_max == 2.0


def test_odometry_twist_is_in_the_body_frame():
    from nav_msgs.msg import Odometry

    msg = Odometry()
    convert.fill_odometry(msg, 1.0, 2.0, math.pi / 2, 0.0, 0.5, 0.1)  # moving +y while facing +y
    assert msg.twist.twist.linear.x == pytest.approx(0.5) and msg.twist.twist.linear.y == pytest.approx(0.0, abs=1e-9)
    assert msg.pose.pose.orientation.z == pytest.approx(math.sin(math.pi / 4))


def test_names_are_valid_ros_tokens_and_unique():
    assert env_snapshot.unique_names(["agent 0", "agent_0", "1st", "a-b"]) == ["agent_0", "agent_0_1", "n1st", "a_b"]


@pytest.mark.parametrize(
    "name,value,needle",
    [
        ("num_envs", 0, "num_envs"), ("num_envs", 2.5, "integer"), ("scenario", "nope", "valid"),
        ("scenario", "simple_spred", "did you mean 'simple_spread'"),
        ("control", "bogus", "control"), ("real_time_factor", -1.0, "0 (off) or in [0.001, 1e+06]"), ("device", "tpu", "device"),
        ("scenario_kwargs", "[1, 2]", "mapping"), ("lidar_range", 0.0, "> 0"), ("add_lidar", "yes", "true or false"),
        ("rate_hz", float("nan"), "finite"), ("unpaced_batch_ms", 1500.0, "[0, 1000]"),
        ("unpaced_batch_ms", -0.5, "[0, 1000]"),
    ],
)
def test_bad_parameters_are_refused_with_a_reason(name, value, needle):
    error = validate(name, value)
    assert error is not None and needle in error


def test_good_parameters_pass_and_env_index_is_bounded_by_num_envs():
    defaults = SimParams()
    assert all(validate(n, getattr(defaults, n)) is None for n in SimParams.names())
    assert validate("env_index", 3, SimParams(num_envs=4)) is None
    assert "env_index" in validate("env_index", 4, SimParams(num_envs=4))
    assert SimParams(scenario_kwargs="{n_agents: 4}").kwargs() == {"n_agents": 4}


def test_step_period_from_rate_and_real_time_factor():
    assert SimParams(rate_hz=50.0).step_period(0.1) == pytest.approx(0.02)
    assert SimParams(real_time_factor=2.0).step_period(0.1) == pytest.approx(0.05)
    assert SimParams(real_time_factor=0.0).step_period(0.1) == 0.0


# ------------------------------------------------ one table: help, descriptors
def test_every_parameter_is_described_once_with_its_descriptor():
    from vmas_ros.ros.params import POLICY_PARAMS, SIM_PARAMS

    for table in (SIM_PARAMS, POLICY_PARAMS):
        text = table.help()
        for name, p in table.params.items():
            assert f"  {name} " in text and p.description in text, name
            d = table.descriptor(name)
            assert d.name == name and d.description == p.description and d.read_only == (not p.runtime)
            assert d.dynamic_typing, "a parameter file's 1 for a double must still load"
    assert SIM_PARAMS.descriptor("num_envs").integer_range[0].to_value == 10_000_000
    assert SIM_PARAMS.descriptor("unpaced_batch_ms").floating_point_range[0].to_value == 1000.0
    assert not SIM_PARAMS.descriptor("rate_hz").floating_point_range, "0 (off) is outside [0.001, 1e6]"
    assert "0 (off) or in [0.001, 1e+06]" in SIM_PARAMS.descriptor("rate_hz").additional_constraints


@pytest.mark.parametrize("argv", [["-m", "vmas_ros.ros.sim_node", "--help"], ["-m", "vmas_ros.ros.policy_node", "-h"],
                                  ["-m", "vmas_ros.cli", "sim", "--help"]])
def test_help_lists_every_parameter_and_exits_0(argv):
    import subprocess
    import sys

    from vmas_ros.ros.params import POLICY_PARAMS, SIM_PARAMS

    done = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    table = POLICY_PARAMS if "policy_node" in argv[1] else SIM_PARAMS
    missing = [name for name in table.names() if f"\n  {name} " not in done.stdout]
    assert not missing, done.stdout
    assert "start-only" in done.stdout and "runtime" in done.stdout
