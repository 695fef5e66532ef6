"""The robot model: velocity lag, the controller's limits, the drives and the body-frame integration."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vmas_ros.fleet.kinematics import DriveModel, MotionState, integrate, limit_command, respond, step, wrap_angle


def drive(model: DriveModel, target, seconds: float, dt: float = 0.01, pose=(0.0, 0.0, 0.0)) -> MotionState:
    state = MotionState.at_rest(np.array([pose]))
    target = np.array([target], dtype=float)
    for _ in range(int(round(seconds / dt))):
        state = step(state, target, dt, model)
    return state


def test_the_lag_reaches_1_minus_1_over_e_after_one_time_constant_whatever_the_step():
    model = DriveModel(velocity_lag=0.2)
    for dt in (0.001, 0.01, 0.05, 0.2):
        state = drive(model, (1.0, 0.0, 0.0), 0.2, dt)
        assert state.velocity[0, 0] == pytest.approx(1 - math.exp(-1), abs=1e-9)
    assert drive(model, (1.0, 0.0, 0.0), 1.0).velocity[0, 0] == pytest.approx(1 - math.exp(-5), abs=1e-9)


def test_without_lag_the_velocity_is_the_command_at_once():
    assert respond(np.zeros((1, 3)), np.array([[0.3, -0.2, 0.1]]), 0.01, 0.0).tolist() == [[0.3, -0.2, 0.1]]


def test_the_lag_follows_the_controller_output_not_the_raw_target():
    # the limiter's memory is its own last output: a lagging robot is not commanded harder
    model = DriveModel(velocity_lag=0.5, max_linear_accel=1.0)
    state = drive(model, (1.0, 0.0, 0.0), 0.5)
    assert state.command[0, 0] == pytest.approx(0.5)
    assert state.velocity[0, 0] < state.command[0, 0]


def test_acceleration_limits_ramp_the_command():
    model = DriveModel(max_linear_accel=2.0, max_angular_accel=4.0)
    out = limit_command(np.array([[1.0, 0.0, 2.0]]), np.zeros((1, 3)), 0.1, model)
    assert out == pytest.approx(np.array([[0.2, 0.0, 0.4]]))
    state = drive(model, (1.0, 0.0, 2.0), 0.3)
    assert state.velocity[0] == pytest.approx([0.6, 0.0, 1.2])
    state = drive(model, (1.0, 0.0, 2.0), 1.0)
    assert state.velocity[0] == pytest.approx([1.0, 0.0, 2.0])
    # braking is limited too
    out = limit_command(np.zeros((1, 3)), np.array([[1.0, 0.0, -2.0]]), 0.1, model)
    assert out == pytest.approx(np.array([[0.8, 0.0, -1.6]]))


def test_holonomic_accel_limit_bounds_the_change_of_the_velocity_vector():
    model = DriveModel(max_linear_accel=1.0)
    out = limit_command(np.array([[0.3, 0.4, 0.0]]), np.zeros((1, 3)), 0.1, model)
    assert out[0, :2] == pytest.approx([0.06, 0.08])


def test_speed_limits_clip_and_keep_a_holonomic_command_direction():
    model = DriveModel(max_linear_speed=1.0, max_angular_speed=2.0)
    out = limit_command(np.array([[3.0, 4.0, -5.0], [0.3, 0.4, 1.0]]), np.zeros((2, 3)), 0.01, model)
    assert out == pytest.approx(np.array([[0.6, 0.8, -2.0], [0.3, 0.4, 1.0]]))


def test_diff_drive_ignores_linear_y_and_clips_linear_x_alone():
    model = DriveModel(holonomic=False, max_linear_speed=1.0)
    out = limit_command(np.array([[0.5, 0.7, 0.0], [3.0, 4.0, 0.0]]), np.zeros((2, 3)), 0.01, model)
    assert out == pytest.approx(np.array([[0.5, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    state = drive(model, (0.5, 0.7, 0.0), 1.0, pose=(1.0, 2.0, 0.0))
    assert state.pose[0] == pytest.approx([1.5, 2.0, 0.0])


@pytest.mark.parametrize("yaw, body, expected", [
    (math.pi / 2, (1.0, 0.0), (0.0, 1.0)),    # facing +y, forward is +y
    (math.pi, (1.0, 0.0), (-1.0, 0.0)),
    (0.0, (0.0, 1.0), (0.0, 1.0)),            # left is +y when facing +x
    (math.pi / 2, (0.0, 1.0), (-1.0, 0.0)),   # left is -x when facing +y
])
def test_the_twist_is_in_the_body_frame(yaw, body, expected):
    state = drive(DriveModel(), (body[0], body[1], 0.0), 1.0, pose=(0.0, 0.0, yaw))
    assert state.pose[0, :2] == pytest.approx(expected, abs=1e-9)
    assert state.pose[0, 2] == pytest.approx(wrap_angle(yaw))


def test_driving_a_circle_integrates_the_heading_accurately():
    # a quarter turn at v = 1 m/s, w = pi/2 rad/s: a quarter circle of radius 2/pi
    state = drive(DriveModel(holonomic=False), (1.0, 0.0, math.pi / 2), 1.0, dt=0.01)
    radius = 2 / math.pi
    assert state.pose[0] == pytest.approx([radius, radius, math.pi / 2], abs=1e-4)


def test_integrate_is_batched_over_robots():
    pose = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2], [2.0, 0.0, -math.pi / 2]])
    out = integrate(pose, np.array([[1.0, 0.0, 0.0]] * 3), 0.5)
    assert out[:, :2] == pytest.approx(np.array([[0.5, 0.0], [1.0, 1.5], [2.0, -0.5]]))


def test_wrap_angle_maps_into_minus_pi_to_pi():
    angles = np.array([0.0, math.pi, -math.pi, 3 * math.pi / 2, -7.0, 100.0])
    wrapped = wrap_angle(angles)
    assert ((wrapped >= -math.pi) & (wrapped < math.pi)).all()
    assert np.cos(wrapped) == pytest.approx(np.cos(angles))
    assert np.sin(wrapped) == pytest.approx(np.sin(angles), abs=1e-12)
