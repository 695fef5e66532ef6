"""sim_node with a fault-injecting scenario, for the fault tests: ``python -m test.ros.faulty_sim --ros-args ...``.

The scenario ``faulty_spread`` is simple_spread plus one injected fault,
chosen with ``scenario_kwargs``: ``{"fault": kind, "fault_step": n}``. From
step ``n`` on (counted by the scenario itself, once per ``Environment.step``):

* ``raise``: ``post_step`` raises RuntimeError (a scenario with a bug);
* ``nan_state``: agent_1's action becomes NaN, so the physics turns its
  position into NaN (a scenario whose dynamics diverge);
* ``nan_reward``: every reward is NaN while the state stays finite.

It is registered in the scenario registry at import, the same way as the
shipped scenarios, so the node under test is the real sim_node (same module,
same main) in a real process; only the scenario is ours.
"""
from __future__ import annotations

import sys

import torch

from vmas_ros.scenarios import REGISTRY
from vmas_ros.scenarios.mpe import simple_spread

NAME = "faulty_spread"
REGISTRY[NAME] = "test.ros.faulty_sim"
FAULTS = ("raise", "nan_state", "nan_reward")

HeuristicPolicy = simple_spread.HeuristicPolicy


class Scenario(simple_spread.Scenario):
    """simple_spread that breaks at step ``fault_step`` in the way ``fault`` says."""

    def make_world(self, batch_dim: int, device, **kwargs):
        self.fault = kwargs.pop("fault", "raise")
        self.fault_step = int(kwargs.pop("fault_step", 10))
        if self.fault not in FAULTS:
            raise ValueError(f"faulty_spread: fault must be one of {FAULTS}, not {self.fault!r}")
        self.steps_taken = 0
        return super().make_world(batch_dim, device, **kwargs)

    def _broken(self) -> bool:
        return self.steps_taken + 1 >= self.fault_step  # the step being taken is the faulty one

    def process_action(self, agent) -> None:
        if self.fault == "nan_state" and self._broken() and agent is self.world.agents[1]:
            agent.action.u = torch.full_like(agent.action.u, float("nan"))

    def post_step(self) -> None:
        if self.fault == "raise" and self._broken():
            raise RuntimeError(f"faulty_spread: injected failure at step {self.steps_taken + 1}")
        self.steps_taken += 1

    def reward(self, agent) -> torch.Tensor:
        reward = super().reward(agent)
        if self.fault == "nan_reward" and self.steps_taken >= self.fault_step:
            return torch.full_like(reward, float("nan"))
        return reward


if __name__ == "__main__":
    from vmas_ros.ros.sim_node import main

    sys.exit(main())
