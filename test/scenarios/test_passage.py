"""``passage``: API, parity with VMAS 1.5.2, reset geometry, safety of long rollouts, heuristic.

Oracle: ``vmas`` 1.5.2 (same start -> same obs, rewards and states). With
``shared_reward`` VMAS charges agent ``k`` the collisions of agents 0..k (its
reward tensor is aliased); ours charges each agent its own, and the test pins
that difference down exactly.
"""
from __future__ import annotations

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import SPACE_MODES
from vmas_ros.testing import parity, vmas_states
from vmas_ros.scenarios import passage
from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.heuristic_policy import RandomPolicy

NAME = "passage"
R = passage.AGENT_RADIUS


def make(num_envs: int = 8, **kwargs):
    return harness.make(passage.Scenario(), num_envs, **kwargs)


def positions(entities) -> torch.Tensor:
    return torch.stack([e.state.pos for e in entities], dim=1)  # [B, n, 2]


def block_clearance(env) -> torch.Tensor:
    """Signed gap between every agent's disc and every solid block, [B, 5, K]: negative when sunk in."""
    solid = [b for b in env.scenario.blocks if b.collide]
    centres, point = positions(solid).unsqueeze(1), positions(env.agents).unsqueeze(2)
    closest = geo.closest_point_on_box_boundary(centres, 0.0, passage.BLOCK_LENGTH, passage.BLOCK_WIDTH, point)
    to_outline = torch.linalg.vector_norm(point - closest, dim=-1)
    inside = ((point - centres).abs() < torch.tensor([passage.BLOCK_LENGTH, passage.BLOCK_WIDTH]) / 2).all(dim=-1)
    return torch.where(inside, -to_outline, to_outline) - R


# ------------------------------------------------------------------- construction
def test_construction():
    env = make(4)
    world = env.world
    assert [a.name for a in env.agents] == [f"agent_{i}" for i in range(5)]
    names = [l.name for l in world.landmarks]
    assert names == [f"goal {i}" for i in range(5)] + [f"passage {i}" for i in range(20)]
    assert (world.x_semidim, world.y_semidim, world.dt, world._substeps, world._drag) == (1, 1, 0.1, 1, 0.25)
    assert all(a.shape.radius == R and a.u_multiplier == 0.7 and a.u_range == 1.0 for a in env.agents)
    blocks = env.scenario.blocks
    assert [b.collide for b in blocks] == [False] + [True] * 19
    assert not blocks[0].is_rendering.any() and all(b.is_rendering.all() for b in blocks[1:])
    assert all((b.shape.length, b.shape.width) == (0.103, 0.2) and not b.movable for b in blocks)
    assert not blocks[1].collides(blocks[2]) and blocks[1].collides(env.agents[0])
    assert env.scenario.extra_render(0)  # the arena's walls
    env3 = make(2, n_passages=3)
    assert [b.collide for b in env3.scenario.blocks[:4]] == [False, False, False, True]
    assert env3.get_from_scenario(True, False, False, False)[0][0].shape == (2, 12)


