"""Shared machinery of the MPE scenario tests (``test/scenarios/test_mpe_*.py``).

Each scenario is checked the same ways against the same oracles; this module
holds the one copy of every check they share, and each test file keeps only
what is specific to its scenario (which kwargs, which per-env scenario state,
which bounds, which measured returns).

* building envs: ``make`` (ours) and ``make_upstream`` (VMAS 1.5.2, the oracle);
* spaces: ``assert_same_space`` and ``check_spaces`` (spaces equal to
  upstream's, then a short random rollout that must stay finite and fit them);
* parity with upstream: ``copy_start`` (upstream's start, and its per-env
  scenario state, into ours) then ``test.simulator.parity.run_lockstep`` (the
  same lock-step loop and state comparison the engine parity tests use);
* resets: ``check_reset_at`` (exactly the selected envs are redrawn);
* semantics against MPE (mpe2): ``make_mpe`` and ``copy_env_to_mpe``;
* policies: ``play_lineups`` (rollouts with per-agent policies, every value
  finite) and ``team_returns`` (heuristic against random returns).
"""
from __future__ import annotations

import warnings
from typing import Callable, Dict, List, NamedTuple, Optional, Sequence, Union

import numpy as np
import torch
import vmas

import vmas_ros
from test.simulator import parity

#: a function of an env giving named per-env tensors ([B, ...]) of scenario state
StateFn = Callable[[object], Dict[str, torch.Tensor]]
#: a policy as ``play_lineups`` calls it: ``(obs [b, obs size], u_range) -> action [b, action size]``
Policy = Callable[[torch.Tensor, float], torch.Tensor]

#: the action layouts an env can be built with, as ``make_env`` kwargs (continuous, the default, spelt out)
ACTION_MODES = {
    "continuous": dict(continuous_actions=True),
    "discrete": dict(continuous_actions=False),
    "multidiscrete": dict(continuous_actions=False, multidiscrete_actions=True),
}
#: the action layouts (continuous left to the default) and the dict layout of observations and actions
SPACE_MODES = {
    "continuous": dict(),
    "discrete": ACTION_MODES["discrete"],
    "multidiscrete": ACTION_MODES["multidiscrete"],
    "dict": dict(dict_spaces=True),
}


# ------------------------------------------------------------------------ envs
def make(scenario, num_envs: int, seed: int = 0, **kwargs):
    """Our env for ``scenario`` (a ``Scenario`` instance or a registered name), on the CPU."""
    return vmas_ros.make_env(scenario, num_envs=num_envs, device="cpu", seed=seed, **kwargs)


def make_upstream(name: str, num_envs: int, seed: int = 0, **kwargs):
    """Upstream VMAS's env for the scenario ``name``, on the CPU; its warnings are muted (not ours to check)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return vmas.make_env(name, num_envs=num_envs, device="cpu", seed=seed, **kwargs)


# ---------------------------------------------------------------------- spaces
def assert_same_space(ours, up, where: str = "space") -> None:
    """Structural equality of a gymnasium space (ours) and a gym space (VMAS).

    Same class name at every level; Dict: same keys in the same order; Tuple:
    same length; MultiDiscrete: same ``nvec``; Discrete: same ``n``; Box: same
    shape, dtype and bounds.
    """
    assert type(ours).__name__ == type(up).__name__, f"{where}: {ours} vs {up}"
    if isinstance(up.spaces if hasattr(up, "spaces") else None, dict):
        assert list(ours.spaces) == list(up.spaces), where
        for key in up.spaces:
            assert_same_space(ours.spaces[key], up.spaces[key], f"{where}[{key}]")
    elif hasattr(up, "spaces"):
        assert len(ours.spaces) == len(up.spaces), where
        for i, (o, u) in enumerate(zip(ours.spaces, up.spaces)):
            assert_same_space(o, u, f"{where}[{i}]")
    elif hasattr(up, "nvec"):
        np.testing.assert_array_equal(ours.nvec, up.nvec)
    elif hasattr(up, "n"):
        assert int(ours.n) == int(up.n), where
    else:
        assert ours.shape == up.shape and ours.dtype == up.dtype, f"{where}: {ours} vs {up}"
        np.testing.assert_array_equal(ours.low, up.low)
        np.testing.assert_array_equal(ours.high, up.high)


def space_actions(env, gen: torch.Generator) -> List[torch.Tensor]:
    """Uniform actions inside each agent's action space (so messages in [0, 1]), drawn from ``gen``."""
    actions = []
    for space in (env.get_agent_action_space(a) for a in env.agents):
        kind = type(space).__name__
        if kind == "Box":
            low, high = torch.tensor(space.low), torch.tensor(space.high)
            actions.append(low + (high - low) * torch.rand(env.num_envs, len(low), generator=gen))
        elif kind == "Discrete":
            actions.append(torch.randint(int(space.n), (env.num_envs, 1), generator=gen))
        else:
            nvec = torch.tensor(space.nvec)
            actions.append((torch.rand(env.num_envs, len(nvec), generator=gen) * nvec).long())
    return actions


