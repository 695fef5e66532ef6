"""PID velocity controller: the agent's action becomes a *desired velocity*.

Real robots are commanded in velocity (ROS ``cmd_vel``), while the engine
integrates forces. A scenario that wants velocity actions creates one
controller per agent and, in ``process_action``, calls
``agent.controller.process_force()``, which overwrites ``agent.action.u`` with
the force the agent's (holonomic) dynamics should apply.

Two parameterisations, as in VMAS 1.5:

* ``pid_form="standard"``: ``ctrl_params=(gain, intg_ts, derv_ts)`` and
  ``u = gain * (e + 1/intg_ts * integral(e) + derv_ts * de/dt)``. ``intg_ts``
  is the time over which an error is tolerated before the integrator has
  caught up; ``derv_ts`` the horizon over which the error is extrapolated.
  A zero ``intg_ts`` disables the integrator.
* ``pid_form="parallel"``: ``ctrl_params=(kP, kI, kD)``, converted with
  ``intg_ts = kP / kI`` and ``derv_ts = kD / kP``.

The output is multiplied by the agent's mass, so gains are in units of
acceleration per velocity error and transfer across agents of different mass.
"""
from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Optional, Sequence, Union

import torch
from torch import Tensor

from vmas_ros.simulator.utils import TorchUtils

if TYPE_CHECKING:  # runtime import would be circular-prone and is not needed
    from vmas_ros.simulator.entities import Agent
    from vmas_ros.simulator.world import World

__all__ = ["VelocityController"]


class VelocityController:
    """Batched PID from desired velocity (``agent.action.u``) to force.

    State (integrated error and last error, [batch, dim_p]) is kept per env so
    that ``reset(index)`` can clear only the envs being reset.

    Anti-windup: a blocked or force-saturated agent keeps accumulating error,
    and the stored integral would later make it overshoot for a long time. When
    the agent has a force limit ``fmax = min(max_f, f_range)`` the accumulated
    error is therefore clipped to ``+/- 0.5 * fmax * intg_ts / (dt * gain)``
    per axis (VMAS 1.5's bound, which it describes as 50% of the force limit;
    the integral force it allows is ``0.5 * fmax * mass / dt``). Without a
    limit a warning is issued, since the integrator can then grow unbounded.
    """

    def __init__(
        self,
        agent: "Agent",
        world: "World",
        ctrl_params: Sequence[float] = (1, 0, 0),
        pid_form: str = "standard",
    ) -> None:
        self.agent = agent
        self.world = world
        self.dt = world.dt
        self.ctrl_gain = ctrl_params[0]
        if pid_form == "standard":
            self.integralTs = ctrl_params[1]
            self.derivativeTs = ctrl_params[2]
        elif pid_form == "parallel":
            self.integralTs = 0.0 if ctrl_params[1] == 0 else self.ctrl_gain / ctrl_params[1]
            self.derivativeTs = ctrl_params[2] / self.ctrl_gain
        else:
            raise ValueError(f"pid_form must be 'standard' or 'parallel', got {pid_form!r}")

        self.use_integrator = self.integralTs != 0
        self.integrator_windup_cutoff: Optional[float] = None
        if self.use_integrator:
            limits = [f for f in (agent.max_f, agent.f_range) if f is not None]
            if limits:
                fmax = min(limits)
                self.integrator_windup_cutoff = 0.5 * fmax * self.integralTs / (self.dt * self.ctrl_gain)
            else:
                warnings.warn(
                    f"VelocityController of agent {agent.name!r}: the agent has no max_f/f_range, "
                    "so the integrator has no anti-windup limit and can wind up"
                )
        self.accum_errs: Tensor
        self.prev_err: Tensor
        self.reset()

    @property
    def _device(self) -> torch.device:
        device = self.agent.device
        return device if device is not None else self.world.device

    def reset(self, index: Optional[Union[int, Tensor]] = None) -> None:
        """Forget integrated and previous errors of the envs in ``index`` (all if None).

        Called from a scenario's ``reset_world_at`` so a freshly reset env does
        not inherit the integral of an episode that has ended.
        """
        if index is None:
            shape = (self.world.batch_dim, self.world.dim_p)
            self.accum_errs = torch.zeros(shape, device=self._device)
            self.prev_err = torch.zeros(shape, device=self._device)
        else:
            if isinstance(index, Tensor):
                index = index.to(self.accum_errs.device)
            self.accum_errs = TorchUtils.where_from_index(index, 0.0, self.accum_errs)
            self.prev_err = TorchUtils.where_from_index(index, 0.0, self.prev_err)

    def zero_grad(self) -> None:
        """Cut the controller memory from the autograd graph (between rollouts)."""
        self.accum_errs = self.accum_errs.detach()
        self.prev_err = self.prev_err.detach()

    def integralError(self, err: Tensor) -> Union[Tensor, float]:
        """Integral term ``accum / intg_ts``, with the accumulator clipped (anti-windup)."""
        if not self.use_integrator:
            return 0.0
        self.accum_errs = self.accum_errs + err * self.dt
        cutoff = self.integrator_windup_cutoff
        if cutoff is not None:
            self.accum_errs = self.accum_errs.clamp(-cutoff, cutoff)
        return (1.0 / self.integralTs) * self.accum_errs

    def rateError(self, err: Tensor) -> Tensor:
        """Derivative term ``derv_ts * de/dt``; remembers ``err`` for the next step."""
        rate = self.derivativeTs * (err - self.prev_err) / self.dt
        self.prev_err = err
        return rate

    def process_force(self) -> None:
        """Replace ``agent.action.u`` (desired velocity) by the PID force for this step."""
        device = self._device
        if self.accum_errs.device != device:  # the env was moved with .to(device)
            self.accum_errs = self.accum_errs.to(device)
            self.prev_err = self.prev_err.to(device)
        agent = self.agent
        u = agent.action.u
        dim_p = self.world.dim_p
        err = u[:, :dim_p] - agent.state.vel
        pid = err + self.integralError(err) + self.rateError(err)
        # ideal (ISA) PID form K * (e + I + D), scaled by mass to get a force
        force = self.ctrl_gain * pid * agent.mass
        # columns beyond (vx, vy), e.g. a torque for HolonomicWithRotation, pass through
        agent.action.u = force if u.shape[1] == dim_p else torch.cat((force, u[:, dim_p:]), dim=-1)
