"""Turning what users pass to ``env.step`` into agents' ``action.u`` and ``action.c``.

Validation is strict and names the agent, the expected shape and the bad
value, because a silently broadcast or NaN action wrecks a training run far
from its cause. All envs are checked at once; the only host read is the one
that decides whether to raise.
"""
from __future__ import annotations

import math
from typing import List

import torch
from torch import Tensor


def per_component(value) -> list:
    """An action setting given as one number or one per action component, as a list."""
    return list(value) if isinstance(value, (list, tuple)) else [value]


def to_action_tensor(action, agent_name: str, num_envs: int, size: int, device: torch.device, continuous: bool) -> Tensor:
    """Validate one agent's action and return it as a [num_envs, size] tensor on ``device``."""
    if not isinstance(action, Tensor):
        try:
            action = torch.as_tensor(action, dtype=torch.float32 if continuous else torch.long)
        except (TypeError, ValueError, RuntimeError) as error:
            raise ValueError(f"action for agent {agent_name!r} is not a tensor or array: {error}") from None
    elif action.device != device:
        raise ValueError(
            f"action for agent {agent_name!r} is on device {action.device}, but the env runs on {device}; "
            f"move it with .to({str(device)!r})"
        )
    if action.dim() == 1 and size == 1 and action.shape[0] == num_envs:
        action = action.unsqueeze(-1)
    if tuple(action.shape) != (num_envs, size):
        raise ValueError(
            f"action for agent {agent_name!r} has shape {tuple(action.shape)}, expected ({num_envs}, {size})"
        )
    if action.dtype == torch.bool or action.is_complex():
        raise ValueError(f"action for agent {agent_name!r} has dtype {action.dtype}; expected a real number type")
    if not continuous and action.dtype.is_floating_point:
        if not bool(torch.all(action == action.round())):
            raise ValueError(f"discrete action for agent {agent_name!r} has non-integer values")
    return action if action.device == device else action.to(device)


def plain_actions(actions: list, shape: torch.Size, device: torch.device) -> bool:
    """Whether every one of ``actions`` is a float32 tensor of ``shape`` on ``device`` that needs no
    gradients: the common case, which needs none of :func:`to_action_tensor`'s conversions (its checks
    would pass). Straight-line attribute reads: this runs on every step."""
    float32 = torch.float32
    for action in actions:
        if (type(action) is not Tensor or action.dtype is not float32 or action.shape != shape
                or action.device != device or action.requires_grad):
            return False
    return True


def to_stacked_actions(actions: Tensor, n_agents: int, num_envs: int, sizes: List[int], device: torch.device,
                       continuous: bool) -> Tensor:
    """Validate the stacked form of every agent's action, ``[n_agents, num_envs, size]``, and return it.

    One tensor for all agents costs one check instead of one per agent (a
    swarm has thousands). It needs every agent to take the same action size;
    a discrete action of size 1 may also come as ``[n_agents, num_envs]``.
    """
    size = sizes[0] if sizes else 0
    if any(s != size for s in sizes):
        raise ValueError(f"a stacked action tensor needs every agent to take the same action size, got {sizes}; "
                         f"pass a list with one tensor per agent instead")
    if actions.device != device:
        raise ValueError(f"the stacked actions are on device {actions.device}, but the env runs on {device}; "
                         f"move them with .to({str(device)!r})")
    if actions.dim() == 2 and size == 1 and tuple(actions.shape) == (n_agents, num_envs):
        actions = actions.unsqueeze(-1)
    if tuple(actions.shape) != (n_agents, num_envs, size):
        raise ValueError(f"stacked actions have shape {tuple(actions.shape)}, expected "
                         f"(n_agents, num_envs, action size) = ({n_agents}, {num_envs}, {size})")
    if actions.dtype == torch.bool or actions.is_complex():
        raise ValueError(f"stacked actions have dtype {actions.dtype}; expected a real number type")
    if not continuous and actions.dtype.is_floating_point and not bool(torch.all(actions == actions.round())):
        raise ValueError("stacked discrete actions have non-integer values")
    return actions


def check_finite_and_range(actions: List[Tensor], lows: List[Tensor], highs: List[Tensor], names: List[str], what: str) -> None:
    """Raise ValueError for NaN/inf or out-of-range entries; one host read for all agents."""
    if not actions:  # every agent is scripted (e.g. football with both teams on AI)
        return
    bad = torch.stack(
        [((~torch.isfinite(a)) | (a < lo) | (a > hi)).any() for a, lo, hi in zip(actions, lows, highs)]
    )
    if not bool(bad.any()):
        return
    for action, low, high, name in zip(actions, lows, highs, names):
        if not bool(torch.isfinite(action).all()):
            env = int((~torch.isfinite(action)).any(-1).nonzero()[0])
            raise ValueError(f"action for agent {name!r} contains NaN or inf (first in env {env}): {action[env].tolist()}")
        outside = (action < low) | (action > high)
        if bool(outside.any()):
            env = int(outside.any(-1).nonzero()[0])
            raise ValueError(
                f"{what} action for agent {name!r} is out of range in env {env}: {action[env].tolist()}, "
                f"allowed [{low.tolist()}, {high.tolist()}] (make_env(clamp_actions=True) clamps instead)"
            )


def discrete_to_continuous(index: Tensor, nvec: List[int], u_range: Tensor) -> Tensor:
    """Map per-component choices in [0, n) to values in [-u_range, u_range].

    For odd ``n`` choice 0 means "no action" (0.0), so a zero action is always the
    first index; the other choices are spread evenly over the range.
    """
    n = torch.tensor(nvec, device=index.device)
    choice = index.long()
    odd = (n % 2) == 1
    middle = n // 2
    shifted = torch.where(choice == 0, middle, torch.where(choice <= middle, choice - 1, choice))
    choice = torch.where(odd, shifted, choice)
    return choice.float() / (n - 1).float() * (2 * u_range) - u_range


def unflatten_discrete(flat: Tensor, nvec: List[int]) -> Tensor:
    """Split a flat index over the product space ``nvec`` into per-component indices (last fastest)."""
    parts = []
    remainder = flat.long()
    for i in range(len(nvec)):
        block = math.prod(nvec[i + 1:])
        parts.append(remainder // block)
        remainder = remainder % block
    return torch.stack(parts, dim=-1)
