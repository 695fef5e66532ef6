"""Pieces shared by the velocity-commanded debug tasks (circle_trajectory, line_trajectory, goal).

* :func:`noisy_concat`: an observation made of 2-vectors, each entry with
  optional uniform noise;
* :class:`CommandFilter`: what happens to a commanded velocity before the PID
  velocity controller turns it into a force (an optional delay of whole
  steps, a clip to a disc, a dead band for tiny commands);
* :func:`tracking_reward`: the path-following reward (closeness to a path plus
  progress along it);
* :class:`PathFollower`: a heuristic that commands a velocity along a path's
  tangent plus a pull back onto the path.
"""
from __future__ import annotations

import abc
from typing import Sequence, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.utils import TorchUtils

__all__ = ["CommandFilter", "PathFollower", "noisy_concat", "tracking_reward"]


def noisy_concat(parts: Sequence[Tensor], noise: float) -> Tensor:
    """``parts`` (each [B, 2]) side by side, [B, 2 * len(parts)], plus uniform noise in [-noise, noise].

    The noise is drawn as one [len(parts), B, 2] block, i.e. part after part,
    so a seeded stream gives the same values as VMAS 1.5, which draws one
    [B, 2] block per part. Nothing is drawn when ``noise`` is 0.
    """
    stacked = torch.stack(list(parts))  # [P, B, 2]
    if noise > 0:
        stacked = stacked + torch.empty_like(stacked).uniform_(-noise, noise)
    return torch.cat(list(stacked.unbind(0)), dim=-1)


def tracking_reward(distance: Tensor, tangent: Tensor, vel: Tensor) -> Tuple[Tensor, Tensor]:
    """The two terms of the path-following reward, each [B].

    ``-sqrt(distance)`` ([B]) rewards closeness: its slope grows near the path,
    so small deviations still cost. ``0.5 * tangent . vel`` (both [B, 2])
    rewards speed along the path's direction of travel.
    """
    closeness = -torch.sqrt(distance)
    progress = (tangent * vel).sum(-1) * 0.5
    return closeness, progress


class CommandFilter:
    """Turns a raw velocity command [B, 2] into the one the PID controller tracks.

    In order: the command leaves a delay line ``delay`` steps later (filled with
    zeros at the start and at every reset of an env), is scaled back onto the
    disc of radius ``u_range`` when longer, and is zeroed below ``min_norm`` (a
    dead band: real robots do not creep).
    """

    def __init__(self, batch_dim: int, dim_p: int, delay: int, u_range: float, min_norm: float, device) -> None:
        self.u_range, self.min_norm = u_range, min_norm
        #: per env, the commands still in the delay line, oldest first: [B, delay, dim_p]
        self.pending = torch.zeros(batch_dim, delay, dim_p, device=device)

    def reset(self, env_index) -> None:
        """Empty the delay line of the envs ``env_index`` selects (all for None)."""
        if env_index is None:
            self.pending = torch.zeros_like(self.pending)
        else:
            self.pending[env_index] = 0.0

    def __call__(self, command: Tensor) -> Tensor:
        if self.pending.shape[1]:
            line = torch.cat([self.pending, command.unsqueeze(1)], dim=1)
            command, self.pending = line[:, 0], line[:, 1:].clone()
        command = TorchUtils.clamp_with_norm(command, self.u_range)
        tiny = torch.linalg.vector_norm(command, dim=-1, keepdim=True) < self.min_norm
        return torch.where(tiny, 0.0, command)


class PathFollower(BaseHeuristicPolicy):
    """Command ``speed`` along the path's tangent plus ``gain`` x the offset back onto the path.

    Observations start with the agent's position (2) and velocity (2); the
    command is a desired velocity (the scenarios' PID controller tracks it),
    clipped to the disc of radius ``u_range``. The pull is capped at
    ``max_pull`` so far from the path the agent still moves along it.
    Subclasses give the path: :meth:`closest_and_tangent`.
    """

    gain = 2.0
    max_pull = 0.8

    def __init__(self, continuous_action: bool = True, speed: float = 1.0) -> None:
        super().__init__(continuous_action)
        if not continuous_action:
            raise ValueError(f"{type(self).__module__} heuristic: only continuous actions are supported")
        self.speed = speed

    @abc.abstractmethod
    def closest_and_tangent(self, pos: Tensor) -> Tuple[Tensor, Tensor]:
        """The path's point closest to ``pos`` and the unit direction of travel there, each [B, 2]."""

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        pos = observation[:, 0:2]
        closest, tangent = self.closest_and_tangent(pos)
        pull = TorchUtils.clamp_with_norm(self.gain * (closest - pos), self.max_pull)
        return TorchUtils.clamp_with_norm(self.speed * tangent + pull, u_range)
