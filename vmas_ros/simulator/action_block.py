"""Every agent's action force and torque in two world-owned tensors, so a step reads them in one op.

A world of A agents keeps ``force`` ``[A, B, dim_p]`` and ``torque``
``[A, B, 1]``; agent ``i``'s ``state.force`` is row ``i`` of it, a
contiguous ``[B, dim_p]`` view. Without the block, every step gathered A small
tensors into one, which costs a Python call per agent: at thousands of agents
that is most of the step.

What users see does not change:

- setting ``agent.state.force = t`` copies ``t`` into the agent's row;
- an edit in place (``agent.state.force[:, 0] = fx``, as VMAS's dynamics make)
  lands in the row, so the step sees it;
- a value that needs gradients is kept by the agent itself, not copied (a row
  would chain every step's graph into one). The block is then *loose* for good,
  and the step gathers the agents' tensors one by one, as before.

Rows are handed out as agents join; the tensors grow by doubling, and the
agents' views are moved to the new tensors then, so adding N agents costs
O(N) in all.

The block also carries the environment's stacked actions ``u`` ``[A, B,
size]`` when a step receives them in one tensor (:meth:`publish_u`): each
agent's ``action.u`` is then its row, taken when first read, so a step of a
thousand agents costs no call per agent for actions nobody reads.
"""
from __future__ import annotations

from typing import List, Optional, Tuple

import torch
from torch import Tensor

__all__ = ["ActionBlock", "ACTION_FIELDS"]

#: the agent state fields that live in the block, with their widths given ``dim_p``
ACTION_FIELDS = ("force", "torque")


class ActionBlock:
    """The action rows of a world's agents (see the module docstring)."""

    def __init__(self, batch_dim: int, dim_p: int, device: torch.device) -> None:
        self.batch_dim, self.dim_p, self.device = batch_dim, dim_p, torch.device(device)
        self.count = 0
        #: some agent holds a force or torque of its own (one that needs gradients): gather per agent
        self.loose = False
        self._states: List[object] = []  # AgentState per row, to move their views when the tensors grow
        self.force, self.torque = self._allocate(0)
        self._views: Optional[Tuple[Tensor, Tensor]] = None  # stacks(), made once per count and tensors
        #: every agent's ``action.u`` of this step stacked ``[A, B, size]`` (None: each agent holds its own),
        #: and a counter that changes whenever that does (agents compare it with the one they last saw)
        self.u_rows: Optional[Tensor] = None
        self.u_version = 0

    def publish_u(self, stacked: Optional[Tensor]) -> None:
        """Make row ``i`` of ``stacked`` ``[A, B, size]`` agent ``i``'s ``action.u`` (None: each agent's own)."""
        if stacked is None and self.u_rows is None:
            return
        self.u_rows = stacked
        self.u_version += 1

    def _allocate(self, capacity: int) -> Tuple[Tensor, Tensor]:
        return (torch.zeros(capacity, self.batch_dim, self.dim_p, device=self.device),
                torch.zeros(capacity, self.batch_dim, 1, device=self.device))

    def row(self, field: str, slot: int) -> Tensor:
        """Row ``slot`` of ``field`` (``"force"`` or ``"torque"``): the view an agent state holds."""
        return (self.force if field == "force" else self.torque)[slot]

    def append(self, state) -> int:
        """A zeroed row for ``state`` (an ``AgentState``); returns its slot."""
        if self.count == self.force.shape[0]:
            self._resize(max(4, 2 * self.count), self.device)
        self._states.append(state)
        self.count += 1
        self._views = None
        return self.count - 1

    def stacks(self) -> Tuple[Tensor, Tensor]:
        """``(force [A, B, dim_p], torque [A, B, 1])``: every agent's action, as views (not copies; the same
        two objects from step to step, until an agent joins or the block moves)."""
        views = self._views
        if views is None:
            views = self._views = (self.force[:self.count], self.torque[:self.count])
        return views

    def to(self, device) -> None:
        """Move the block, and the agents' row views with it, to ``device``."""
        self._resize(self.force.shape[0], torch.device(device))

    def _resize(self, capacity: int, device: torch.device) -> None:
        old_force, old_torque = self.stacks()
        self.device = device
        self.force, self.torque = self._allocate(capacity)
        self._views = None
        self.force[:self.count].copy_(old_force)
        self.torque[:self.count].copy_(old_torque)
        if self.u_rows is not None:
            self.u_rows = self.u_rows.to(device)
        for slot, state in enumerate(self._states):
            state._move_action_rows(self, slot)
