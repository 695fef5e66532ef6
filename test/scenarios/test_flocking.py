"""``flocking``: API, parity with VMAS 1.5.2, the target's script, physics sanity, heuristic.

Oracle: ``vmas`` (same start, same clock and shaping state -> same obs,
rewards and states, lidar readings included). Lidar scenarios are slow in
both implementations, so batches and rollouts are small.
"""
from __future__ import annotations

import pytest
import torch

from test.scenarios import harness
from vmas_ros.testing import parity, vmas_states
from vmas_ros.scenarios import flocking
from vmas_ros.simulator.heuristic_policy import RandomPolicy

NAME = "flocking"
#: every upstream kwarg away from its default
CUSTOM = {
    "n_agents": 3, "n_obstacles": 2, "min_dist_between_entities": 0.3, "n_lidar_rays": 8, "collision_reward": -0.5,
    "dist_shaping_factor": 2.0,
}


def make(num_envs: int, **kwargs):
    return harness.make(flocking.Scenario(), num_envs, **kwargs)


def positions(env) -> torch.Tensor:
    """Every agent's position, the target first: [B, 1 + n_agents, 2]."""
    return torch.stack([a.state.pos for a in env.world.agents], dim=1)


def contacts(env) -> torch.Tensor:
    """Per env, agent pairs (target excluded) whose surfaces are within the scenario's collision distance: [B]."""
    pos = positions(env)[:, 1:]
    gap = torch.cdist(pos, pos) - 2 * 0.05
    return (gap <= flocking.COLLISION_DISTANCE).triu(diagonal=1).sum(dim=(1, 2))


# ------------------------------------------------------------------- construction
def test_default_construction():
    env = make(2)
    world = env.world
    assert [a.name for a in world.agents] == ["target", "agent_0", "agent_1", "agent_2", "agent_3"]
    assert [a.name for a in env.agents] == ["agent_0", "agent_1", "agent_2", "agent_3"]  # the target is scripted
    assert world.agents[0].action_script is not None and all(a.action_script is None for a in env.agents)
    assert [l.name for l in world.landmarks] == [f"obstacle_{i}" for i in range(5)]
    assert all(l.collide and not l.movable and l.shape.radius == 0.1 for l in world.landmarks)
    assert all(a.collide and a.shape.radius == 0.05 for a in world.agents)
    assert (world.substeps, world.collision_force, world.drag, world.dt) == (5, 400, 0.25, 0.1)
    assert world.x_semidim is None and world.y_semidim is None
    for agent in env.agents:
        (lidar,) = agent.sensors
        assert (lidar.n_rays, lidar.max_range) == (12, 0.2)
        # the lidar sees obstacles, neither the agents nor the target
        assert [e.name for e in world.entities if lidar.entity_filter(e)] == [l.name for l in world.landmarks]
    obs = env.reset()
    assert [tuple(o.shape) for o in obs] == [(2, 18)] * 4
    torch.testing.assert_close(world.agents[0].state.pos, torch.tensor([[0.0, -1.0]] * 2))


def test_custom_construction():
    env = make(2, **CUSTOM)
    assert [a.name for a in env.agents] == ["agent_0", "agent_1", "agent_2"]
    assert [l.name for l in env.world.landmarks] == ["obstacle_0", "obstacle_1"]
    assert all(a.sensors[0].n_rays == 8 for a in env.agents)
    assert all(getattr(env.scenario, key) == value for key, value in CUSTOM.items())
    assert [tuple(o.shape) for o in env.reset()] == [(2, 14)] * 3
    pos = positions(env)
    assert (torch.cdist(pos, pos) + torch.eye(4) >= 0.3).all()  # spawned min_dist apart, target included


