"""Which agents are close to which: pairs of points within a distance, in every env at once.

Scenarios ask it for terms such as "how many other agents does each one
touch". A small team compares every pair (a few large tensor ops); a swarm
finds its pairs through the engine's spatial hash
(:mod:`vmas_ros.simulator.physics.spatial_hash`), whose cost grows with the
number of agents rather than its square. Both give the same pairs: each pair's
distance is computed the same way, and the hash only decides which pairs are
worth computing.
"""
from __future__ import annotations

from typing import Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.physics.spatial_hash import candidates_within
from vmas_ros.simulator.thresholds import GRID_MIN_SPHERES, GRID_START_CAPACITY

__all__ = ["ClosePairs"]


class ClosePairs:
    """Every pair of points at most ``within`` apart, per env.

    ``pairs(pos)``, ``pos`` ``[B, n, 2]``: returns ``(first, second)``, int64
    flat indices ``b * n + i`` of the two points of each such pair, ``i < j``,
    in no particular order. The distance is ``torch.linalg.vector_norm`` of the
    difference. A swarm's hashed list keeps the room it needed last time, and
    grows it (computing again) when a call needs more: no pair is ever missed.
    """

    def __init__(self, within: float) -> None:
        self.within = float(within)
        self.capacity = GRID_START_CAPACITY
        self._triu = None  # every pair (i < j) of a small team, [2, P]

    def __call__(self, pos: Tensor) -> Tuple[Tensor, Tensor]:
        batch, n = pos.shape[:2]
        flat = pos.reshape(batch * n, 2)
        if n >= GRID_MIN_SPHERES:
            first, second = self._hashed(flat, n)
        else:
            first, second = self._every_pair(batch, n, pos.device)
        close = torch.linalg.vector_norm(flat[first] - flat[second], dim=-1) <= self.within
        return first[close], second[close]

    def _every_pair(self, batch: int, n: int, device) -> Tuple[Tensor, Tensor]:
        if self._triu is None or self._triu.shape[1] != n * (n - 1) // 2 or self._triu.device != device:
            self._triu = torch.triu_indices(n, n, 1, device=device)
        offset = (torch.arange(batch, device=device) * n).unsqueeze(1)  # [B, 1]
        return (offset + self._triu[0]).reshape(-1), (offset + self._triu[1]).reshape(-1)

    def _hashed(self, flat: Tensor, n: int) -> Tuple[Tensor, Tensor]:
        x, y = flat[:, 0].contiguous(), flat[:, 1].contiguous()
        found, self.capacity = candidates_within(x, y, n, x, y, n, self.within, self.capacity)
        keep = found.valid & (found.target > found.query)
        return found.query[keep].long(), found.target[keep].long()
