"""discovery's batched respawn (``respawn_clear``): only covered targets move, they land clear of
everything in VMAS's order, where they land is uniform over the clear part of the arena, and computing
only the envs with a covered target gives the same bits as computing all."""
from __future__ import annotations

import math

import torch

from vmas_ros.scenarios.discovery import draw_candidates, respawn_clear, respawn_from

MIN_DIST = 0.2


def rows(points, batch, device):
    """Planar rows ``(x, y)``, each ``[len(points), batch]``, of fixed points repeated in every env."""
    t = torch.tensor(points, dtype=torch.float32, device=device).view(-1, 2)
    return t[:, 0:1].expand(-1, batch).contiguous(), t[:, 1:2].expand(-1, batch).contiguous()


def squared_distance(ax, ay, bx, by):
    return (ax - bx) ** 2 + (ay - by) ** 2


def test_only_covered_targets_move_and_land_clear_in_order(device):
    torch.manual_seed(0)
    batch, n_agents, n_targets = 4000, 5, 7
    ax, ay = torch.rand(2, n_agents, batch, device=device) * 2 - 1
    tx, ty = torch.rand(2, n_targets, batch, device=device) * 2 - 1
    covered = torch.rand(n_targets, batch, device=device) < 0.4  # often several per env at once
    new_x, new_y = respawn_clear(ax, ay, tx, ty, covered, MIN_DIST, 1.0, 1.0, 16)

    moved = (new_x != tx) | (new_y != ty)
    assert not (moved & ~covered).any(), "a target that was not covered moved"
    assert moved[covered].float().mean() > 0.999, "covered targets should (almost) always find a spot"
    assert (new_x.abs() <= 1).all() and (new_y.abs() <= 1).all()
    limit = MIN_DIST ** 2
    for i in range(n_targets):
        m = moved[i]
        clear_of_agents = squared_distance(new_x[i], new_y[i], ax, ay).amin(0) >= limit
        assert clear_of_agents[m].all(), f"target {i} landed on an agent"
        for j in range(n_targets):
            if j == i:
                continue
            # earlier targets are already at their new spots; later ones still at their old ones
            ox, oy = (new_x[j], new_y[j]) if j < i else (tx[j], ty[j])
            assert (squared_distance(new_x[i], new_y[i], ox, oy) >= limit)[m].all(), (i, j)


def test_landing_spots_are_uniform_over_the_clear_region(device):
    """Two targets respawn in every env, with one agent at the centre.

    Target 0 must keep clear of target 1's old spot (target 1 has not moved
    yet), target 1 need not. Target 1 scans only points target 0 never looked
    at; if it rescanned the stream from the start, it would often take a
    point target 0 had rejected for being near target 1's old spot, and land
    there about twice as often as the area there allows. Checked: quadrant
    shares (target 0, whose old spot is far away), the mean distance from the
    centre against its exact value for a uniform point in the square minus
    the agent's disc, and target 1's share near its old spot against that
    disc's share of the area left to it.
    """
    torch.manual_seed(1)
    batch = 40000
    ax, ay = rows([(0.0, 0.0)], batch, device)
    tx, ty = rows([(5.0, 5.0), (0.5, 0.5)], batch, device)
    covered = torch.ones(2, batch, dtype=torch.bool, device=device)
    new_x, new_y = respawn_clear(ax, ay, tx, ty, covered, MIN_DIST, 1.0, 1.0, 16)
    r = torch.sqrt(new_x ** 2 + new_y ** 2)
    assert (r >= MIN_DIST).all()
    quadrants = torch.stack([(new_x[0] > 0) & (new_y[0] > 0), (new_x[0] < 0) & (new_y[0] > 0),
                             (new_x[0] < 0) & (new_y[0] < 0), (new_x[0] > 0) & (new_y[0] < 0)]).float().mean(1)
    # target 0's clear area per quadrant: 1, less a quarter of the agent's disc, less (first quadrant)
    # the whole disc round target 1's old spot
    disc_area = math.pi * MIN_DIST ** 2
    areas = torch.tensor([1 - disc_area / 4 - disc_area] + [1 - disc_area / 4] * 3, device=device)
    assert torch.allclose(quadrants, areas / areas.sum(), atol=0.01), (quadrants, areas / areas.sum())
    # E|p| for p uniform in [-1, 1]^2 minus the agent's disc (target 1: its old spot does not block it)
    whole = (math.sqrt(2) + math.asinh(1)) / 3  # mean distance in the square, area 4
    hole = 2 * math.pi * MIN_DIST ** 3 / 3 / 4  # the disc's share of that integral
    expected_r = (whole - hole) / (1 - disc_area / 4)
    assert abs(float(r[1].mean()) - expected_r) < 0.01, (float(r[1].mean()), expected_r)
    near_old = squared_distance(new_x[1], new_y[1], tx[1], ty[1]) < MIN_DIST ** 2
    share = float(near_old.float().mean())
    # the area left to target 1: the square minus the agent's and target 0's new discs (~3.35% near)
    assert 0.028 < share < 0.040, share
    assert (squared_distance(new_x[1], new_y[1], new_x[0], new_y[0]) >= MIN_DIST ** 2).all()


def test_without_agents_or_covering_nothing_breaks(device):
    batch = 64
    empty = torch.zeros(0, batch, device=device)
    tx, ty = torch.rand(2, 3, batch, device=device)
    none = torch.zeros(3, batch, dtype=torch.bool, device=device)
    new_x, new_y = respawn_clear(empty, empty, tx, ty, none, MIN_DIST, 1.0, 1.0, 16)
    assert torch.equal(new_x, tx) and torch.equal(new_y, ty)
    all_ = torch.ones(3, batch, dtype=torch.bool, device=device)
    new_x, new_y = respawn_clear(empty, empty, tx, ty, all_, MIN_DIST, 1.0, 1.0, 16)
    assert ((new_x != tx) | (new_y != ty)).all()
    assert new_x.device == tx.device and new_x.shape == tx.shape


def test_computing_only_the_covered_envs_gives_the_same_bits(device):
    """Covering in a few envs and on some targets only (as in play), then in every env: both ways of
    running ``respawn_from`` agree bit for bit, and targets of envs without covering stay."""
    torch.manual_seed(2)
    batch, n_agents, n_targets = 500, 5, 7
    ax, ay = torch.rand(2, n_agents, batch, device=device) * 2 - 1
    tx, ty = torch.rand(2, n_targets, batch, device=device) * 2 - 1
    cand_x, cand_y = draw_candidates(batch, 1.0, 1.0, 16, device)
    few = torch.zeros(n_targets, batch, dtype=torch.bool, device=device)
    few[2, 7] = few[2, 300] = few[5, 300] = few[6, 41] = True
    for covered in (few, torch.rand(n_targets, batch, device=device) < 0.4, torch.zeros_like(few)):
        only = respawn_from(cand_x, cand_y, ax, ay, tx, ty, covered, MIN_DIST ** 2, only_covered_envs=True)
        every = respawn_from(cand_x, cand_y, ax, ay, tx, ty, covered, MIN_DIST ** 2, only_covered_envs=False)
        assert torch.equal(only[0], every[0]) and torch.equal(only[1], every[1])
        moved = (only[0] != tx) | (only[1] != ty)
        assert not (moved & ~covered).any()
        assert covered.sum() == 0 or moved[covered].float().mean() > 0.99  # covered targets (almost) always move
