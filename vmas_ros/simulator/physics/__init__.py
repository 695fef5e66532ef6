"""The batched physics step, one module per concern (VMAS's module path ``simulator.physics``).

``pipeline.step(state, tables, params, actions, fixed_rotation)`` advances
every env by ``dt`` and reads like the paper's equations:

- ``types``: the step's data: ``PlanarState`` (``q``, ``v``: ``[3, N, B]``),
  ``StepParams``;
- ``constants``: per-entity constants as ``[3, N, 1]`` columns, built once
  per layout (``StepConstants``);
- ``scales``: per-env scales of mass and drag, when a world has them;
- ``actions``: the agents' actions as the step's ``[3, N, B]`` input, clamped
  to their limits and zero where an agent is held;
- ``forces``: action, friction and gravity forces;
- ``joints``: joint springs and rotation locks;
- ``collision``: one contact kernel per pair of shape kinds, found through a
  table;
- ``scatter``: adding per-pair forces onto entities;
- ``integrator``: semi-implicit Euler, and how held entities stay still.

The sizes at which equivalent code paths switch are in
:mod:`vmas_ros.simulator.thresholds`, with the reason for each.

``World.step`` (:mod:`vmas_ros.simulator.world`) calls the pipeline on the
state its ``WorldState`` holds, eagerly or through ``torch.compile``.
"""
from vmas_ros.simulator.physics import scales
from vmas_ros.simulator.physics.constants import StepConstants, step_constants
from vmas_ros.simulator.physics.pipeline import step, step_vectors
from vmas_ros.simulator.physics.scales import DynamicsScales
from vmas_ros.simulator.physics.types import BodyState, PlanarState, StepParams, stack_actions

__all__ = [
    "BodyState", "DynamicsScales", "PlanarState", "StepConstants", "StepParams", "scales", "stack_actions", "step",
    "step_constants", "step_vectors",
]
