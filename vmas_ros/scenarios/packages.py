"""Pieces shared by the package-pushing tasks (``transport``, ``reverse_transport``).

* env selectors: ``place`` (write per-env draws with ``set_pos``, whatever the
  selector; ``vmas_ros.scenarios.common`` counts the selected envs);
* spawning: ``spawn_apart``, batched rejection sampling of positions kept a
  minimum distance from each other and from already occupied points;
* delivery bookkeeping: ``delivery_reward`` (the shaped reward of packages
  moving towards their goal) and ``package_colors`` (red, green once delivered);
* heuristics: ``unit`` and ``scale_to_range``.

Every function is batched over envs (tensors ``[B, ...]``) and has no host
sync, except ``spawn_apart``, which runs at reset only and must know when all
of its draws are clear.
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from vmas_ros.scenarios.common import for_index
from vmas_ros.simulator.utils import Color

#: an env selector as ``reset_world_at`` receives it: all envs, one env, or a 1-D index tensor
EnvIndex = None | int | Tensor
#: rejection-sampling rounds after which ``spawn_apart`` gives up
MAX_SPAWN_ROUNDS = 10_000


# ------------------------------------------------------------------ env selectors
def place(entity, pos: Tensor, env_index: EnvIndex) -> None:
    """``entity.set_pos`` with ``pos`` drawn per selected env ([rows, 2]), for any selector."""
    entity.set_pos(for_index(pos, env_index), batch_index=env_index)


# ----------------------------------------------------------------------- spawning
def spawn_apart(
    rows: int,
    count: int,
    min_dist: float,
    low: Sequence[float],
    high: Sequence[float],
    device,
    occupied: Tensor | None = None,
    what: str = "entities",
) -> Tensor:
    """``count`` points per row, uniform in the rectangle ``[low, high]``: [rows, count, 2].

    Points are drawn one after the other; each must lie at least ``min_dist``
    from every point of ``occupied`` ([rows, k, 2], same row) and from the
    points drawn before it. Only the rows whose draw clashes are redrawn, so a
    round costs one batched draw whatever the number of envs. Raises
    ValueError (the kwargs asked for too much) naming ``what`` if the
    rectangle is too crowded to finish.
    """
    low_t = torch.tensor(low, dtype=torch.float32, device=device)
    span = torch.tensor(high, dtype=torch.float32, device=device) - low_t
    placed = torch.zeros(rows, 0, 2, device=device) if occupied is None else occupied
    first = placed.shape[1]
    for _ in range(count):
        pos = low_t + span * torch.rand(rows, 1, 2, device=device)
        for _ in range(MAX_SPAWN_ROUNDS):
            clash = (torch.cdist(pos, placed).squeeze(1) < min_dist).any(dim=-1)  # [rows]
            if not bool(clash.any()):
                break
            pos = torch.where(clash[:, None, None], low_t + span * torch.rand(rows, 1, 2, device=device), pos)
        else:
            raise ValueError(
                f"could not spawn {count} {what} {min_dist:.3f} apart in [{list(low)}, {list(high)}] "
                f"after {MAX_SPAWN_ROUNDS} rounds: too crowded, use fewer or smaller entities"
            )
        placed = torch.cat([placed, pos], dim=1)
    return placed[:, first:]


# -------------------------------------------------------------------- delivery
def delivery_reward(previous: Tensor, potential: Tensor, on_goal: Tensor) -> Tensor:
    """Shaped team reward [B] from per-package potentials ``[B, P]`` (or ``[B]``).

    A package earns the decrease of its potential (the shaping factor times its
    distance to the goal) since the last step, except in a step that ends with
    it on the goal (as in VMAS): then it earns nothing, neither for the last
    bit of its approach nor for being nudged about once delivered.
    """
    gain = torch.where(on_goal, 0.0, previous - potential)
    return gain.sum(dim=-1) if gain.dim() > 1 else gain


def package_colors(on_goal: Tensor) -> Tensor:
    """Per-env colours [..., 3]: red while a package is away, green once it is on its goal.

    A lookup in a cached two-row palette (one ``index_select``): painting runs every step.
    """
    palette = _PALETTES.get(on_goal.device)
    if palette is None:
        palette = _PALETTES[on_goal.device] = torch.tensor([Color.RED.value, Color.GREEN.value], device=on_goal.device)
    return torch.index_select(palette, 0, on_goal.flatten().long()).view(*on_goal.shape, 3)


_PALETTES: dict = {}  # device -> [2, 3] (red, green)


# ---------------------------------------------------------------------- heuristics
def unit(vectors: Tensor, eps: float = 1e-6) -> Tensor:
    """Vectors [..., 2] scaled to length 1 (zero vectors stay zero)."""
    return vectors / torch.linalg.vector_norm(vectors, dim=-1, keepdim=True).clamp_min(eps)


def scale_to_range(direction: Tensor, u_range: float) -> Tensor:
    """The action ``u_range * direction`` (``direction`` of norm <= 1), clamped to the range per component."""
    return (direction * u_range).clamp(-u_range, u_range)
