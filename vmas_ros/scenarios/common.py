"""Helpers every scenario shares.

Kwargs: :func:`read_kwargs` (a scenario's kwargs with their defaults; unknown
ones warn, as in VMAS), :func:`configure` (read, check and keep them as the
scenario's attributes) and :func:`heuristic_kwargs` (the same kwargs handed to
a heuristic, where an unknown one is a mistake and raises;
:func:`continuous_heuristic_kwargs` for a heuristic that drives continuous
actions only).

Checks: :func:`check_number`, :func:`check_int` and :func:`check_flag` raise
ValueError naming the scenario, the kwarg, what was expected and what came.

Resets: how many envs a reset selects, values drawn for them shaped the way
``Entity.set_*(..., batch_index=...)`` takes them, and spawn points kept
apart (:func:`sample_clear_positions`). VMAS's reset selector ``env_index``
is None (every env), an int (one env) or, for scenarios with
``supports_batched_reset``, a 1-D tensor of env indices. Setters take
``[batch, D]`` for None or indices and ``[D]`` for an int, so a scenario
draws ``[rows, D]`` once and passes it through :func:`for_index`.

Distances: :func:`pair_distances` between two sets of points on planar rows.

Heuristics: :func:`greedy_first_match`, the landmark an agent takes when
agents and landmarks pair up nearest first.

Rendering: :func:`range_links`, the lines ``extra_render`` draws between
agents within communication range of each other.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from numbers import Real
from typing import Any, Callable, Optional

import torch
from torch import Tensor

from vmas_ros.simulator.utils import Color, ScenarioUtils, selected_env_count

__all__ = [
    "check_flag", "check_int", "check_number", "configure", "continuous_heuristic_kwargs", "for_index", "greedy_first_match", "heuristic_kwargs", "pair_distances", "range_links", "read_kwargs",
    "sample_clear_positions", "selected_rows", "uniform_rows",
]


def read_kwargs(kwargs: dict, defaults: Mapping[str, Any]) -> dict:
    """Pop every kwarg ``defaults`` names from ``kwargs`` (its default when absent) and warn
    about whatever is left, naming it, as VMAS does for kwargs a scenario does not use.

    Every scenario's ``make_world`` reads its kwargs through this (``{}`` for a
    scenario without any), so unknown kwargs are reported the same way everywhere.
    """
    config = {name: kwargs.pop(name, default) for name, default in defaults.items()}
    ScenarioUtils.check_kwargs_consumed(kwargs)
    return config


def check_number(scenario: str, name: str, value, minimum: Optional[float] = 0.0, strict: bool = False) -> float:
    """``value`` as a float if it is a finite real number (not a bool) and ``>= minimum``
    (``>`` with ``strict``; any finite number with ``minimum=None``), else ValueError naming it."""
    ok = isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)
    if ok and minimum is not None:
        ok = value > minimum if strict else value >= minimum
    if not ok:
        bound = "" if minimum is None else f" {'>' if strict else '>='} {minimum:g}"
        raise ValueError(f"{scenario}: {name} must be a finite number{bound}, got {value!r}")
    return float(value)


def check_int(scenario: str, name: str, value, minimum: int = 1, unit: str = "") -> int:
    """``value`` if it is an int (not a bool) ``>= minimum``, else ValueError naming it and, when
    given, its ``unit`` (e.g. ``"steps"``)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        what = f" ({unit})" if unit else ""
        raise ValueError(f"{scenario}: {name} must be an int >= {minimum}{what}, got {value!r}")
    return value


def check_flag(scenario: str, name: str, value) -> bool:
    """``value`` if it is True or False, else ValueError naming it."""
    if not isinstance(value, bool):
        raise ValueError(f"{scenario}: {name} must be True or False, got {value!r}")
    return value


def configure(scenario, kwargs: dict, defaults: Mapping[str, Any], validate: Callable[[dict], None]) -> dict:
    """:func:`read_kwargs`, check them with ``validate`` (it raises on a bad value) and set each
    on ``scenario`` as an attribute of the same name. Returns the kwargs read."""
    config = read_kwargs(kwargs, defaults)
    validate(config)
    for name, value in config.items():
        setattr(scenario, name, value)
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


def continuous_heuristic_kwargs(scenario: str, defaults: Mapping[str, Any], scenario_kwargs: Mapping[str, Any],
                                continuous_action: bool) -> dict:
    """:func:`heuristic_kwargs` for a heuristic that computes forces and so drives continuous
    actions only: asked for discrete ones, it raises ValueError."""
    if not continuous_action:
        raise ValueError(f"{scenario} heuristic: only continuous actions are supported")
    return heuristic_kwargs(scenario, defaults, scenario_kwargs)


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


