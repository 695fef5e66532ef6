"""Forward-only dynamics: a thrust along the agent's current heading."""
import torch

from vmas_ros.simulator.dynamics.common import Dynamics


class Forward(Dynamics):
    """One action component: the force along the body x axis.

    The agent cannot turn by itself (pair it with contacts, joints or a second
    agent applying torque); the thrust follows whatever heading it has.
    """

    @property
    def needed_action_size(self) -> int:
        return 1

    def process_action(self) -> None:
        agent = self.agent
        thrust = agent.action.u[:, 0]
        heading = agent.state.rot[:, 0]
        # body-frame (thrust, 0) expressed in the world frame
        agent.state.force = torch.stack((thrust * torch.cos(heading), thrust * torch.sin(heading)), dim=-1)