def test_bad_and_unknown_kwargs():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)
    for bad in ({"n_agents": 0}, {"n_lidar_rays": 0}, {"n_obstacles": -1}, {"min_dist_between_entities": -1}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            make(2, **bad)
    with pytest.raises(ValueError, match="n_lidar_rays"):
        flocking.HeuristicPolicy(n_lidar_rays=0)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("mode", list(harness.SPACE_MODES))
def test_spaces_match_upstream_and_actions_work(mode):
    options = harness.SPACE_MODES[mode]
    obs, _rews = harness.check_spaces(make(2, **options), harness.make_upstream(NAME, 2, **options), steps=3)
    values = list(obs.values()) if isinstance(obs, dict) else obs
    assert [tuple(v.shape) for v in values] == [(2, 18)] * 4


# -------------------------------------------------------------------------- reset
def scenario_state(env) -> dict:
    return {"t": env.scenario.t, "shaping": env.scenario.distance_shaping.T}  # per env: rows


@pytest.mark.parametrize("index", [2, [0, 3], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(6)
    env.reset()
    for _ in range(6):
        env.step([torch.ones(6, 2)] * 4)
    check = harness.check_reset_at(env, index, mask_rows=slice(None, None, 2), scenario_state=scenario_state)
    chosen, scenario = check.chosen, env.scenario
    assert (scenario.t[chosen] == 0).all() and (scenario.t[~chosen] == 6).all()
    start = torch.tensor([0.0, -1.0]).expand(int(chosen.sum()), 2)
    torch.testing.assert_close(env.world.agents[0].state.pos[chosen], start)
    # the shaping baseline of a reset env is that of its new positions
    torch.testing.assert_close(scenario.distance_shaping[:, chosen], scenario._shaping(scenario._distances())[:, chosen])


# ------------------------------------------------------------------------- parity
def test_matches_upstream_vmas():
    up, ours = harness.make_upstream(NAME, 6), make(6)
    harness.copy_start(up, ours, vmas_states.flocking)
    seen = parity.run_lockstep(up, ours, seed=0, steps=40)
    assert seen.fastest > 0.3  # the target got going


def test_matches_upstream_vmas_in_contact():
    """Custom kwargs, agents and obstacles packed into a small square: collisions and lidar hits happen."""
    up, ours = harness.make_upstream(NAME, 6, **CUSTOM), make(6, **CUSTOM)
    parity.copy_random_state(up, ours, seed=3, spread=0.35)
    harness.copy_start(up, ours, vmas_states.flocking)
    lidar_hits, collision_steps = [], 0
    for step in range(30):
        actions = parity.uniform_actions(up, torch.Generator().manual_seed(step))
        obs_up, rew_up, _, info_up = up.step([a.clone() for a in actions])
        obs, rew, _, info = ours.step([a.clone() for a in actions])
        parity.assert_same_state(up, ours, step)
        for mine, theirs in zip(obs + rew, obs_up + rew_up, strict=True):
            torch.testing.assert_close(mine, theirs, atol=parity.ATOL, rtol=0)
        for mine, theirs in zip(info, info_up, strict=True):
            for key in ("agent_collision_rew", "agent_distance_rew"):
                torch.testing.assert_close(mine[key], theirs[key], atol=parity.ATOL, rtol=0)
        lidar_hits.append(min(float(o[:, 6:].min()) for o in obs))
        collision_steps += int(sum((i["agent_collision_rew"] < 0).sum() for i in info))
    assert min(lidar_hits) < 0.15 and collision_steps > 0


# --------------------------------------------------------------------- semantics
def test_target_follows_its_script():
    """Unit force along heading t / 30 from rest: after one step its velocity is dt x (1, 0); then it turns."""
    env = make(2, n_obstacles=0, n_agents=1)
    env.reset()
    env.agents[0].set_pos(torch.tensor([[5.0, 5.0]] * 2), batch_index=None)  # out of the way
    target = env.world.agents[0]
    env.step([torch.zeros(2, 2)])
    torch.testing.assert_close(target.state.vel, torch.tensor([[0.1, 0.0]] * 2))
    for _ in range(59):
        env.step([torch.zeros(2, 2)])
    heading = torch.atan2(target.state.vel[:, 1], target.state.vel[:, 0])
    assert (heading > 1.5).all() and (heading < 2.0).all()  # the force turned by 59 / 30 rad; drag lags it
    assert (env.scenario.t == 60).all()


def test_reward_terms():
    """Two agents touching each other: -0.1 each, counted in the info; the shaping term telescopes."""
    env = make(1, n_obstacles=0, n_agents=2)
    env.reset()
    env.agents[0].set_pos(torch.tensor([[0.0, 0.0]]), batch_index=None)
    env.agents[1].set_pos(torch.tensor([[0.099, 0.0]]), batch_index=None)
    _, rews, _, infos = env.step([torch.zeros(1, 2)] * 2)
    assert [float(i["agent_collision_rew"]) for i in infos] == pytest.approx([-0.1, -0.1])
    for rew, info in zip(rews, infos):
        torch.testing.assert_close(rew, info["agent_collision_rew"] + info["agent_distance_rew"])
    before = env.scenario.distance_shaping.clone()
    _, _, _, infos = env.step([torch.zeros(1, 2)] * 2)
    torch.testing.assert_close(torch.stack([i["agent_distance_rew"] for i in infos]),
                               before - env.scenario.distance_shaping)


# ------------------------------------------------------------------ long rollouts
def test_long_rollouts_stay_finite_and_solid():
    """300 steps, half the envs random, half heuristic: values finite; no agent sinks into an obstacle or the target."""
    env = make(8)
    random, heuristic = RandomPolicy().compute_action, flocking.HeuristicPolicy().compute_action
    obs = env.reset()
    deepest = 0.0
    for _ in range(300):
        actions = [torch.cat([random(o[:4], 1.0), heuristic(o[4:], 1.0)]) for o in obs]
        obs, rews, _, _ = env.step(actions)
        assert all(torch.isfinite(o).all() for o in obs) and all(torch.isfinite(r).all() for r in rews)
        agents = positions(env)[:, 1:]
        obstacles = torch.stack([l.state.pos for l in env.world.landmarks], dim=1)
        into_obstacles = 0.15 - torch.cdist(agents, obstacles)
        into_target = 0.1 - torch.linalg.vector_norm(agents - env.world.agents[0].state.pos.unsqueeze(1), dim=-1)
        deepest = max(deepest, float(into_obstacles.max()), float(into_target.max()))
    assert deepest < 0.03


# ---------------------------------------------------------------------- heuristic
def test_heuristic_reacts_to_its_observation():
    policy = flocking.HeuristicPolicy()
    free = torch.full((1, 12), flocking.LIDAR_RANGE)
    far = torch.cat([torch.zeros(1, 4), torch.tensor([[1.5, 0.0]]), free], dim=1)  # target 1.5 to the left
    assert policy.compute_action(far, 1.0)[0, 0] < -0.9
    close = torch.cat([torch.zeros(1, 4), torch.tensor([[0.15, 0.0]]), free], dim=1)  # too close: back off
    assert policy.compute_action(close, 1.0)[0, 0] > 0.9
    blocked = free.clone()
    blocked[0, 6] = 0.02  # an obstacle right behind the ring point (ray 6 points at -x)
    on_ring = torch.cat([torch.zeros(1, 4), torch.tensor([[0.45, 0.0]]), blocked], dim=1)
    assert policy.compute_action(on_ring, 1.0)[0, 0] > 0.5
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 10), 1.0)


def naive_pursuit(observation: torch.Tensor, u_range: float) -> torch.Tensor:
    """The baseline with no collision avoidance: full thrust at the target."""
    return (-observation[:, 4:6] * 10).clamp(-u_range, u_range)


def test_heuristic_flocks_around_the_target():
    """16 envs x 150 steps per policy, seed 0; "settled" = the last 75 steps.

    Measured: the heuristic keeps 87% of agent-steps within 1.0 of the
    target (median distance 0.71) against 43% for random play (median 1.1);
    its mean return per agent, +0.30, beats random's, -0.33 (seeds 1 and 2:
    +0.20 vs -0.29, +0.21 vs -0.46); and it touches other agents in 1.5% of
    agent-pair steps (14 pair-steps per env), where naive pursuit of the
    target touches in 21% (187).

    Random play touches even less (~1 pair-step per env): its agents hardly
    move and stay spread over the arena, while agents that gather round one
    point without seeing each other (the lidar filter sees obstacles only, as
    in VMAS) can only notice a neighbour by touching it. So the collision
    check compares against naive pursuit and bounds the rate.
    """
    results = {}
    for name, policy in [
        ("random", RandomPolicy().compute_action), ("heuristic", flocking.HeuristicPolicy().compute_action),
        ("naive", naive_pursuit),
    ]:
        torch.manual_seed(0)
        env = make(16)
        obs, total, touches, dist = env.reset(), 0.0, 0, []
        for step in range(150):
            obs, rews, _, _ = env.step([policy(o, 1.0) for o in obs])
            total += float(torch.stack(rews).mean())
            touches += int(contacts(env).sum())
            if step >= 75:
                dist.append(torch.stack([o[:, 4:6].norm(dim=-1) for o in obs]))
        dist = torch.stack(dist)
        results[name] = {"ret": total, "touches": touches / 16, "within": float((dist < 1.0).float().mean())}
    heuristic, random, naive = results["heuristic"], results["random"], results["naive"]
    assert heuristic["within"] > 0.8 and random["within"] < 0.5, results
    assert heuristic["ret"] > random["ret"] + 0.3, results
    assert heuristic["touches"] < naive["touches"] / 5, results
    assert heuristic["touches"] < 0.03 * 150 * 6, results  # under 3% of agent-pair steps
