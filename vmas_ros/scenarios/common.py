"""Helpers every scenario shares.

Kwargs: :func:`read_kwargs` (a scenario's kwargs with their defaults; unknown
ones warn, as in VMAS) and :func:`heuristic_kwargs` (the same kwargs handed to
a heuristic, where an unknown one is a mistake and raises).

Resets: how many envs a reset selects, and values drawn for them shaped the
way ``Entity.set_*(..., batch_index=...)`` takes them.

VMAS's reset selector ``env_index`` is None (every env), an int (one env) or,
for scenarios with ``supports_batched_reset``, a 1-D tensor of env indices.
Setters take ``[batch, D]`` for None or indices and ``[D]`` for an int, so a
scenario draws ``[rows, D]`` once and passes it through :func:`for_index`.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch
from torch import Tensor

from vmas_ros.simulator.utils import ScenarioUtils, selected_env_count

__all__ = ["for_index", "heuristic_kwargs", "read_kwargs", "selected_rows", "uniform_rows"]


def read_kwargs(kwargs: dict, defaults: Mapping[str, Any]) -> dict:
    """Pop every kwarg ``defaults`` names from ``kwargs`` (its default when absent) and warn
    about whatever is left, as VMAS does for kwargs a scenario does not use."""
    config = {name: kwargs.pop(name, default) for name, default in defaults.items()}
    ScenarioUtils.check_kwargs_consumed(kwargs)
    return config


def heuristic_kwargs(scenario: str, defaults: Mapping[str, Any], scenario_kwargs: Mapping[str, Any]) -> dict:
    """The scenario kwargs a heuristic was given, completed with ``defaults``.

    Unlike the scenario, a heuristic refuses kwargs it does not know (TypeError):
    it would otherwise parse observations with the wrong layout, silently.
    """
    unknown = set(scenario_kwargs) - set(defaults)
    if unknown:
        raise TypeError(f"{scenario} HeuristicPolicy got unknown kwargs {sorted(unknown)}")
    return {**defaults, **scenario_kwargs}


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
