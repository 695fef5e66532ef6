"""The physics step: every env advanced by ``dt``, in ``substeps`` substeps (paper, "The VMAS platform").

Each substep, for every entity at once::

    f = f_action + f_friction + f_gravity     forces.applied_forces
      + f_joints                              joints.add_joint_forces
      + sum over pairs f_contact              collision.add_contact_forces
    v, x = semi-implicit Euler of f           integrator.substep

Joints are added before contacts: the order of the sums is VMAS's, which
worlds with stiff joints need for bit parity. Nothing here loops over envs or
entity pairs in Python, and nothing reads a tensor back to the host: the
number of kernels per step depends only on how many shape-pair kinds and
joints the world has, which also makes this a fixed-shape function that
``torch.compile`` can fuse (``World.compile_physics``).
"""
from __future__ import annotations

from typing import Optional, Tuple

from torch import Tensor

from vmas_ros.simulator.physics import forces, integrator
from vmas_ros.simulator.physics.actions import assemble_actions
from vmas_ros.simulator.physics.collision import add_contact_forces
from vmas_ros.simulator.physics.constants import step_constants
from vmas_ros.simulator.physics.joints import add_joint_forces
from vmas_ros.simulator.physics.types import BodyState, PlanarState, StepParams, stack_actions
from vmas_ros.simulator.tables import WorldTables

__all__ = ["advance", "step", "step_vectors"]


def advance(state: PlanarState, tables: WorldTables, params: StepParams, actions,
            fixed_rotation: Optional[Tensor], kernels: tuple = ()) -> Tuple[PlanarState, tuple]:
    """What ``World.step`` runs, and what ``compile_physics`` compiles: :func:`step`, then each state kernel
    (``World.add_state_kernel``) on the new state, ``(new state, kernel outputs)``.

    ``actions`` is the ``[3, N, B]`` input, or the agents' (forces, torques) lists to assemble it from
    (in the compiled graph, where that costs nothing; see ``actions.assemble_actions``).
    """
    if isinstance(actions, tuple):
        actions = assemble_actions(state.q, tables, *actions)
    new = step(state, tables, params, actions, fixed_rotation, actions_writable=True)
    return new, tuple(None if kernel is None else kernel(new.q, new.v) for kernel in kernels)


def step(state: PlanarState, tables: WorldTables, params: StepParams, actions: Tensor,
         fixed_rotation: Optional[Tensor], actions_writable: bool = False) -> PlanarState:
    """The state ``dt`` later. ``actions``: ``[3, N, B]`` (fx, fy, torque per entity; see ``stack_actions``);
    ``fixed_rotation``: the joints' ``[J, B, 1]`` target angles; ``actions_writable``: the caller hands
    ``actions`` over, so the last substep may add contact forces into it instead of a copy."""
    c = step_constants(tables, params)
    hold = integrator.hold_method(c, state.q.numel())
    fixed = None if fixed_rotation is None else fixed_rotation[..., 0]
    q, v = state.q, state.v
    for i in range(params.substeps):
        last = i == params.substeps - 1
        force = forces.applied_forces(actions, v, tables, c, may_write_actions=actions_writable and last)
        add_joint_forces(force, tables.joints, q, fixed, params)
        add_contact_forces(force, tables, q, params)
        q, v = integrator.substep(q, v, state.v, force, c, hold, first=i == 0)
    return PlanarState(q, v)


def step_vectors(state: BodyState, tables: WorldTables, params: StepParams, action_force: Tensor,
                 action_torque: Tensor, fixed_rotation: Optional[Tensor]) -> BodyState:
    """:func:`step` in VMAS's vector layout, for tools and tests: ``action_*`` per entity
    (``[N, B, 2]`` / ``[N, B, 1]``)."""
    actions = stack_actions(action_force, action_torque)
    return step(PlanarState.from_vectors(state), tables, params, actions, fixed_rotation).to_vectors()
