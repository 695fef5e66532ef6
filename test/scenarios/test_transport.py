"""``transport``: API, parity with VMAS 1.5.2, spawning, no tunnelling, heuristic.

Oracle: ``vmas`` (same kwargs -> same world and spaces; same start -> same
obs, rewards, dones and states, also while packages reach the goal).
"""
from __future__ import annotations

import pytest
import torch

from test.scenarios import harness
from test.scenarios.harness import ACTION_MODES
from vmas_ros.testing import vmas_states
from vmas_ros.testing.parity import run_lockstep
from vmas_ros.bench.heuristics import episode_returns
from vmas_ros.scenarios import transport
from vmas_ros.simulator.heuristic_policy import RandomPolicy

NAME = "transport"
BATCH = 8
#: a small team's worth of everything else non-default
CUSTOM = {"n_agents": 3, "n_packages": 2, "package_width": 0.1, "package_length": 0.2, "package_mass": 2.0}


def make(num_envs: int = BATCH, **kwargs):
    return harness.make(transport.Scenario(), num_envs, **kwargs)


def penetration(env) -> torch.Tensor:
    """How deep each agent reaches into each package, [B, N, P] (<= 0: apart).

    The agent's radius minus the signed distance from its centre to the box
    (negative inside); packages never rotate, so the boxes are axis-aligned.
    """
    agents = torch.stack([a.state.pos for a in env.agents], dim=1)  # [B, N, 2]
    packages = env.scenario.packages
    centres = torch.stack([p.state.pos for p in packages], dim=1)  # [B, P, 2]
    half = torch.tensor([[p.shape.length / 2, p.shape.width / 2] for p in packages])  # [P, 2]
    excess = (agents.unsqueeze(2) - centres.unsqueeze(1)).abs() - half  # [B, N, P, 2]
    signed = excess.clamp_min(0).norm(dim=-1) + excess.amax(dim=-1).clamp_max(0)
    return transport.AGENT_RADIUS - signed


def package_distances(env) -> torch.Tensor:
    packages = torch.stack([p.state.pos for p in env.scenario.packages], dim=1)
    return (packages - env.scenario.goal.state.pos.unsqueeze(1)).norm(dim=-1)  # [B, P]


# ------------------------------------------------------------------- construction
@pytest.mark.parametrize("kwargs", [{}, CUSTOM], ids=["default", "custom"])
def test_world_matches_upstream(kwargs):
    """Entities (names, order, shapes, masses, flags), agents' actuation and world parameters."""
    ours, up = make(2, **kwargs).world, harness.make_upstream(NAME, 2, **kwargs).world
    n_agents, n_packages = kwargs.get("n_agents", 4), kwargs.get("n_packages", 1)
    assert [e.name for e in ours.entities] == (
        ["goal"] + [f"package {i}" for i in range(n_packages)] + [f"agent_{i}" for i in range(n_agents)]
    )
    assert [e.name for e in ours.entities] == [e.name for e in up.entities]
    for e_ours, e_up in zip(ours.entities, up.entities):
        assert type(e_ours.shape).__name__ == type(e_up.shape).__name__, e_ours.name
        for attr in ("radius", "length", "width", "hollow"):
            assert getattr(e_ours.shape, attr, None) == pytest.approx(getattr(e_up.shape, attr, None)), e_ours.name
        for attr in ("mass", "movable", "rotatable", "collide"):
            assert getattr(e_ours, attr) == getattr(e_up, attr), (e_ours.name, attr)
    for a_ours, a_up in zip(ours.agents, up.agents):
        assert a_ours.action.u_multiplier == a_up.action.u_multiplier == 0.6
        assert a_ours.action.u_range == a_up.action.u_range
    for attr in ("dt", "substeps", "drag", "collision_force", "contact_margin", "x_semidim", "y_semidim"):
        assert getattr(ours, attr) == pytest.approx(getattr(up, f"_{attr}")), attr  # VMAS keeps them private
    assert ours.x_semidim == pytest.approx(1 + 0.06 + max(kwargs.get("package_length", 0.15), kwargs.get("package_width", 0.15)))


def test_unknown_kwargs_warn():
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(2, not_a_kwarg=1)


@pytest.mark.parametrize("name, value", [
    ("n_agents", 0), ("n_packages", 1.5), ("package_width", -0.1), ("package_length", True),
    ("package_mass", 0), ("package_mass", float("nan")),
])
def test_bad_kwargs_raise(name, value):
    with pytest.raises(ValueError, match=name):
        make(2, **{name: value})


def test_impossible_spawn_raises():
    """A package too large for two things to keep its spawn gap in [-1, 1]^2 is refused, not looped on."""
    with pytest.raises(ValueError, match="too crowded"):
        make(2, package_width=6.0)


# ------------------------------------------------------------------------- spaces
@pytest.mark.parametrize("dict_spaces", [False, True])
@pytest.mark.parametrize("mode", list(ACTION_MODES))
def test_spaces_match_upstream_and_actions_work(mode, dict_spaces):
    options = dict(ACTION_MODES[mode], dict_spaces=dict_spaces, n_packages=2)
    obs, _ = harness.check_spaces(make(4, **options), harness.make_upstream(NAME, 4, **options), steps=3)
    values = list(obs.values()) if dict_spaces else obs
    assert [tuple(v.shape) for v in values] == [(4, 4 + 7 * 2)] * 4


