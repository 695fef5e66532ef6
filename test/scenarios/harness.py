"""Shared machinery of the MPE scenario tests (``test/scenarios/test_mpe_*.py``).

Each scenario is checked the same ways against the same oracles; this module
holds the one copy of every check they share, and each test file keeps only
what is specific to its scenario (which kwargs, which per-env scenario state,
which bounds, which measured returns).

* building envs: ``make`` (ours) and ``make_upstream`` (VMAS 1.5.2, the oracle);
* spaces: ``assert_same_space`` and ``check_spaces`` (spaces equal to
  upstream's, then a short random rollout that must stay finite and fit them);
* parity with upstream: ``copy_start`` (upstream's start, and its per-env
  scenario state, into ours) then ``vmas_ros.testing.parity.run_lockstep`` (the
  same lock-step loop and state comparison the engine parity tests use);
* resets: ``check_reset_at`` (exactly the selected envs are redrawn);
* semantics against MPE (mpe2): ``make_mpe`` and ``copy_env_to_mpe``;
* policies: ``play_lineups`` (rollouts with per-agent policies, every value
  finite) and ``team_returns`` (heuristic against random returns).

The pieces that ``vmas_ros.testing.check_scenario`` shares with these tests
(the layouts, random actions and rollouts, the fit of an observation to its
space, the parity helpers, the row-wise comparison of snapshots) live in the
shipped package ``vmas_ros.testing`` and are imported from there.
"""
from __future__ import annotations

from typing import Callable, Dict, List, NamedTuple, Optional, Sequence, Union

import numpy as np
import pytest
import torch

import vmas_ros
from vmas_ros.testing.parity import assert_same_space, copy_start, make_vmas_env
from vmas_ros.testing.rollout import ACTION_MODES, SPACE_MODES, random_steps, space_actions, space_mismatch
from vmas_ros.testing.state import changed_rows, entity_state

__all__ = [
    "ACTION_MODES", "SPACE_MODES", "make", "make_upstream", "assert_same_space", "space_actions", "random_steps",
    "check_kwargs_refused", "check_spaces", "copy_start", "ResetCheck", "check_reset_at", "make_mpe", "copy_env_to_mpe", "play_lineups",
    "team_returns",
]

#: a function of an env giving named per-env tensors ([B, ...]) of scenario state
StateFn = Callable[[object], Dict[str, torch.Tensor]]
#: a policy as ``play_lineups`` calls it: ``(obs [b, obs size], u_range) -> action [b, action size]``
Policy = Callable[[torch.Tensor, float], torch.Tensor]


# ------------------------------------------------------------------------ envs
def make(scenario, num_envs: int, seed: int = 0, **kwargs):
    """Our env for ``scenario`` (a ``Scenario`` instance or a registered name), on the CPU."""
    return vmas_ros.make_env(scenario, num_envs=num_envs, device="cpu", seed=seed, **kwargs)


def make_upstream(name: str, num_envs: int, seed: int = 0, **kwargs):
    """Upstream VMAS's env for the scenario ``name``, on the CPU; its warnings are muted (not ours to check)."""
    return make_vmas_env(name, num_envs, device="cpu", seed=seed, **kwargs)


# ---------------------------------------------------------------------- spaces
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
        assert set(obs) == set(spaces), f"observations of {sorted(obs)}, spaces of {sorted(spaces)}"
        fits = [space_mismatch(o, spaces[k], ours.num_envs, f"observation of {k}") for k, o in obs.items()]
    else:
        assert len(obs) == len(spaces), f"{len(obs)} observations, {len(spaces)} spaces"
        fits = [space_mismatch(o, s, ours.num_envs, f"observation {i}") for i, (o, s) in enumerate(zip(obs, spaces))]
    assert fits == [None] * len(fits), [problem for problem in fits if problem]
    return obs, rews


# ---------------------------------------------------------------------- kwargs
def check_kwargs_refused(make: Callable, num_envs: int, bad: Sequence[dict]) -> None:
    """``make(num_envs, **kwargs)`` warns about an unknown kwarg, naming it, and raises ValueError
    naming the kwarg for each ``{name: value}`` of ``bad``."""
    with pytest.warns(UserWarning, match="not_a_kwarg"):
        make(num_envs, not_a_kwarg=1)
    for kwargs in bad:
        (name,) = kwargs
        with pytest.raises(ValueError, match=name):
            make(num_envs, **kwargs)


# ---------------------------------------------------------------------- resets
class ResetCheck(NamedTuple):
    """What ``check_reset_at`` saw, for the scenario-specific checks that follow it."""

    chosen: torch.Tensor  # [B] bool, the envs that were reset
    before: Dict[str, torch.Tensor]  # snapshot before the reset (entity ``name.pos``/``name.vel``, scenario state)
    after: Dict[str, torch.Tensor]  # the same snapshot after it
    obs: object  # what ``reset_at`` returned


def _snapshot(env, scenario_state: Optional[StateFn]) -> Dict[str, torch.Tensor]:
    state = entity_state(env, ("pos", "vel"))
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
    unchosen_changed = changed_rows(before, after, ~chosen)
    assert not unchosen_changed, f"changed outside the reset envs: {unchosen_changed}"
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