def sample_clear_positions(
    occupied: Tensor, count: int, min_dist: float, x_bounds: tuple[float, float], y_bounds: tuple[float, float],
    candidates: int = 64,
) -> Tensor:
    """``count`` uniform positions per row ([rows, count, 2]), each ``min_dist`` clear of the others.

    ``occupied`` ([rows, m, 2]) holds positions to keep clear of. Entities are
    placed one after another; each draws ``candidates`` uniform points per row
    at once and takes the first one clear of everything placed so far, which
    is distributed exactly like rejection sampling, without a data-dependent
    loop or host sync. If no candidate of a row is clear (only in a crowded
    arena), that row takes its candidate farthest from the others.
    """
    rows, device = occupied.shape[0], occupied.device
    # entity-major planar components [m, rows, 1]: the distances to everything placed are [m, rows,
    # candidates] with the candidates contiguous, and the nearest is a reduction over the leading dim
    # (a reduction over a small trailing dim, or a broadcast over a trailing dim of 2, is a slow path)
    taken_x, taken_y = occupied[..., 0].T.unsqueeze(-1), occupied[..., 1].T.unsqueeze(-1)
    picked = []
    for _ in range(count):
        draw_x = torch.empty(rows, candidates, device=device).uniform_(*x_bounds)
        draw_y = torch.empty(rows, candidates, device=device).uniform_(*y_bounds)
        if taken_x.shape[0]:
            gap_x, gap_y = draw_x - taken_x, draw_y - taken_y
            clearance = torch.addcmul(gap_x * gap_x, gap_y, gap_y).amin(dim=0)  # squared distances
        else:
            clearance = torch.full((rows, candidates), math.inf, device=device)
        clear = clearance >= min_dist * min_dist
        pick = torch.where(clear.any(dim=1), clear.int().argmax(dim=1), clearance.argmax(dim=1)).unsqueeze(1)
        x, y = torch.gather(draw_x, 1, pick), torch.gather(draw_y, 1, pick)  # [rows, 1]
        picked.append(torch.cat([x, y], dim=1))
        taken_x = torch.cat([taken_x, x.unsqueeze(0)])
        taken_y = torch.cat([taken_y, y.unsqueeze(0)])
    return torch.stack(picked, dim=1) if picked else occupied.new_zeros(rows, 0, 2)


def pair_distances(ax: Tensor, ay: Tensor, bx: Tensor, by: Tensor) -> Tensor:
    """Distances ``[I, J, ...]`` between points ``(ax, ay)`` ``[I, ...]`` and ``(bx, by)`` ``[J, ...]``.

    Planar rows (one tensor per component, envs last) vectorise where
    ``[..., 2]`` vectors would not. The floor under the square root keeps its
    gradient finite where two points coincide (a point to itself), as a
    norm's is.
    """
    dx, dy = ax.unsqueeze(1) - bx.unsqueeze(0), ay.unsqueeze(1) - by.unsqueeze(0)
    return torch.addcmul(dx * dx, dy, dy).clamp_min(1e-30).sqrt()


def range_links(entities: list, env_index: int, max_range: float) -> list:
    """Black lines between every two of ``entities`` at most ``max_range`` apart in env ``env_index``.

    What ``extra_render`` draws between agents that can talk to each other;
    the lines come in pair order ``(0, 1), (0, 2), ..., (1, 2), ...``.
    """
    from vmas_ros.simulator import rendering

    pos = torch.stack([entity.state.pos[env_index] for entity in entities])  # [n, 2]
    close = (torch.linalg.vector_norm(pos.unsqueeze(1) - pos.unsqueeze(0), dim=-1) <= max_range).triu(diagonal=1)
    links = []
    for i, j in close.nonzero().tolist():
        link = rendering.Line(tuple(pos[i].tolist()), tuple(pos[j].tolist()), width=1)
        link.set_color(*Color.BLACK.value)
        links.append(link)
    return links


def greedy_first_match(dist: Tensor) -> Tensor:
    """The column matched to row 0 of each ``[A, L]`` matrix of ``dist`` ``[B, A, L]``; -1 where none is.

    Greedy matching: the globally nearest (row, column) pair is matched and
    both leave, then the nearest of the rest, and so on. A heuristic builds
    ``dist`` from one agent's observation with that agent as row 0, so every
    agent computes the same matching and they go to different landmarks
    without talking. Returns ``[B]`` long.
    """
    batch, n_rows, n = dist.shape
    big = torch.finfo(dist.dtype).max
    mine = torch.full((batch,), -1, dtype=torch.long, device=dist.device)
    for _ in range(min(n_rows, n)):
        flat = dist.flatten(1).argmin(dim=1)
        row, column = flat // n, flat % n
        mine = torch.where((row == 0) & (mine < 0), column, mine)
        dist = dist.scatter(1, row.view(-1, 1, 1).expand(-1, 1, n), big)
        dist = dist.scatter(2, column.view(-1, 1, 1).expand(-1, n_rows, 1), big)
    return mine