def test_unknown_kwargs_warn_and_bad_values_raise():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for bad in (0, 21, 1.5):
        with pytest.raises(ValueError, match="n_passages"):
            make(2, n_passages=bad)
    with pytest.raises(ValueError, match="n_passages"):
        passage.HeuristicPolicy(n_passages=0)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("mode", list(SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode):
    options = dict(SPACE_MODES[mode], n_passages=2 if mode == "dict" else 1)
    obs, _ = harness.check_spaces(make(4, **options), harness.make_upstream(NAME, 4, **options), steps=3)
    values = list(obs.values()) if isinstance(obs, dict) else obs
    assert [v.shape[1] for v in values] == [10 if mode == "dict" else 8] * 5


# ---------------------------------------------------------------- starting state
def test_start_is_a_cross_below_and_its_copy_above():
    env = make(64)
    agents, goals = positions(env.agents), positions([a.goal for a in env.agents])
    for points, low, high in ((agents, -0.8, -0.3), (goals, 0.3, 0.8)):
        centre = points.mean(dim=1)  # the cross's arms cancel out
        offsets = points - centre.unsqueeze(1)
        assert (centre[:, 0].abs() <= 0.8 + 1e-5).all()
        assert ((centre[:, 1] >= low - 1e-5) & (centre[:, 1] <= high + 1e-5)).all()
        rounded = {tuple(sorted(map(tuple, (o * 10).round().int().tolist()))) for o in offsets}
        assert rounded == {((-1, 0), (0, -1), (0, 0), (0, 1), (1, 0))}
    torch.testing.assert_close(goals - goals.mean(dim=1, keepdim=True), agents - agents.mean(dim=1, keepdim=True))
    places = (agents - agents.mean(dim=1, keepdim=True)).mul(10).round()
    assert len({tuple(p.flatten().tolist()) for p in places}) > 20  # places shuffled per env
    block_x = positions(env.scenario.blocks)[..., 0]
    slots = -1 - R + 0.103 / 2 + 0.103 * torch.arange(20)
    torch.testing.assert_close(block_x.sort(dim=1).values, slots.expand(64, 20))
    assert len(set(block_x[:, 0].tolist())) > 10  # the gap is anywhere, per env
    torch.testing.assert_close(
        env.scenario.global_shaping, torch.linalg.vector_norm(agents - goals, dim=-1) * 100, rtol=1e-5, atol=1e-4
    )


@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(8)
    gen = torch.Generator().manual_seed(1)
    for _ in range(5):
        env.step([torch.rand(8, 2, generator=gen) * 2 - 1 for _ in env.agents])
    for block in env.scenario.blocks:  # off their slots, so a reset must redraw every block
        block.set_pos(block.state.pos + 0.01, batch_index=None)
    check = harness.check_reset_at(
        env, index, mask_rows=slice(None, None, 3), bound=1.0 + R,
        scenario_state=lambda env: {"shaping": env.scenario.global_shaping},
    )
    chosen = check.chosen
    agents, goals = positions(env.agents)[chosen], positions([a.goal for a in env.agents])[chosen]
    torch.testing.assert_close(check.after["shaping"][chosen], torch.linalg.vector_norm(agents - goals, dim=-1) * 100)


# ------------------------------------------------------------------------- parity
def upward_actions(batch: int):
    """Random actions biased up, towards the barrier, so agents hit it and each other."""
    def draw(gen: torch.Generator):
        return [
            torch.stack([torch.rand(batch, generator=gen) * 2 - 1, torch.rand(batch, generator=gen) * 1.5 - 0.3], dim=1)
            .clamp(-1, 1)
            for _ in range(5)
        ]
    return draw


@pytest.mark.parametrize("n_passages", [1, 4])
def test_matches_upstream_vmas(n_passages):
    up, ours = harness.make_upstream(NAME, 8, n_passages=n_passages), make(8, n_passages=n_passages)
    harness.copy_start(up, ours, vmas_states.passage)
    seen = parity.run_lockstep(up, ours, seed=0, steps=35, actions=upward_actions(8))
    assert seen.largest_reward > 10  # collisions were charged


def test_shared_reward_matches_upstream_up_to_its_aliasing():
    """Same states and observations; upstream's reward of agent ``k`` is ours plus the
    (negative) collision terms of agents ``0..k-1``; ``info`` splits ours in its two terms."""
    batch = 8
    up, ours = harness.make_upstream(NAME, batch, shared_reward=True), make(batch, shared_reward=True)
    harness.copy_start(up, ours, vmas_states.passage)
    draw, gen = upward_actions(batch), torch.Generator().manual_seed(0)
    charged = 0.0
    for step in range(1, 31):
        actions = draw(gen)
        obs_up, rew_up, done_up, _ = up.step([a.clone() for a in actions])
        obs, rew, done, info = ours.step([a.clone() for a in actions])
        parity.assert_same_state(up, ours, step)
        for mine, theirs in zip(obs, obs_up, strict=True):
            torch.testing.assert_close(mine, theirs, atol=parity.ATOL, rtol=0)
        assert torch.equal(done, done_up)
        collisions = torch.stack([i["collision_rew"] for i in info])  # [5, B]
        earlier = torch.cumsum(collisions, dim=0) - collisions
        torch.testing.assert_close(torch.stack(rew) + earlier, torch.stack(rew_up), atol=parity.ATOL, rtol=0)
        shaping = torch.stack([i["shaping_rew"] for i in info])
        assert (shaping == shaping[0]).all()  # shared
        torch.testing.assert_close(shaping + collisions, torch.stack(rew))
        charged = max(charged, float(-collisions.min()))
    assert charged >= 10


def test_done_when_every_agent_is_on_its_goal():
    env = make(2)
    goals = positions([a.goal for a in env.agents])
    on_goal = goals + torch.tensor([0.0, 0.01])
    on_goal[1, 2] += torch.tensor([0.0, 0.01])  # env 1: agent 2 is 0.02 off (more than half its radius)
    for i, agent in enumerate(env.agents):
        agent.set_pos(on_goal[:, i], batch_index=None)
    assert env.done().tolist() == [True, False]


# ------------------------------------------------------------------------ safety
def test_long_rollouts_stay_finite_and_out_of_the_barrier():
    """200 steps, a third random, a third heuristic among random, a third heuristic;
    agents driven into the barrier sink at most 2 cm into it, never through it."""
    torch.manual_seed(0)
    env = make(6)
    heuristic, rand = passage.HeuristicPolicy().compute_action, RandomPolicy().compute_action
    worst = torch.tensor(1.0)

    def watched(obs, u_range):  # agent 0 of the first line-up: looks once per step
        nonlocal worst
        worst = torch.minimum(worst, block_clearance(env).min())
        return rand(obs, u_range)

    lineups = [[watched] + [rand] * 4, [heuristic, rand, heuristic, rand, heuristic], [heuristic] * 5]
    harness.play_lineups(env, lineups, steps=200)
    assert -0.02 < worst < 0.0, worst  # agents did touch the barrier, but shallowly


# --------------------------------------------------------------------- heuristic
def test_heuristic_climbs_only_when_lined_up():
    policy = passage.HeuristicPolicy()
    #                     pos        vel    goal offset   gap offset
    below_aligned = [0.3, -0.3, 0.0, 0.0, 0.0, 0.8, 0.0, 0.3]
    below_off = [0.5, -0.3, 0.0, 0.0, -0.2, 0.8, -0.2, 0.3]
    at_barrier_off = [0.5, -0.17, 0.0, 0.0, -0.2, 0.8, -0.2, 0.17]
    above = [0.3, 0.3, 0.0, 0.0, 0.2, 0.2, 0.0, -0.3]
    action = policy.compute_action(torch.tensor([below_aligned, below_off, at_barrier_off, above]), 1.0)
    assert action[0, 1] > 0.9 and action[0, 0].abs() < 1e-6  # straight up through the gap
    assert action[1, 0] < -0.2 and action[1, 1].abs() < 1e-6  # sideways towards the gap, no climbing
    assert action[2, 1] <= 0  # not into the barrier
    assert action[3, 0] > 0.5 and action[3, 1] > 0.5  # to the goal
    assert (action.abs() <= 1).all()
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 10), 1.0)


def test_heuristic_crosses_the_barrier_and_rebuilds_the_cross():
    """32 envs x 360 steps (seed 0): 16 with the heuristic, 16 random.

    Measured (64 envs, seed 1): every formation through the gap and on its goals
    (done) by step ~180 median, ~330 at most for the farthest gaps; mean return
    ~ +90 per agent (about 110 of shaping less some collisions where the cross
    straddles the gap or passes a parked team-mate). Random agents make no
    progress and bump into each other and the barrier: ~ -85. Required: at least
    14 of the 16 heuristic envs done (all 16 are), and a gain of 100 per agent.
    """
    torch.manual_seed(0)
    env = make(32, seed=0)
    heuristic = passage.HeuristicPolicy().compute_action
    done_ever = torch.zeros(32, dtype=torch.bool)

    def watched(obs, u_range):
        nonlocal done_ever
        done_ever = done_ever | env.done()
        return heuristic(obs, u_range)

    returns = harness.play_lineups(env, [[watched] + [heuristic] * 4, [None] * 5], steps=360)
    heuristic_return, random_return = returns.mean(dim=0).tolist()
    assert int(done_ever[:16].sum()) >= 14 and not done_ever[16:].any(), done_ever
    assert heuristic_return > random_return + 100, returns