def random_steps(env, steps: int, gen: Optional[torch.Generator] = None, as_dict: bool = False):
    """Step ``env`` ``steps`` times at random; every observation and reward must stay finite.

    Actions are ``space_actions(env, gen)`` when ``gen`` is given, else
    ``env.get_random_actions()``; with ``as_dict`` they are passed as
    ``{agent name: action}``. Returns the last ``(obs, rews)``.
    """
    for _ in range(steps):
        actions = env.get_random_actions() if gen is None else space_actions(env, gen)
        if as_dict:
            actions = {a.name: act for a, act in zip(env.agents, actions, strict=True)}
        obs, rews, _, _ = env.step(actions)
        values = list(obs.values()) + list(rews.values()) if isinstance(obs, dict) else obs + rews
        assert all(torch.isfinite(v).all() for v in values)
    return obs, rews


def check_spaces(ours, up, steps: int, gen: Optional[torch.Generator] = None, as_dict: bool = False):
    """Our observation and action spaces equal upstream's; then ``steps`` random steps work.

    The steps are ``random_steps(ours, steps, gen, as_dict)`` (every value
    finite); after the last, each observation must have the shape of its
    space (with the batch dimension first). Returns the last ``(obs, rews)``
    for scenario-specific checks.
    """
    assert_same_space(ours.observation_space, up.observation_space, "observation_space")
    assert_same_space(ours.action_space, up.action_space, "action_space")
    obs, rews = random_steps(ours, steps, gen, as_dict)
    spaces = ours.observation_space.spaces
    if isinstance(obs, dict):
        assert {k: tuple(o.shape) for k, o in obs.items()} == {k: (ours.num_envs, *s.shape) for k, s in spaces.items()}
    else:
        assert [tuple(o.shape) for o in obs] == [(ours.num_envs, *s.shape) for s in spaces]
    return obs, rews


# ---------------------------------------------------------------------- parity
def copy_start(up, ours, scenario_state: Optional[Callable[[object, object], None]] = None) -> None:
    """Start ours where upstream's reset left it, so that ``parity.run_lockstep`` can compare them.

    Every entity's pos, vel, rot and ang_vel are copied (``parity.copy_state``).
    Scenarios that also draw per-env state at reset (goals, secrets, ...) pass
    ``scenario_state(up, ours)``, which writes upstream's draw into ours.
    """
    parity.copy_state(up, ours)
    if scenario_state is not None:
        scenario_state(up, ours)


# ---------------------------------------------------------------------- resets
class ResetCheck(NamedTuple):
    """What ``check_reset_at`` saw, for the scenario-specific checks that follow it."""

    chosen: torch.Tensor  # [B] bool, the envs that were reset
    before: Dict[str, torch.Tensor]  # snapshot before the reset (entity ``name.pos``/``name.vel``, scenario state)
    after: Dict[str, torch.Tensor]  # the same snapshot after it
    obs: object  # what ``reset_at`` returned


def _snapshot(env, scenario_state: Optional[StateFn]) -> Dict[str, torch.Tensor]:
    state = {f"{e.name}.{f}": getattr(e.state, f).clone() for e in env.world.entities for f in ("pos", "vel")}
    if scenario_state is not None:
        state.update({key: value.clone() for key, value in scenario_state(env).items()})
    return state


def check_reset_at(
    env,
    index: Union[int, List[int], str],
    mask_rows: Union[Sequence[int], slice] = (),
    scenario_state: Optional[StateFn] = None,
    bound: Union[None, float, Callable[[object], float]] = None,
) -> ResetCheck:
    """``env.reset_at(index)`` resets exactly the envs ``index`` selects.

    ``index`` is an env index, a list of them, or ``"mask"``: a boolean mask
    selecting ``mask_rows``. Checked, bitwise:

    * in every other env, every entity's pos and vel and every tensor of
      ``scenario_state(env)`` are unchanged;
    * in every selected env, every entity is at rest and every coordinate of
      its position was redrawn (differs from before), within ``|x| <= bound``
      (a number, or a function of the entity) when a bound is given.
    """
    chosen = torch.zeros(env.num_envs, dtype=torch.bool)
    if isinstance(index, str):
        assert index == "mask", index
        index = chosen.clone()
        index[mask_rows] = True
    chosen[torch.as_tensor(index)] = True
    before = _snapshot(env, scenario_state)
    obs = env.reset_at(index)
    after = _snapshot(env, scenario_state)
    for key, value in before.items():
        assert torch.equal(after[key][~chosen], value[~chosen]), key
    for e in env.world.entities:
        pos = e.state.pos[chosen]
        assert (pos != before[f"{e.name}.pos"][chosen]).all() and (e.state.vel[chosen] == 0).all(), e.name
        if bound is not None:
            assert (pos.abs() <= (bound(e) if callable(bound) else bound)).all(), e.name
    return ResetCheck(chosen, before, after, obs)


