"""The physics step's action input: every entity's (fx, fy, torque) as one ``[3, N, B]`` tensor.

Agents' dynamics write a force ``[B, 2]`` and a torque ``[B, 1]`` each, into their
rows of the world's action block (:mod:`vmas_ros.simulator.action_block`); the
step copies the block into the entities' rows (landmarks get zeros). At a few envs the
number of calls matters more than the arithmetic, so the copy is chosen by
size (:mod:`vmas_ros.simulator.thresholds`). Before that, an agent's action is clamped to its
limits and zeroed in the coordinates it cannot move or turn in, as VMAS does.
"""
from __future__ import annotations

from typing import Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.action_block import ActionBlock
from vmas_ros.simulator.layout import split_xy_into, stack_into
from vmas_ros.simulator.utils import clamp_norm
from vmas_ros.simulator.physics.integrator import differentiable
from vmas_ros.simulator.thresholds import SMALL_BATCH_ELEMENTS
from vmas_ros.simulator.tables import WorldTables
from vmas_ros.simulator.tracing import tracing

__all__ = ["agents_action_input", "assemble_actions", "hold_agents", "limit_actions"]


def assemble_actions(q: Tensor, tables: WorldTables, forces, torques) -> Tensor:
    """The step's action input ``[3, N, B]`` (fx, fy, torque per entity, zero for landmarks; see
    physics.types.stack_actions) from the agents' forces ``[A, B, 2]`` and torques ``[A, B, 1]`` (stacks, or
    lists of per-agent tensors). A fresh tensor: the physics adds contact forces into it.
    """
    actions = q.new_zeros(q.shape)
    n_agents = tables.n_agents
    if n_agents == 0:
        return actions
    rows = actions[:, tables.n_entities - n_agents:]  # the agents' [3, A, B] block (landmarks stay zero)
    if isinstance(forces, (list, tuple)):
        if not tracing() and not differentiable(*forces, *torques):
            # each agent's force and torque stacked straight into its rows (no stacks of the batch)
            stack_into(forces, rows[:2])
            stack_into(torques, rows[2:])
            return actions
        forces, torques = torch.stack(forces), torch.stack(torques)
    if q.numel() <= SMALL_BATCH_ELEMENTS or tracing():
        # few elements: each call's fixed cost dominates; one strided copy (and the compiler's choice)
        rows[:2].copy_(forces.permute(2, 0, 1))
    else:
        # many: the components copied straight into their rows (bit-exact, no batch-sized temporaries;
        # a strided copy of interleaved pairs runs at a fraction of memory speed on the CPU)
        split_xy_into(forces, rows[:2])
    rows[2].copy_(torques[..., 0])
    return actions


def limit_actions(force: Tensor, torque: Tensor, tables: WorldTables) -> Tuple[Tensor, Tensor]:
    """Agents' action forces ``[A, B, 2]`` and torques ``[A, B, 1]`` clamped to their limits as VMAS clamps
    them: the norm to ``max_f`` (``max_t``), then each component to ``f_range`` (``t_range``)."""
    if tables.limits_force:
        force = clamp_norm(force, tables.agent_max_f)
        force = torch.maximum(torch.minimum(force, tables.agent_f_range), -tables.agent_f_range)
    if tables.limits_torque:
        torque = clamp_norm(torque, tables.agent_max_t)
        torque = torch.maximum(torch.minimum(torque, tables.agent_t_range), -tables.agent_t_range)
    return force, torque


def hold_agents(force: Tensor, torque: Tensor, tables: WorldTables) -> Tuple[Tensor, Tensor]:
    """``force`` ``[A, B, 2]`` zeroed for agents that cannot move, ``torque`` ``[A, B, 1]`` for those that
    cannot turn (VMAS ignores their actions there)."""
    return (torch.where(tables.agent_movable, force, 0.0), torch.where(tables.agent_rotatable, torque, 0.0))


def agents_action_input(agents, block: ActionBlock, tables: WorldTables, q: Tensor, compiled: bool):
    """The step's action input ``[3, N, B]`` (:func:`assemble_actions`) from the agents' action forces and
    torques, clamped to their limits (written back to the agents, as VMAS does) and held where an agent
    cannot move or turn; or, for a ``compiled`` step with nothing to clamp or hold, the (forces, torques)
    for the compiled step to assemble in its own graph.

    The forces and torques are the rows of the world's action ``block``, read in one op; only when some
    agent holds a value of its own (one that needs gradients: the block is loose) are they gathered
    agent by agent."""
    if tables.n_agents == 0:
        return q.new_zeros(q.shape)
    if tables.fixed_agents is None:  # some agent cannot move or turn: its action is ignored there
        tables.fixed_agents = not all(a.movable and a.rotatable for a in agents)
    limited = tables.limits_force or tables.limits_torque
    if block.loose:
        forces, torques = [a.state._force for a in agents], [a.state._torque for a in agents]
        if not (limited or tables.fixed_agents):
            return (forces, torques) if compiled else assemble_actions(q, tables, forces, torques)
        force, torque = torch.stack(forces), torch.stack(torques)
    else:
        force, torque = block.stacks()
        if not (limited or tables.fixed_agents):
            return (force, torque) if compiled else assemble_actions(q, tables, force, torque)
    if limited:
        force, torque = _limit_and_write_back(force, torque, agents, block, tables)
    if tables.fixed_agents:
        force, torque = hold_agents(force, torque, tables)
    return assemble_actions(q, tables, force, torque)


def _limit_and_write_back(force: Tensor, torque: Tensor, agents, block: ActionBlock,
                          tables: WorldTables) -> Tuple[Tensor, Tensor]:
    """:func:`limit_actions`, with the clamped values written back where scenarios read them, as VMAS
    does (only for agents that can move, or turn)."""
    clamped_force, clamped_torque = limit_actions(force, torque, tables)
    if not block.loose:  # the rows themselves: one write for all agents
        force.copy_(torch.where(tables.agent_movable, clamped_force, force))
        torque.copy_(torch.where(tables.agent_rotatable, clamped_torque, torque))
        return clamped_force, clamped_torque
    for agent, f, t in zip(agents, clamped_force.unbind(0), clamped_torque.unbind(0)):
        if agent.movable:
            agent.state._set_action("force", f)
        if agent.rotatable:
            agent.state._set_action("torque", t)
    return clamped_force, clamped_torque
