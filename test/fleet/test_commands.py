"""The command queue: latency, timeout, new episodes; and the commands refused."""
from __future__ import annotations

import math

import pytest

from vmas_ros.fleet.commands import CommandBuffer, command_problem


def test_a_command_takes_effect_after_the_latency_and_lapses_after_the_timeout():
    buffer = CommandBuffer(2, latency=0.05, timeout=0.5)
    buffer.push(0, (1.0, 0.5, 0.2), now=10.0)
    assert buffer.target(10.04).tolist() == [[0.0] * 3] * 2
    assert buffer.target(10.05).tolist() == [[1.0, 0.5, 0.2], [0.0] * 3]
    assert buffer.target(10.55).tolist()[0] == [1.0, 0.5, 0.2]  # age 0.5 s since it took effect
    assert buffer.target(10.56).tolist()[0] == [0.0] * 3


def test_commands_queue_in_order_per_robot():
    buffer = CommandBuffer(2, latency=0.1, timeout=1.0)
    buffer.push(0, (1.0, 0.0, 0.0), now=0.0)
    buffer.push(1, (0.0, 1.0, 0.0), now=0.02)
    buffer.push(0, (2.0, 0.0, 0.0), now=0.05)
    assert buffer.target(0.11).tolist() == [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    assert buffer.target(0.13).tolist() == [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    assert buffer.target(0.16).tolist() == [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0]]


def test_without_latency_a_command_acts_at_once_and_clear_forgets_everything():
    buffer = CommandBuffer(1, latency=0.0, timeout=0.5)
    buffer.push(0, (0.3, 0.0, 0.0), now=1.0)
    assert buffer.target(1.0).tolist() == [[0.3, 0.0, 0.0]]
    buffer.push(0, (0.7, 0.0, 0.0), now=1.1)
    buffer.clear()
    assert buffer.target(1.1).tolist() == [[0.0, 0.0, 0.0]]


@pytest.mark.parametrize("values, named", [
    ((math.nan, 0, 0, 0, 0, 0), "linear.x=nan"),
    ((0, math.inf, 0, 0, 0, 0), "linear.y=inf"),
    ((0, 0, 0, 0, 0, -math.inf), "angular.z=-inf"),
    ((0, 0, 0, 0, 0, 2e6), "angular.z=2e+06"),
    ((0, 0, -1e7, 0, 0, 0), "linear.z=-1e+07"),
])
def test_bad_commands_are_named(values, named):
    problem = command_problem(values)
    assert problem is not None and named in problem and "expected" in problem


def test_ordinary_commands_pass():
    assert command_problem((1.0, -0.5, 0.0, 0.0, 0.0, 2.0)) is None
    assert command_problem((1e6, 0, 0, 0, 0, -1e6)) is None
