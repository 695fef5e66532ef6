"""simple_crypto: construction, spaces, resets, parity with VMAS 1.5.2, semantics of MPE, heuristic.

The secret and key are scenario state (``Scenario.secret``/``.key``, per env);
upstream keeps them on the agents (``agent.secret``, the speaker's
``agent.key``) as long tensors. Parity tests copy them over.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

import vmas
import vmas_ros
from vmas_ros.scenarios.mpe import simple_crypto as scenario

NAME = "simple_crypto"
BATCH = 16
FIELDS = ("pos", "vel", "rot", "ang_vel")
KWARGS = [{}, {"dim_c": 6}]


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


def _messages(num_envs: int, dim_c: int, gen: torch.Generator) -> torch.Tensor:
    """Continuous actions: zero physical part, random messages, all-zero (silent) in about a third of envs."""
    speak = (torch.rand(num_envs, 1, generator=gen) > 0.3).float()
    return torch.cat([torch.zeros(num_envs, 2), torch.rand(num_envs, dim_c, generator=gen) * speak], dim=-1)


# ------------------------------------------------------------------ construction
def test_default_world_matches_upstream_facts():
    env, up = _make(), vmas.make_env(NAME, num_envs=2, seed=0)
    assert [a.name for a in env.agents] == [a.name for a in up.agents] == ["eve_0", "bob_0", "alice_0"]
    assert [a.adversary for a in env.agents] == [a.adversary for a in up.agents]
    assert [a.speaker for a in env.agents] == [a.speaker for a in up.agents]
    assert not env.world.landmarks and env.world.dim_c == 4
    assert not any(a.silent or a.movable or a.collide for a in env.agents)
    assert env.scenario.secret.shape == env.scenario.key.shape == (BATCH, 4)


def test_kwargs_and_validation():
    env = _make(dim_c=6)
    assert env.world.dim_c == 6 and env.scenario.secret.shape == (BATCH, 6)
    with pytest.warns(UserWarning, match="bogus"):
        _make(bogus=1)
    for bad in (0, -1, 2.0, True):
        with pytest.raises(ValueError, match="dim_c"):
            _make(dim_c=bad)


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
    if not env.continuous_actions:  # a discrete message is one-hot
        said = torch.stack([a.state.c for a in env.agents])
        assert ((said == 0) | (said == 1)).all() and (said.sum(-1) == 1).all()


# ------------------------------------------------------------------------ resets
@pytest.mark.parametrize("index", [3, [0, 5, 6], "mask"], ids=["int", "list", "mask"])
def test_reset_at_touches_exactly_those_envs(index):
    env = _make()
    env.step([_messages(BATCH, 4, torch.Generator().manual_seed(0)).clamp_min(0.1) for _ in env.agents])
    if index == "mask":
        index = torch.arange(BATCH) % 3 == 1
    chosen = torch.zeros(BATCH, dtype=torch.bool)
    chosen[index] = True

    def snapshot():
        pos = torch.stack([a.state.pos for a in env.agents], dim=1).flatten(1)
        said = torch.stack([a.state.c for a in env.agents], dim=1).flatten(1)
        return pos, torch.cat([env.scenario.secret, env.scenario.key, said], dim=-1)

    pos_before, rest_before = snapshot()
    env.reset_at(index)
    pos_after, rest_after = snapshot()
    assert torch.equal(pos_after[~chosen], pos_before[~chosen])
    assert torch.equal(rest_after[~chosen], rest_before[~chosen])
    assert (pos_after[chosen] != pos_before[chosen]).all()
    said = rest_after[:, 8:]
    assert (said[chosen] == 0).all() and (said[~chosen] != 0).all()  # messages cleared by the reset


def test_secret_and_key_are_random_bits_per_env():
    env = _make(num_envs=256)
    for bits in (env.scenario.secret, env.scenario.key):
        assert ((bits == 0) | (bits == 1)).all()
        assert 0.4 < float(bits.mean()) < 0.6 and len(bits.unique(dim=0)) == 16
    assert not torch.equal(env.scenario.secret, env.scenario.key)


@pytest.mark.parametrize("policy", ["random", "heuristic"])
def test_long_rollouts_stay_finite(policy):
    env = _make()
    heuristic = scenario.HeuristicPolicy()
    obs = env.reset()
    for _ in range(200):
        actions = env.get_random_actions() if policy == "random" else [heuristic.compute_action(o, 1.0) for o in obs]
        obs, rews, _, _ = env.step(actions)
        assert all(torch.isfinite(t).all() for t in obs + rews)


# ------------------------------------------------------------------------ parity
@pytest.mark.parametrize("kwargs", KWARGS)
@pytest.mark.parametrize("continuous", [True, False], ids=["continuous", "discrete"])
def test_parity_with_upstream_vmas(kwargs, continuous):
    up = vmas.make_env(NAME, num_envs=BATCH, device="cpu", seed=0, continuous_actions=continuous, **kwargs)
    env = _make(continuous_actions=continuous, **kwargs)
    for e_up, e_ours in zip(up.world.entities, env.world.entities):
        for field in FIELDS:
            getattr(e_ours, f"set_{field}")(getattr(e_up.state, field).clone(), batch_index=None)
    # upstream: one shared long tensor agent.secret on every agent, the key on the speaker (agents[2])
    env.scenario.secret[:] = up.world.agents[0].secret.float()
    env.scenario.key[:] = up.world.agents[2].key.float()
    dim_c = env.world.dim_c
    gen = torch.Generator().manual_seed(11)
    for step in range(50):
        if continuous:  # random physical part (ignored: agents are immovable) and messages, some silent
            actions = [_messages(BATCH, dim_c, gen) for _ in up.agents]
            for action in actions:
                action[:, :2] = torch.rand(BATCH, 2, generator=gen) * 2 - 1
        else:
            actions = [torch.randint(0, 9 * dim_c, (BATCH, 1), generator=gen) for _ in up.agents]
        obs_up, rew_up, _, _ = up.step([a.clone() for a in actions])
        obs, rew, _, _ = env.step(actions)
        for a_up, a_ours in zip(up.agents, env.agents):
            torch.testing.assert_close(a_ours.state.c, a_up.state.c, atol=1e-6, rtol=0)
            for field in FIELDS:
                torch.testing.assert_close(getattr(a_ours.state, field), getattr(a_up.state, field), atol=1e-4, rtol=0)
        for mine, theirs in zip(obs + rew, obs_up + rew_up):
            torch.testing.assert_close(mine, theirs.float(), atol=1e-4, rtol=0, msg=lambda m: f"step {step}: {m}")


# --------------------------------------------------------------- MPE semantics
def test_rewards_and_observations_match_mpe():
    """Same secret, key and messages in MPE's simple_crypto_v3: identical rewards and observations.

    MPE's secret is the colour of a goal landmark (one-hot) and the key the
    colour of a random landmark; ours are VMAS's random bit vectors. MPE's
    formulas do not care, so we give MPE our bit vectors (as the goal
    landmark's colour and the speaker's key). Silent (all-zero) messages are
    included to check that both leave them unscored.
    """
    from mpe2 import simple_crypto_v3

    cases = 12
    env = _make(num_envs=cases, seed=5)
    gen = torch.Generator().manual_seed(2)
    actions = [_messages(cases, 4, gen) for _ in env.agents]
    obs, rew, _, _ = env.step(actions)
    mpe = simple_crypto_v3.parallel_env(continuous_actions=True, max_cycles=1000)
    mpe.reset(seed=0)
    world = mpe.unwrapped.world
    assert [a.name for a in world.agents] == [a.name for a in env.agents]
    for k in range(cases):
        world.landmarks[0].color = env.scenario.secret[k].double().numpy().copy()
        for agent in world.agents:
            agent.goal_a = world.landmarks[0]
        world.agents[2].key = env.scenario.key[k].double().numpy().copy()
        messages = {a.name: act[k, 2:].numpy() for a, act in zip(env.agents, actions)}
        obs_mpe, rew_mpe, *_ = mpe.step(messages)
        for i, agent in enumerate(env.agents):
            assert rew_mpe[agent.name] == pytest.approx(float(rew[i][k]), abs=1e-5)
            np.testing.assert_allclose(obs_mpe[agent.name], obs[i][k].numpy(), atol=1e-6)
    assert any(float(r.abs().min()) == 0 for r in rew)  # some silent listener left unscored


# -------------------------------------------------------------------- heuristic
@pytest.mark.parametrize("dim_c", [4, 6])
def test_heuristic_bob_decodes_and_eve_guesses_half(dim_c):
    env = _make(num_envs=64, dim_c=dim_c)
    policy = scenario.HeuristicPolicy()
    policy.dim_c = dim_c
    obs = env.reset()
    for _ in range(3):
        obs, rew, _, _ = env.step([policy.compute_action(o, 1.0) for o in obs])
    torch.testing.assert_close(env.agents[1].state.c, env.scenario.secret)
    torch.testing.assert_close(rew[0], torch.full((64,), -dim_c / 4))
    torch.testing.assert_close(rew[1], torch.full((64,), dim_c / 4))


def _returns(good_heuristic: bool, eve_heuristic: bool, num_envs=64, steps=100):
    env = _make(num_envs=num_envs, seed=1)
    policy = scenario.HeuristicPolicy()
    obs = env.reset()
    total = torch.zeros(env.n_agents)
    for _ in range(steps):
        random_actions = env.get_random_actions()
        actions = [
            policy.compute_action(o, 1.0) if (eve_heuristic if a.adversary else good_heuristic) else r
            for a, o, r in zip(env.agents, obs, random_actions)
        ]
        obs, rews, _, _ = env.step(actions)
        total += torch.stack(rews, dim=1).mean(dim=0)
    return float(total[0]), float(total[1])  # Eve, Alice and Bob


def test_heuristic_beats_random():
    """Each side's heuristic against random messages, the other side random in both runs.

    Expected per step with dim_c = 4: a uniform random guess of a bit costs
    1/3, the 0.5 guess 1/4, an exact decode 0. So Alice and Bob go from about
    0 (Bob's and Eve's random errors cancel) to about +4/3 per step (Bob exact
    from the second step, Eve random), and Eve from -4/3 to exactly -1.
    Measured (64 envs x 100 steps, seed 1): Alice/Bob -0.3 random vs +131.9
    heuristic, Eve -133.7 random vs -100.0 heuristic. Per-env returns have a
    std below 9 (standard error of the mean ~1), so the asserted margins of
    100 and 20 are far outside the noise.
    """
    eve_random, good_random = _returns(False, False)
    _, good_heuristic = _returns(True, False)
    eve_heuristic, _ = _returns(False, True)
    assert good_heuristic > good_random + 100
    assert eve_heuristic > eve_random + 20
