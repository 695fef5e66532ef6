"""How agents' actions become the physics step's input, a mixin of ``World``.

Each agent's dynamics writes ``agent.state.force`` ``[B, 2]`` and ``torque``
``[B, 1]``; the step wants one ``[3, N, B]`` tensor (fx, fy, torque per
entity, zero for landmarks; see ``physics.types.stack_actions``), clamped to the
agents' limits as VMAS clamps them. Kept apart from the step itself: this is
bookkeeping between the object API and the batched state, and at a few envs
its call count matters more than its arithmetic.
"""
from __future__ import annotations

from typing import Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.physics.forces import clamp_norm
from vmas_ros.simulator.physics.actions import assemble_actions
from vmas_ros.simulator.tables import WorldTables


class ActionInputs:
    """The step's action input; ``World`` provides ``_agents``."""

    def _action_input(self, tables: WorldTables, q: Tensor):
        """The step's action input: ``[3, N, B]`` (see :func:`assemble_actions`), or, when no limit or
        held agent asks for clamping here and the physics is compiled, the agents' (forces, torques)
        lists for the compiled step to assemble in its own graph."""
        if tables.n_agents == 0:
            return q.new_zeros(q.shape)
        if not (tables.limits_force or tables.limits_torque or self._fixed_agents(tables)):
            lists = ([a.state._force for a in self._agents], [a.state._torque for a in self._agents])
            return lists if self.physics_compiled else assemble_actions(q, tables, *lists)
        agent_force, agent_torque = self._agent_actions(tables)
        return assemble_actions(q, tables, agent_force, agent_torque)

    def _agent_actions(self, tables: WorldTables) -> Tuple[Tensor, Tensor]:
        """Agents' action forces [A, B, 2] and torques [A, B, 1], clamped to their limits as VMAS does."""
        forces = [a.state._force for a in self._agents]
        torques = [a.state._torque for a in self._agents]
        fixed = self._fixed_agents(tables)
        agent_force, agent_torque = torch.stack(forces), torch.stack(torques)
        if tables.limits_force:
            agent_force = clamp_norm(agent_force, tables.agent_max_f)
            agent_force = torch.maximum(torch.minimum(agent_force, tables.agent_f_range), -tables.agent_f_range)
        if tables.limits_torque:
            agent_torque = clamp_norm(agent_torque, tables.agent_max_t)
            agent_torque = torch.maximum(torch.minimum(agent_torque, tables.agent_t_range), -tables.agent_t_range)
        if tables.limits_force or tables.limits_torque:
            # clamped actions are visible to scenarios, as in VMAS
            for agent, f, t in zip(self._agents, agent_force.unbind(0), agent_torque.unbind(0)):
                if agent.movable:
                    agent.state._force = f
                if agent.rotatable:
                    agent.state._torque = t
        if fixed:
            agent_force = torch.where(tables.agent_movable, agent_force, 0.0)
            agent_torque = torch.where(tables.agent_rotatable, agent_torque, 0.0)
        return agent_force, agent_torque

    def _fixed_agents(self, tables: WorldTables) -> bool:
        """Whether some agent cannot move or rotate (its action force or torque is then ignored)."""
        if tables.fixed_agents is None:
            tables.fixed_agents = not all(a.movable and a.rotatable for a in self._agents)
        return tables.fixed_agents