# ------------------------------------------------------------------ MPE (mpe2)
def make_mpe(parallel_env, ours, same_names: bool = True, **kwargs):
    """MPE's env ``parallel_env(**kwargs)`` (PettingZoo's parallel API), reset with seed 0.

    Its agents must be ours', by name and in order (pass ``same_names=False``
    where VMAS renamed them). Returns the env, its world and its scenario
    (whose ``reward`` and ``observation`` define the task).
    """
    mpe = parallel_env(**kwargs)
    mpe.reset(seed=0)
    world = mpe.unwrapped.world
    if same_names:
        assert [a.name for a in world.agents] == [a.name for a in ours.agents]
    return mpe, world, mpe.unwrapped.scenario


def copy_env_to_mpe(ours, world, env_index: int, velocities: bool, same_names: bool = True) -> None:
    """Put MPE's agents and landmarks where env ``env_index`` of ours has them.

    Both worlds list the same entities in the same order, under the same
    names unless ``same_names=False``. With ``velocities`` they move as ours
    do; without, they are at rest (with a no-op action MPE's explicit Euler
    step then leaves them in place, so MPE scores the very state we set).
    """
    pairs = zip(world.agents + world.landmarks, ours.world.agents + ours.world.landmarks, strict=True)
    for e_mpe, e_ours in pairs:
        assert e_mpe.name == e_ours.name or not same_names
        e_mpe.state.p_pos = e_ours.state.pos[env_index].double().numpy().copy()
        e_mpe.state.p_vel = e_ours.state.vel[env_index].double().numpy().copy() if velocities else np.zeros(2)


# -------------------------------------------------------------------- policies
def play_lineups(env, lineups: Sequence[Sequence[Optional[Policy]]], steps: int = 100) -> torch.Tensor:
    """Play line-ups side by side from ``env.reset()``; every observation and reward must stay finite.

    The batch is split into ``len(lineups)`` equal groups and group ``g``
    acts with ``lineups[g][i](obs, u_range)`` for agent ``i``; a ``None``
    policy takes that agent's rows of ``env.get_random_actions()``. Those are
    drawn at every step, before any policy runs, if some policy is ``None``,
    and never otherwise (so the RNG is used as by a hand-written loop).
    Returns the mean summed reward, [n_agents, n_lineups].
    """
    groups = len(lineups)
    size = env.num_envs // groups
    assert size * groups == env.num_envs
    any_random = any(p is None for lineup in lineups for p in lineup)
    rows = [slice(g * size, (g + 1) * size) for g in range(groups)]
    obs = env.reset()
    total = torch.zeros(env.n_agents, env.num_envs)
    for _ in range(steps):
        rand = env.get_random_actions() if any_random else None
        actions = []
        for i, (o, a) in enumerate(zip(obs, env.agents)):
            policies = [lineup[i] for lineup in lineups]
            parts = [rand[i][r] if p is None else p(o[r], a.u_range) for r, p in zip(rows, policies)]
            actions.append(torch.cat(parts))
        obs, rews, _, _ = env.step(actions)
        assert all(torch.isfinite(o).all() for o in obs) and all(torch.isfinite(r).all() for r in rews)
        total += torch.stack(rews)
    return total.view(env.n_agents, groups, size).mean(dim=-1)


def team_returns(env, policy, heuristic: Callable[[object], bool], steps: int = 100) -> List[float]:
    """Every agent's return (summed over ``steps``, mean over envs) from ``env.reset()``.

    Agent ``a`` plays ``policy.compute_action`` if ``heuristic(a)``, else
    randomly (``env.get_random_actions()``); see ``play_lineups``.
    """
    lineup = [policy.compute_action if heuristic(a) else None for a in env.agents]
    return play_lineups(env, [lineup], steps)[:, 0].tolist()
