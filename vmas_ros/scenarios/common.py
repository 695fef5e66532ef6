"""Reset-time helpers every scenario shares: how many envs a reset selects, and
values drawn for them shaped the way ``Entity.set_*(..., batch_index=...)`` takes them.

VMAS's reset selector ``env_index`` is None (every env), an int (one env) or,
for scenarios with ``supports_batched_reset``, a 1-D tensor of env indices.
Setters take ``[batch, D]`` for None or indices and ``[D]`` for an int, so a
scenario draws ``[rows, D]`` once and passes it through :func:`for_index`.
"""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator.utils import selected_env_count

__all__ = ["for_index", "selected_rows", "uniform_rows"]


def selected_rows(batch_dim: int, env_index) -> int:
    """How many envs ``env_index`` selects (None: all ``batch_dim``)."""
    return selected_env_count(batch_dim, env_index)


def for_index(values: Tensor, env_index) -> Tensor:
    """``values`` drawn per selected env ([rows, ...]) shaped for a setter: the one row for an int index."""
    return values[0] if isinstance(env_index, int) else values


def uniform_rows(world, env_index, size: int, low: float, high: float) -> Tensor:
    """Uniform values in [low, high) for the selected envs, shaped for a setter ([rows, size] or [size])."""
    rows = selected_rows(world.batch_dim, env_index)
    return for_index(torch.empty(rows, size, device=world.device).uniform_(low, high), env_index)
