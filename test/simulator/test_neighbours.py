"""ClosePairs: a swarm's pairs found through the grid are exactly the pairs every-pair comparison finds."""
from __future__ import annotations

import math

import pytest
import torch

from vmas_ros.simulator.neighbours import ClosePairs
from vmas_ros.simulator.thresholds import GRID_MIN_SPHERES, GRID_START_CAPACITY


def _brute(pos: torch.Tensor, within: float) -> set:
    batch, n = pos.shape[:2]
    d = torch.linalg.vector_norm(pos.unsqueeze(2) - pos.unsqueeze(1), dim=-1)
    b, i, j = torch.nonzero((d <= within) & torch.ones(n, n, dtype=torch.bool, device=pos.device).triu(1),
                            as_tuple=True)
    return set(zip((b * n + i).tolist(), (b * n + j).tolist()))


@pytest.mark.parametrize("side", [0.5 * math.sqrt(400), 2.0, 0.5], ids=["sparse", "crowded", "dense"])
def test_hashed_pairs_are_every_close_pair(device, side):
    n, within = max(GRID_MIN_SPHERES, 400), 0.105
    generator = torch.Generator().manual_seed(1)
    pos = ((torch.rand(3, n, 2, generator=generator) - 0.5) * side).to(device)
    pos[1, :10] = pos[0, :10]  # the same close pairs in two envs: each env's own
    close = ClosePairs(within)
    first, second = close(pos)
    found = set(zip(first.tolist(), second.tolist()))
    assert len(found) == len(first), "a pair was listed twice"
    expected = _brute(pos, within)
    assert expected and found == expected
    if side <= 0.5:  # a dense crowd outgrows the starting room, and is computed again with more
        assert close.capacity > GRID_START_CAPACITY


def test_a_small_team_compares_every_pair(device):
    pos = torch.tensor([[[0.0, 0.0], [0.1, 0.0], [0.3, 0.0]], [[0.0, 0.0], [0.5, 0.0], [0.55, 0.0]]], device=device)
    first, second = ClosePairs(0.1)(pos)
    assert set(zip(first.tolist(), second.tolist())) == {(0, 1), (4, 5)}
