"""Helpers shared by the foraging scenarios (``dispersion``, ``dropout``).

In both tasks non-colliding agents "eat" landmarks by covering them: an agent
covers a landmark when their centres are closer than the sum of their radii.
An eaten landmark stays where it is but is no longer drawn, and pays nothing
more. Everything here is batched over envs and agents; the per-env state (the
``eaten`` flags) lives on the scenario, so ``BaseScenario.to`` moves it.

Reset helpers take VMAS's ``env_index`` selector: ``None`` (every env), an
int (one env), or a 1-D tensor of env indices (the batched reset).
"""
from __future__ import annotations

from collections.abc import Sequence

import torch

from vmas_ros.scenarios.common import selected_rows
from vmas_ros.simulator.core import Entity, World


def stacked_pos(entities: Sequence[Entity]) -> torch.Tensor:
    """Positions of ``entities``, [B, len(entities), 2]."""
    return torch.stack([e.state.pos for e in entities], dim=1)


def radii(entities: Sequence[Entity], device) -> torch.Tensor:
    """Bounding radii of spherical ``entities``, [len(entities)]."""
    return torch.tensor([e.shape.radius for e in entities], dtype=torch.float32, device=device)


def coverage(
    agent_pos: torch.Tensor, agent_radius: torch.Tensor, food_pos: torch.Tensor, food_radius: torch.Tensor,
) -> torch.Tensor:
    """Which agent covers which food, [B, A, F] bool.

    ``agent_pos`` [B, A, 2], ``food_pos`` [B, F, 2], radii [A] and [F]. Covering
    is strict overlap of the two discs (centre distance < sum of radii), the
    rule both scenarios score with.
    """
    gap = torch.linalg.vector_norm(agent_pos.unsqueeze(2) - food_pos.unsqueeze(1), dim=-1)
    return gap < agent_radius.view(1, -1, 1) + food_radius.view(1, 1, -1)


def hide_eaten(food: Sequence[Entity], eaten: torch.Tensor) -> None:
    """Stop drawing each eaten food (``eaten`` [B, F]); food is never moved, only hidden."""
    for k, landmark in enumerate(food):
        landmark.is_rendering.logical_and_(~eaten[:, k])


def show_food(food: Sequence[Entity], env_index) -> None:
    """Draw every food again in the envs ``env_index`` selects (all when None)."""
    for landmark in food:
        if env_index is None:
            landmark.reset_render()
        else:
            landmark.is_rendering[env_index] = True


def uniform_positions(world: World, env_index, count: int, low: float, high: float) -> torch.Tensor:
    """``count`` positions per selected env, uniform in [low, high]^2: [rows, count, 2]."""
    rows = selected_rows(world.batch_dim, env_index)
    return torch.empty(rows, count, world.dim_p, device=world.device).uniform_(low, high)


def spread_positions(
    world: World,
    env_index,
    count: int,
    min_dist: float,
    low: float,
    high: float,
    occupied: torch.Tensor | None = None,
) -> torch.Tensor:
    """``count`` positions per selected env, uniform in [low, high]^2 and pairwise ``min_dist`` apart.

    Also ``min_dist`` from ``occupied`` ([rows, K, 2]) when given. Positions are
    drawn one after another, each redrawn (in the envs where it is too close to
    an earlier one) until it fits, all selected envs at once; unlike
    ``ScenarioUtils.spawn_entities_randomly`` this also serves a batch of env
    indices. Returns [rows, count, 2].
    """
    rows = selected_rows(world.batch_dim, env_index)
    placed = occupied if occupied is not None else torch.empty(rows, 0, world.dim_p, device=world.device)
    first = placed.shape[1]
    for _ in range(count):
        pos = torch.empty(rows, 1, world.dim_p, device=world.device).uniform_(low, high)
        while placed.shape[1]:
            clash = (torch.linalg.vector_norm(placed - pos, dim=-1) < min_dist).any(dim=1)  # [rows]
            if not bool(clash.any()):  # reset time only: the host sync ends the rejection loop
                break
            fresh = torch.empty_like(pos).uniform_(low, high)
            pos = torch.where(clash.view(-1, 1, 1), fresh, pos)
        placed = torch.cat([placed, pos], dim=1)
    return placed[:, first:]