# -------------------------------------------------------------------------- reset
def scenario_state(env):
    return {"potential": env.scenario.potential, "on_goal": env.scenario.on_goal}


@pytest.mark.parametrize("index", [3, [1, 4], "mask"])
def test_reset_at_resets_exactly_those_envs(index):
    env = make(16, n_packages=2)
    policy = transport.HeuristicPolicy()
    for _ in range(10):  # move packages, so that the potentials differ from a fresh draw
        env.step([policy.compute_action(o, 1.0) for o in env.get_from_scenario(True, False, False, False)[0]])
    check = harness.check_reset_at(env, index, mask_rows=slice(None, None, 3), scenario_state=scenario_state, bound=1.0)
    chosen = check.chosen
    torch.testing.assert_close(env.scenario.potential[chosen], 100 * package_distances(env)[chosen])
    assert not env.scenario.on_goal[chosen].any()


def test_spawn_keeps_its_gaps():
    """Agents 0.06 apart; goal and packages (half-diagonal + 0.16) from agents and from each other."""
    env = make(256, n_agents=6, n_packages=3)
    agents = torch.stack([a.state.pos for a in env.agents], dim=1)
    others = torch.stack([env.scenario.goal.state.pos] + [p.state.pos for p in env.scenario.packages], dim=1)
    gap = env.scenario.packages[0].shape.circumscribed_radius() + 0.16
    off_diagonal = ~torch.eye(6, dtype=torch.bool)
    assert (torch.cdist(agents, agents)[:, off_diagonal] >= 0.06).all()
    assert (torch.cdist(others, agents) >= gap).all()
    assert (torch.cdist(others, others)[:, ~torch.eye(4, dtype=torch.bool)] >= gap).all()
    assert (torch.cat([agents, others], dim=1).abs() <= 1.0).all()
    assert not env.done().any() and (penetration(env) < 0).all()


# ------------------------------------------------------------------------- parity
def test_matches_upstream_vmas_random_actions():
    up, ours = harness.make_upstream(NAME, BATCH), make()
    harness.copy_start(up, ours, vmas_states.transport)
    run_lockstep(up, ours, seed=0)


def test_matches_upstream_vmas_while_delivering():
    """Light packages pushed by the heuristic (plus noise): contacts, rewards and arrivals all compared.

    Dones are compared before every step; the run must see packages arrive
    (so the on-goal masking of the reward and the observation flag are
    exercised) and rewards paid.
    """
    kwargs = dict(CUSTOM, package_mass=0.5)
    up, ours = harness.make_upstream(NAME, BATCH, **kwargs), make(**kwargs)
    harness.copy_start(up, ours, vmas_states.transport)
    policy = transport.HeuristicPolicy(package_width=0.1, package_length=0.2)
    arrived = torch.zeros(BATCH, 2, dtype=torch.bool)

    def actions(gen: torch.Generator):
        assert torch.equal(up.done(), ours.done())
        arrived.logical_or_(ours.scenario.on_goal)
        noisy = []
        for agent in ours.agents:
            noise = (torch.rand(BATCH, 2, generator=gen) * 2 - 1) * 0.3
            noisy.append((policy.compute_action(ours.scenario.observation(agent), 1.0) + noise).clamp(-1, 1))
        return noisy

    seen = run_lockstep(up, ours, seed=1, actions=actions, steps=60)
    assert arrived.any() and seen.largest_reward > 0.5, (arrived, seen)


# ---------------------------------------------------------------------- rollouts
def test_long_rollouts_stay_finite_and_nothing_tunnels():
    """200 steps with two packages, half the envs random, half heuristic (with light packages).

    Every value stays finite, packages never rotate, everything stays inside
    the walls, and no agent's centre ever gets inside a package (the deepest
    measured contact is ~0.02 with agents queued behind each other, against
    a radius of 0.03).
    """
    torch.manual_seed(0)
    env = make(8, n_packages=2, package_mass=5.0)
    heuristic, random = transport.HeuristicPolicy().compute_action, RandomPolicy().compute_action
    obs = env.reset()
    deepest, wall = 0.0, env.world.x_semidim
    for _ in range(200):
        actions = [torch.cat([random(o[:4], 1.0), heuristic(o[4:], 1.0)]) for o in obs]
        obs, rews, _, _ = env.step(actions)
        assert all(torch.isfinite(v).all() for v in obs + rews)
        deepest = max(deepest, float(penetration(env).max()))
        for e in env.world.entities:
            assert torch.isfinite(e.state.pos).all() and (e.state.pos.abs() <= wall + 1e-6).all(), e.name
        assert all((p.state.rot == 0).all() for p in env.scenario.packages)
    assert 0.0 < deepest < transport.AGENT_RADIUS, deepest  # agents did touch the packages, never crossed into them


