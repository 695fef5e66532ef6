"""Rotation-only dynamics: the single action is a torque.

The module name keeps VMAS's spelling (``roatation``) so that
``from vmas.simulator.dynamics.roatation import Rotation`` ports by changing the
prefix only.
"""
from vmas_ros.simulator.dynamics.common import Dynamics


class Rotation(Dynamics):
    """One action component: the torque about the agent's centre (e.g. a turret)."""

    @property
    def needed_action_size(self) -> int:
        return 1

    def process_action(self) -> None:
        self.agent.state.torque = self.agent.action.u[:, 0:1]
