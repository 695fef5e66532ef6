"""Dynamics models turn an agent's action vector into forces and torques.

A model reads ``agent.action.u`` (shape [batch, action_size]) and writes
``agent.state.force`` ([batch, 2], world frame) and, for rotating models,
``agent.state.torque`` ([batch, 1]). The world integrates those forces.
"""
from __future__ import annotations

import abc
from typing import Optional, Union

from torch import Tensor


class Dynamics(abc.ABC):
    """Base of every dynamics model; bound to exactly one agent at construction."""

    def __init__(self) -> None:
        self._agent = None

    @property
    def agent(self):
        if self._agent is None:
            raise ValueError("this dynamics model is not attached to an agent yet: pass it to Agent(dynamics=...)")
        return self._agent

    @agent.setter
    def agent(self, value) -> None:
        if self._agent is not None:
            raise ValueError(f"dynamics already belongs to agent {self._agent.name!r}; make one per agent")
        self._agent = value

    def reset(self, index: Optional[Union[Tensor, int]] = None) -> None:
        """Clear internal state (e.g. integrator memory) for the given envs."""

    def zero_grad(self) -> None:
        """Detach internal tensors from the autograd graph."""

    def check_and_process_action(self) -> None:
        size = self.agent.action.u.shape[1]
        if size < self.needed_action_size:
            raise ValueError(
                f"agent {self.agent.name!r} has action size {size}, but {type(self).__name__} "
                f"needs {self.needed_action_size}"
            )
        self.process_action()

    @property
    @abc.abstractmethod
    def needed_action_size(self) -> int:
        """How many action components this model consumes."""

    @abc.abstractmethod
    def process_action(self) -> None:
        """Write ``agent.state.force`` (and ``torque``) from ``agent.action.u``."""