# ---------------------------------------------------------------------- heuristic
def test_heuristic_goes_round_not_through():
    """Package at the origin, goal to its right: an agent on the goal side circles round; one behind pushes."""
    env = make(3)
    env.scenario.goal.set_pos(torch.tensor([0.8, 0.0]), batch_index=None)
    env.scenario.packages[0].set_pos(torch.tensor([0.0, 0.0]), batch_index=None)
    env.agents[0].set_pos(torch.tensor([[0.3, 0.001], [-0.3, 0.02], [0.0, 0.4]]), batch_index=None)
    policy = transport.HeuristicPolicy()
    action = policy.compute_action(env.scenario.observation(env.agents[0]), 1.0)
    me = env.agents[0].state.pos
    heading = action / action.norm(dim=-1, keepdim=True)
    miss = (me[:, 0] * heading[:, 1] - me[:, 1] * heading[:, 0]).abs()  # the box centre's distance to the heading line
    reach = env.scenario.packages[0].shape.circumscribed_radius() + transport.AGENT_RADIUS
    assert action[0, 0] < 0 and action[0, 1] > 0 and miss[0] > reach  # in front: round the top, clear of the box
    assert action[1, 0] > 0.95  # behind: push towards the goal
    assert action[2, 0] < 0 and miss[2] > reach  # above: back and round, clear of the box
    assert (action.norm(dim=-1) <= 1 + 1e-6).all()
    delivered = env.scenario.observation(env.agents[0]).clone()
    delivered[:, 10] = 1.0
    assert (policy.compute_action(delivered, 1.0) == 0).all()  # nothing left to do
    with pytest.raises(ValueError, match="width"):
        policy.compute_action(torch.zeros(1, 12), 1.0)


def run(env, policy, steps: int):
    """Mean (shared) return per env and which envs finished, every agent playing ``policy``."""
    returns, _, finished = episode_returns(env, policy, steps)
    return float(returns[0].mean()), finished


def test_heuristic_delivers_packages():
    """32 envs, 250 steps, seed 0, packages of mass 5 (a default one weighs 50: four agents push it at
    under 2 cm/s, ~1000 steps for an average trip, see the next test).

    Measured: the heuristic delivers in ~97% of the envs (return ~82 = 0.8 m of
    progress per env); random play in none (return ~0.1). Require 75%.
    """
    torch.manual_seed(0)
    heuristic, random = transport.HeuristicPolicy(), RandomPolicy()
    returns, finished = zip(*(run(make(32, package_mass=5.0), p, 250) for p in (heuristic, random)))
    assert finished[0].float().mean() >= 0.75, finished[0]
    assert finished[1].float().mean() <= 0.1 and returns[0] > returns[1] + 50, (returns, finished[1])


def test_heuristic_moves_default_packages():
    """Default kwargs, 16 envs, 150 steps, seed 0: the heavy package moves steadily towards the goal.

    Measured returns: heuristic ~10 (10 cm of progress; the envs that spawned
    near the goal finish), random ~0. Require 6.
    """
    torch.manual_seed(0)
    heuristic, random = transport.HeuristicPolicy(), RandomPolicy()
    (h_return, _), (r_return, _) = (run(make(16), p, 150) for p in (heuristic, random))
    assert h_return > 6 and abs(r_return) < 2, (h_return, r_return)


def test_cached_observations_follow_the_state_and_never_alias():
    """Observations are built once per state for all agents: moving the package (a set_pos, no step)
    shows in the next collection, each agent's offset is its own, and a second collection of the same
    state is a different tensor (handed out without the env's copy)."""
    env = make(3, n_packages=2)
    env.reset()
    first = env.get_from_scenario(True, False, False, False)[0]
    again = env.get_from_scenario(True, False, False, False)[0]
    assert all(torch.equal(a, b) and a.data_ptr() != b.data_ptr() for a, b in zip(first, again))
    package = env.scenario.packages[1]
    package.set_pos(package.state.pos + 0.25, batch_index=None)
    moved = env.get_from_scenario(True, False, False, False)[0]
    block = transport.OWN_BLOCK + transport.PACKAGE_BLOCK  # the second package's block
    for agent, obs in zip(env.agents, moved):
        expected = torch.cat([package.state.pos - env.scenario.goal.state.pos, package.state.pos - agent.state.pos], -1)
        torch.testing.assert_close(obs[:, block : block + 4], expected, rtol=0, atol=0)
    assert not torch.equal(moved[0], first[0])


def test_observation_columns_compiled_and_eager_agree():
    """The observation layout (layout.cat_columns) gives the same bits eagerly and under torch.compile,
    where it is one concatenation."""
    from vmas_ros.scenarios import transport

    gen = torch.Generator().manual_seed(1)
    for n_packages in (1, 3):
        pos, vel = torch.randn(2 + n_packages + 3, 50, 2, generator=gen), torch.randn(2 + n_packages + 3, 50, 2, generator=gen)
        on_goal = torch.rand(50, n_packages, generator=gen) > 0.5
        eager = transport.observations(pos, vel, on_goal, n_packages)
        compiled = torch.compile(transport.observations, fullgraph=True, dynamic=False)(pos, vel, on_goal, n_packages)
        assert torch.equal(eager, compiled)
