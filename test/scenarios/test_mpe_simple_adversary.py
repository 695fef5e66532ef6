"""simple_adversary: construction, spaces, resets, parity with VMAS 1.5.2, semantics of MPE, heuristic.

Upstream VMAS draws one goal landmark for the whole batch; ours draws one per
env (``Scenario.goal``). Parity tests copy upstream's goal into every env.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

import vmas
import vmas_ros
from vmas_ros.scenarios.mpe import simple_adversary as scenario

NAME = "simple_adversary"
BATCH = 16
FIELDS = ("pos", "vel", "rot", "ang_vel")
KWARGS = [{}, {"n_agents": 5, "n_adversaries": 2}]


def _make(num_envs: int = BATCH, seed: int = 0, **kwargs):
    return vmas_ros.make_env(scenario.Scenario(), num_envs=num_envs, device="cpu", seed=seed, **kwargs)


def _space(space):
    """A plain description of a space, comparable between gym (upstream) and gymnasium (ours)."""
    kind = type(space).__name__
    if kind == "Tuple":
        return kind, [_space(s) for s in space.spaces]
    if kind == "Dict":
        return kind, {k: _space(s) for k, s in space.spaces.items()}
    if kind == "Box":
        return kind, tuple(space.shape), space.low.tolist(), space.high.tolist()
    if kind == "Discrete":
        return kind, int(space.n)
    return kind, np.asarray(space.nvec).tolist()


def _state(env) -> torch.Tensor:
    """[B, ...] everything a reset redraws: positions of all entities and the goal."""
    pos = torch.stack([e.state.pos for e in env.world.entities], dim=1).flatten(1)
    return torch.cat([pos, env.scenario.goal.unsqueeze(-1).float()], dim=-1)


# ------------------------------------------------------------------ construction
def test_default_world_matches_upstream_facts():
    env, up = _make(), vmas.make_env(NAME, num_envs=2, seed=0)
    assert [e.name for e in env.world.entities] == [e.name for e in up.world.entities]
    for ours, theirs in zip(env.world.entities, up.world.entities):
        assert ours.shape.radius == theirs.shape.radius and ours.collide == theirs.collide == False  # noqa: E712
    assert [a.adversary for a in env.agents] == [True, False, False]
    assert env.world.dim_c == 0 and all(a.silent for a in env.agents)


def test_kwargs_and_validation():
    env = _make(n_agents=5, n_adversaries=2)
    assert [a.name for a in env.agents] == ["adversary_0", "adversary_1", "agent_0", "agent_1", "agent_2"]
    assert len(env.world.landmarks) == 4
    with pytest.warns(UserWarning, match="bogus"):
        _make(bogus=1)
    for bad in ({"n_agents": 2, "n_adversaries": 2}, {"n_adversaries": 0}, {"n_agents": 2.5}):
        with pytest.raises(ValueError, match="n_adversaries"):
            _make(**bad)


# ------------------------------------------------------------------------ spaces
MODES = {
    "continuous": dict(),
    "discrete": dict(continuous_actions=False),
    "multidiscrete": dict(continuous_actions=False, multidiscrete_actions=True),
    "dict": dict(dict_spaces=True),
}


@pytest.mark.parametrize("kwargs", KWARGS)
@pytest.mark.parametrize("mode", MODES.values(), ids=MODES.keys())
def test_spaces_equal_upstream_and_steps_work(kwargs, mode):
    env = _make(num_envs=4, **kwargs, **mode)
    up = vmas.make_env(NAME, num_envs=4, seed=0, **kwargs, **mode)
    assert _space(env.observation_space) == _space(up.observation_space)
    assert _space(env.action_space) == _space(up.action_space)
    for _ in range(3):
        actions = env.get_random_actions()
        if mode.get("dict_spaces"):
            actions = {a.name: act for a, act in zip(env.agents, actions)}
        obs, rews, _, _ = env.step(actions)
    if isinstance(obs, dict):
        assert all(obs[name].shape == (4, *space.shape) for name, space in env.observation_space.spaces.items())
    else:
        assert all(o.shape == (4, *space.shape) for o, space in zip(obs, env.observation_space.spaces))


# ------------------------------------------------------------------------ resets
@pytest.mark.parametrize("index", [3, [0, 5, 6], "mask"], ids=["int", "list", "mask"])
def test_reset_at_touches_exactly_those_envs(index):
    env = _make()
    env.step(env.get_random_actions())
    if index == "mask":
        index = torch.arange(BATCH) % 3 == 1
    chosen = torch.zeros(BATCH, dtype=torch.bool)
    chosen[index] = True
    before = _state(env)
    env.reset_at(index)
    after = _state(env)
    assert torch.equal(after[~chosen], before[~chosen])
    moved = (after[chosen, :-1] != before[chosen, :-1]).all(dim=-1)
    assert moved.all()
    agent_vel = torch.stack([a.state.vel for a in env.agents], dim=1)
    assert (agent_vel[chosen] == 0).all() and (agent_vel[~chosen] != 0).any()
    colors = torch.stack([l.color for l in env.world.landmarks], dim=1)  # [B, L, 3]
    green = colors[..., 1] > colors[..., 0]  # [B, L]
    assert (green.sum(-1) == 1).all() and torch.equal(green.float().argmax(-1), env.scenario.goal)


def test_goal_is_drawn_per_env():
    env = _make(num_envs=64)
    assert len(env.scenario.goal.unique()) == 2
    assert env.scenario.goal.min() >= 0 and env.scenario.goal.max() < len(env.world.landmarks)


@pytest.mark.parametrize("policy", ["random", "heuristic"])
def test_long_rollouts_stay_finite(policy):
    env = _make(n_agents=4, n_adversaries=1)
    heuristic = scenario.HeuristicPolicy()
    obs = env.reset()
    for _ in range(200):
        actions = env.get_random_actions() if policy == "random" else [heuristic.compute_action(o, 1.0) for o in obs]
        obs, rews, _, _ = env.step(actions)
        assert all(torch.isfinite(t).all() for t in obs + rews)


# ------------------------------------------------------------------------ parity
@pytest.mark.parametrize("kwargs", KWARGS)
def test_parity_with_upstream_vmas(kwargs):
    up = vmas.make_env(NAME, num_envs=BATCH, device="cpu", seed=0, **kwargs)
    env = _make(**kwargs)
    for e_up, e_ours in zip(up.world.entities, env.world.entities):
        for field in FIELDS:
            getattr(e_ours, f"set_{field}")(getattr(e_up.state, field).clone(), batch_index=None)
    # upstream keeps one goal Landmark for the whole batch on every agent (agent.goal);
    # ours keeps a landmark index per env, so every env gets upstream's goal
    env.scenario.goal[:] = up.world.landmarks.index(up.world.agents[0].goal)
    gen = torch.Generator().manual_seed(7)
    for step in range(50):
        actions = [torch.rand(BATCH, 2, generator=gen) * 2 - 1 for _ in up.agents]
        obs_up, rew_up, _, _ = up.step([a.clone() for a in actions])
        obs, rew, _, _ = env.step(actions)
        for e_up, e_ours in zip(up.world.entities, env.world.entities):
            for field in FIELDS:
                torch.testing.assert_close(getattr(e_ours.state, field), getattr(e_up.state, field), atol=1e-4, rtol=0)
        for mine, theirs in zip(obs + rew, obs_up + rew_up):
            torch.testing.assert_close(mine, theirs, atol=1e-4, rtol=0, msg=lambda m: f"step {step}: {m}")


# --------------------------------------------------------------- MPE semantics
def test_rewards_and_observations_match_mpe():
    """Same positions and goal in MPE's simple_adversary_v3 (N=2): identical rewards and observations.

    MPE integrates differently (explicit Euler, action sensitivity 5), so
    every case starts at rest and takes a zero physical action: nothing moves
    and both simulators score the state we set.
    """
    from mpe2 import simple_adversary_v3

    cases = 12
    env = _make(num_envs=cases, seed=5)
    obs, rew, _, _ = env.step([torch.zeros(cases, 2) for _ in env.agents])
    mpe = simple_adversary_v3.parallel_env(N=2, continuous_actions=True, max_cycles=1000)
    mpe.reset(seed=0)
    world = mpe.unwrapped.world
    assert [a.name for a in world.agents] == [a.name for a in env.agents]
    for k in range(cases):
        for e_mpe, e_ours in zip(world.agents + world.landmarks, env.world.agents + env.world.landmarks):
            e_mpe.state.p_pos = e_ours.state.pos[k].double().numpy().copy()
            e_mpe.state.p_vel = np.zeros(2)
        for agent in world.agents:
            agent.goal_a = world.landmarks[int(env.scenario.goal[k])]
        obs_mpe, rew_mpe, *_ = mpe.step({name: np.zeros(5, dtype=np.float32) for name in mpe.agents})
        for i, agent in enumerate(env.agents):
            assert rew_mpe[agent.name] == pytest.approx(float(rew[i][k]), abs=1e-5)
            np.testing.assert_allclose(obs_mpe[agent.name], obs[i][k].numpy(), atol=1e-5)


# -------------------------------------------------------------------- heuristic
def _team_returns(good_heuristic: bool, adversary_heuristic: bool, num_envs=64, steps=100):
    env = _make(num_envs=num_envs, seed=1)
    policy = scenario.HeuristicPolicy()
    obs = env.reset()
    total = torch.zeros(env.n_agents)
    for _ in range(steps):
        random_actions = env.get_random_actions()
        actions = [
            policy.compute_action(o, 1.0) if (adversary_heuristic if a.adversary else good_heuristic) else r
            for a, o, r in zip(env.agents, obs, random_actions)
        ]
        obs, rews, _, _ = env.step(actions)
        total += torch.stack(rews, dim=1).mean(dim=0)
    return float(total[0]), float(total[1])  # adversary, good team


def test_heuristic_beats_random():
    """Each team's heuristic against random play, the other team random in both runs.

    Measured (64 envs x 100 steps, seed 1): good team +26 random vs +92
    heuristic (it parks on the goal at once instead of wandering ~0.7 from
    it); adversary -102 random vs -53 heuristic (a coin flip between
    landmarks leaves it ~0.5 from the goal instead of ~1). Per-env returns
    have a std of 45-60, a standard error of 6-8 for a 64-env mean, and the
    runs share their seed, so the asserted margins (40 and 15) stay clear of
    the noise while sitting well inside the measured gaps (66 and 49).
    """
    adv_random, good_random = _team_returns(False, False)
    _, good_heuristic = _team_returns(True, False)
    adv_heuristic, _ = _team_returns(False, True)
    assert good_heuristic > good_random + 40
    assert adv_heuristic > adv_random + 15
