"""Holonomic dynamics that also steer the heading: (fx, fy, torque)."""
from vmas_ros.simulator.dynamics.common import Dynamics


class HolonomicWithRotation(Dynamics):
    """Three action components: a world-frame force (fx, fy) and a torque.

    Useful for omnidirectional robots whose heading matters (e.g. a camera or
    a gripper that must face something): translation and rotation are
    commanded independently.
    """

    @property
    def needed_action_size(self) -> int:
        return 3

    def process_action(self) -> None:
        u = self.agent.action.u
        self.agent.state.force = u[:, :2]
        # keep a [batch, 1] column: the world stacks torques per entity
        self.agent.state.torque = u[:, 2:3]
