"""Holonomic dynamics: the action is the force in the world frame."""
from vmas_ros.simulator.dynamics.common import Dynamics


class Holonomic(Dynamics):
    """Two action components, (fx, fy) in the world frame; the default for agents."""

    @property
    def needed_action_size(self) -> int:
        return 2

    def process_action(self) -> None:
        u = self.agent.action.u
        self.agent.state.force = u if u.shape[1] == 2 else u[:, :2]
