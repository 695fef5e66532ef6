"""kinematic_bicycle (debug): a car-like robot beside an omnidirectional one.

Description
    A playground for the ``KinematicBicycle`` dynamics (front-wheel steering,
    integrated with Euler). Agent ``bicycle_0`` is commanded with (speed,
    steering angle), both limited (``max_speed``, ``max_steering_angle``);
    every further agent ``holo_rot_<i>`` is holonomic with its own heading,
    commanded with a world-frame force and a torque (scaled by 0.001). All are
    colliding boxes ``l_f + l_r`` long and ``width`` wide, in a world with 10
    substeps and collision force 500. There is no task: the reward is always
    zero.
Observation (per agent, in this order)
    own position (2), own velocity (2).
Reward
    Zero, shape [B].
Starting state
    Agents uniform in [-1, 1]^2 with centres at least 0.1 apart, at rest,
    heading 0.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``n_agents`` (2; the first is the bicycle), ``width`` (0.1), ``l_f`` (0.1,
    centre of gravity to front axle), ``l_r`` (0.1, to rear axle),
    ``max_steering_angle`` (30 degrees in rad; VMAS's default is a 0-d
    tensor, here a float; a 0-d tensor is accepted), ``max_speed`` (1.0).

Heuristic
    As there is no reward, the shipped ``HeuristicPolicy`` drives every agent
    home to the origin and is measured on the distance to it.
"""
from __future__ import annotations

import math
from typing import Sequence

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_int, continuous_heuristic_kwargs, read_kwargs
from vmas_ros.scenarios.debug.diff_drive import (
    HOLO_MULTIPLIER, SUBSTEPS, TASK_SCORE, SpawnScenario, holonomic_home, steer_home, task_score,
)
from vmas_ros.simulator.core import Agent, Box, World
from vmas_ros.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation
from vmas_ros.simulator.dynamics.kinematic_bicycle import KinematicBicycle
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy

DEFAULTS = {
    "n_agents": 2, "width": 0.1, "l_f": 0.1, "l_r": 0.1,
    "max_steering_angle": math.radians(30.0), "max_speed": 1.0,
}
COLLISION_FORCE = 500
__all__ = ["HeuristicPolicy", "Scenario", "TASK_SCORE", "task_score"]  # the task score is diff_drive's


def validate(config: dict) -> dict:
    """The config with numbers as floats; raise ValueError for a value the robot cannot be built with."""
    check_int("kinematic_bicycle", "n_agents", config["n_agents"])
    out = dict(config)
    for name, value in config.items():
        if name == "n_agents":
            continue
        if isinstance(value, torch.Tensor) and value.numel() == 1:
            value = float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"kinematic_bicycle: {name} must be a finite number, got {value!r}")
        out[name] = float(value)
    for name in ("width", "max_speed"):
        if not out[name] > 0:
            raise ValueError(f"kinematic_bicycle: {name} must be > 0, got {config[name]!r}")
    for name in ("l_f", "l_r"):
        if out[name] < 0:
            raise ValueError(f"kinematic_bicycle: {name} must be >= 0 (an axle distance), got {config[name]!r}")
    if not out["l_f"] + out["l_r"] > 0:
        raise ValueError(f"kinematic_bicycle: l_f + l_r (the wheelbase) must be > 0, got l_f={out['l_f']}, "
                         f"l_r={out['l_r']}")
    if not 0 < out["max_steering_angle"] < math.pi / 2:
        raise ValueError("kinematic_bicycle: max_steering_angle must be in (0, pi/2) rad, "
                         f"got {config['max_steering_angle']!r}")
    return out


class Scenario(SpawnScenario):
    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = validate(read_kwargs(kwargs, DEFAULTS))
        self.n_agents = config["n_agents"]
        width, l_f, l_r = config["width"], config["l_f"], config["l_r"]
        max_steer, max_speed = config["max_steering_angle"], config["max_speed"]
        self.plot_grid = True

        world = World(batch_dim, device, substeps=SUBSTEPS, collision_force=COLLISION_FORCE)
        world.add_agent(Agent(
            name="bicycle_0", shape=Box(length=l_f + l_r, width=width), collide=True, render_action=True,
            u_range=[max_speed, max_steer], u_multiplier=[1, 1], max_speed=max_speed,
            dynamics=KinematicBicycle(
                world, width=width, l_f=l_f, l_r=l_r, max_steering_angle=max_steer, integration="euler",
            ),
        ))
        for i in range(1, self.n_agents):
            world.add_agent(Agent(
                name=f"holo_rot_{i}", shape=Box(length=l_f + l_r, width=width), collide=True,
                render_action=True, u_range=[1, 1, 1], u_multiplier=HOLO_MULTIPLIER,
                dynamics=HolonomicWithRotation(),
            ))
        return world


class HeuristicPolicy(BaseHeuristicPolicy):
    """Drive home to the origin (there is no reward to chase; see the module docstring).

    The robot is told by the action size, ``len(u_range)``: 2 for the bicycle
    (speed, steering angle: the steering turns the velocity, which is the
    heading plus the small slip angle, towards the origin; see
    ``diff_drive.steer_home``), 3 for the holonomic ones (a PD force to the
    origin, no torque). Near the origin the bicycle circles at its smallest
    turning radius, ``(l_f + l_r) / tan(max_steering_angle)`` about. Continuous
    actions only.
    """

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        validate(continuous_heuristic_kwargs("kinematic_bicycle", DEFAULTS, scenario_kwargs, continuous_action))

    def compute_action(self, observation: Tensor, u_range: Sequence[float]) -> Tensor:
        if len(u_range) == 3:
            return holonomic_home(observation, u_range)
        speed, steering = steer_home(observation, float(u_range[0]), float(u_range[1]), turn_gain=3.0)
        return torch.stack([speed, steering], dim=-1)
