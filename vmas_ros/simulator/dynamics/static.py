"""Dynamics for agents that never actuate (sensors on a pole, scripted props)."""
from vmas_ros.simulator.dynamics.common import Dynamics


class Static(Dynamics):
    """Consumes no action; the agent's force and torque stay untouched.

    The agent still takes part in contacts and may be pushed around if it is
    movable; it simply has no motor of its own.
    """

    @property
    def needed_action_size(self) -> int:
        return 0

    def process_action(self) -> None:
        return None
