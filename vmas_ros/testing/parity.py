"""Parity with VMAS 1.5 (the oracle): one start in both worlds, the same actions, the same results.

Every parity comparison does the same three things:

1. one initial state in both worlds: ``copy_random_state`` (a random,
   contact-rich state written into both), or ``copy_start`` (ours starts where
   VMAS's own reset left it: every entity's state, plus the per-env scenario
   state a ``scenario_state(vmas_env, our_env)`` hook writes; add
   ``copy_random_stream`` where observations are noisy);
2. both stepped with identical actions (``run_lockstep``);
3. the same states (``assert_same_state``), observations and rewards within
   ``ATOL`` at every step (``assert_same_outputs`` adds dones and infos).

``make_vmas_env`` builds VMAS's env with its warnings muted, and
``assert_same_space`` compares a gymnasium space of ours with VMAS's gym one.
``check_scenario``'s ``vmas_parity`` check and the project's parity tests use
these same functions. Every check raises AssertionError itself (never a bare
``assert``), so it holds under ``python -O`` too.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Callable, List, Optional, Sequence

import numpy as np
import torch

from vmas_ros.testing.rollout import by_agent
from vmas_ros.testing.state import FIELDS

__all__ = [
    "FIELDS", "ATOL", "RTOL", "STEPS", "make_vmas_env", "assert_same_space", "copy_random_state", "copy_state",
    "copy_start", "copy_random_stream", "uniform_actions", "assert_same_state", "Lockstep", "run_lockstep",
    "assert_same_infos", "assert_same_outputs",
]

ATOL = 1e-4
#: relative tolerance of the fields other than ``pos`` (velocities and angles
#: may carry float32 rounding relative to their size); ``pos`` always has rtol 0
RTOL = 1e-4
#: steps of a parity run
STEPS = 50


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise AssertionError(message)


# ------------------------------------------------------------------------ envs
def make_vmas_env(name: str, num_envs: int, device="cpu", seed: int = 0, **kwargs):
    """VMAS's env of its scenario ``name``; VMAS's own warnings are muted (not ours to check)."""
    import vmas

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return vmas.make_env(name, num_envs=num_envs, device=device, seed=seed, **kwargs)


def assert_same_space(ours, up, where: str = "space") -> None:
    """Structural equality of a gymnasium space (ours) and a gym space (VMAS).

    Same class name at every level; Dict: same keys in the same order; Tuple:
    same length; MultiDiscrete: same ``nvec``; Discrete: same ``n``; Box: same
    shape, dtype and bounds.
    """
    _require(type(ours).__name__ == type(up).__name__, f"{where}: ours is {ours}, VMAS's is {up}")
    if isinstance(up.spaces if hasattr(up, "spaces") else None, dict):
        _require(list(ours.spaces) == list(up.spaces),
                 f"{where}: ours has keys {list(ours.spaces)}, VMAS's {list(up.spaces)}")
        for key in up.spaces:
            assert_same_space(ours.spaces[key], up.spaces[key], f"{where}[{key}]")
    elif hasattr(up, "spaces"):
        _require(len(ours.spaces) == len(up.spaces),
                 f"{where}: ours has {len(ours.spaces)} entries, VMAS's {len(up.spaces)}")
        for i, (o, u) in enumerate(zip(ours.spaces, up.spaces)):
            assert_same_space(o, u, f"{where}[{i}]")
    elif hasattr(up, "nvec"):
        _require(np.array_equal(ours.nvec, up.nvec), f"{where}: ours has nvec {ours.nvec}, VMAS's {up.nvec}")
    elif hasattr(up, "n"):
        _require(int(ours.n) == int(up.n), f"{where}: ours has n={int(ours.n)}, VMAS's n={int(up.n)}")
    else:
        _require(ours.shape == up.shape and ours.dtype == up.dtype, f"{where}: ours is {ours}, VMAS's is {up}")
        _require(np.array_equal(ours.low, up.low), f"{where}: ours has low {ours.low}, VMAS's {up.low}")
        _require(np.array_equal(ours.high, up.high), f"{where}: ours has high {ours.high}, VMAS's {up.high}")


# ----------------------------------------------------------------------- start
def copy_random_state(up, ours, seed: int, spread: float, agents_only: bool = False) -> None:
    """Write one random (contact-rich when ``spread`` is small) state into both worlds."""
    gen = torch.Generator().manual_seed(seed)
    batch = up.world.batch_dim
    pairs = zip(up.world.agents, ours.world.agents) if agents_only else zip(up.world.entities, ours.world.entities)
    for e_up, e_ours in pairs:
        values = {
            "pos": (torch.rand(batch, 2, generator=gen) * 2 - 1) * spread,
            "vel": (torch.rand(batch, 2, generator=gen) * 2 - 1) * 0.3,
            "rot": (torch.rand(batch, 1, generator=gen) * 2 - 1) * 3.0,
            "ang_vel": (torch.rand(batch, 1, generator=gen) * 2 - 1) * 0.5,
        }
        for field_name, value in values.items():
            # each world its own copy: setters keep the tensor, and VMAS writes some in place
            getattr(e_up, f"set_{field_name}")(value.to(up.device).clone(), batch_index=None)
            getattr(e_ours, f"set_{field_name}")(value.to(ours.device).clone(), batch_index=None)


def _same_entities(up, ours) -> None:
    names_up, names = [e.name for e in up.world.entities], [e.name for e in ours.world.entities]
    _require(names == names_up, f"ours has the entities {names}, VMAS's has {names_up} (same names, same order)")


def copy_state(up, ours) -> None:
    """Give every entity of ours VMAS's ``FIELDS`` (pos, vel, rot, ang_vel) in every env.

    The worlds must list the same entities under the same names, in the same
    order. Moving a joint's end re-places its rod between the ends, so the
    rods (which come before the agents) get their own state back in a second
    pass. It also makes a joint that does not let its end turn (``rotate=False``
    without a ``fixed_rotation``) take the end's current angle to the rod as
    the one to hold, where VMAS holds the angle it had at reset; each such
    angle, [B, 1], is copied from VMAS's joint afterwards.
    """
    _same_entities(up, ours)
    for _ in range(2):
        for e_up, e_ours in zip(up.world.entities, ours.world.entities):
            for field_name in FIELDS:
                value = getattr(e_up.state, field_name)
                if not torch.equal(getattr(e_ours.state, field_name), value):
                    getattr(e_ours, f"set_{field_name}")(value.clone(), batch_index=None)
    held = {frozenset((c.entity_a.name, c.entity_b.name)): c.fixed_rotation for c in up.world.joints}
    for constraint in ours.world.joints:
        angle = held.get(frozenset((constraint.entity_a.name, constraint.entity_b.name)))
        if isinstance(angle, torch.Tensor):
            constraint.fixed_rotation = angle.clone()


def copy_start(up, ours, scenario_state: Optional[Callable[[object, object], None]] = None) -> None:
    """Start ours where VMAS's reset left it, so that ``run_lockstep`` can compare them.

    Every entity's pos, vel, rot and ang_vel are copied (``copy_state``).
    Scenarios that also draw per-env state at reset (goals, secrets, ...) pass
    ``scenario_state(up, ours)``, which writes VMAS's draw into ours.
    """
    copy_state(up, ours)
    if scenario_state is not None:
        scenario_state(up, ours)


def copy_random_stream(up, ours) -> None:
    """Give ours VMAS's torch random stream (on the CPU) where VMAS's reset left it.

    VMAS keeps one stream for all its envs (``Environment.vmas_random_state``),
    ours one per env. A scenario whose reset draws other numbers than VMAS's
    (one draw per env where VMAS draws one per batch, for instance) leaves the
    two streams at different places, and every observation noise drawn after
    that would differ; from here on both draw from the same place. VMAS keeps
    no CUDA stream, so on a GPU noisy observations cannot be compared.
    """
    state = getattr(up, "vmas_random_state", None)
    if state is not None:
        ours._rng_state["torch"] = state[0].clone()  # the env's own streams (envs/environment.py)


# ---------------------------------------------------------------- comparisons
def uniform_actions(env, gen: torch.Generator) -> List[torch.Tensor]:
    """One action per agent of ``env``, uniform in [-u_range, u_range] per component: [B, action size].

    Drawn on the generator's device (the CPU for ``torch.Generator()``), then
    scaled on the env's, so the draw does not depend on the device.
    """
    return [
        (torch.rand(env.num_envs, env.get_agent_action_size(a), generator=gen).to(env.device) * 2 - 1)
        * a.action.u_range_tensor
        for a in env.agents
    ]


def assert_same_state(up, ours, step: int, rtol: float = RTOL, atol: float = ATOL) -> None:
    """Same entities (by name), each state field finite, on VMAS's device and close to VMAS's.

    Positions within ``atol`` (absolute only); velocities and angles within
    ``atol`` absolute plus ``rtol`` relative (pass ``rtol=0`` for absolute only).
    """
    _same_entities(up, ours)
    for e_up, e_ours in zip(up.world.entities, ours.world.entities):
        for field_name in FIELDS:
            expected, actual = getattr(e_up.state, field_name), getattr(e_ours.state, field_name)
            where = f"step {step}, {e_ours.name}.{field_name}"
            _require(actual.device == expected.device,
                     f"{where}: ours is on {actual.device}, VMAS's on {expected.device}")
            _require(bool(torch.isfinite(actual).all()), f"{e_ours.name}.{field_name} not finite at step {step}")
            torch.testing.assert_close(
                actual, expected, atol=atol, rtol=0 if field_name == "pos" else rtol,
                msg=lambda m: f"{where} differs from VMAS's: {m}",
            )


def _assert_same_per_agent(ours, kind: str, mine, theirs, step: int, atol: float) -> None:
    """Each agent's ``kind`` (observation or reward) of ours within ``atol`` of VMAS's (absolute, same dtype)."""
    mine, theirs = by_agent(ours, mine), [value for _, value in by_agent(ours, theirs)]
    _require(len(mine) == len(theirs), f"step {step}: ours gave {len(mine)} {kind}s, VMAS {len(theirs)}")
    for (name, value), expected in zip(mine, theirs):
        torch.testing.assert_close(
            value, expected, atol=atol, rtol=0, msg=lambda m: f"step {step}: {kind} of {name} differs from VMAS's: {m}",
        )


@dataclass
class Lockstep:
    """What ours did during ``run_lockstep``: evidence that the comparison was not vacuous."""

    #: largest |reward| of any agent in any env at any step
    largest_reward: float = 0.0
    #: largest speed of any entity in any env at any step
    fastest: float = 0.0
    #: per agent, its rewards summed over envs and steps
    reward_sums: List[float] = field(default_factory=list)
    #: largest |message| (``state.c``) any of the ``speakers`` sent
    loudest_message: float = 0.0


def run_lockstep(
    up,
    ours,
    seed: int,
    actions: Optional[Callable[[torch.Generator], List[torch.Tensor]]] = None,
    steps: int = STEPS,
    rtol: float = RTOL,
    speakers: Sequence[int] = (),
    message_atol: float = ATOL,
    resync: bool = False,
    atol: float = ATOL,
) -> Lockstep:
    """Step both envs ``steps`` times with identical actions; they must agree at every step.

    ``actions(gen)`` draws one step's actions from a generator seeded with
    ``seed`` (default: ``uniform_actions`` of VMAS's agents). Before the
    first step and after each one: ``assert_same_state`` (with ``rtol`` and
    ``atol``), and every observation and reward within ``atol`` (absolute,
    same dtype). For the agents at the indices ``speakers`` the messages
    (``state.c``) must also agree within ``message_atol`` (absolute).

    With ``resync``, ours starts every step from VMAS's state
    (``copy_state``), so each step is compared from identical inputs. Our
    engine computes lengths as ``sqrt(x * x + y * y)`` on planar components,
    VMAS with ``torch.linalg.vector_norm`` on ``[..., 2]`` vectors; the two
    differ in the last bit for about a fifth of all inputs, and chaotic runs
    (stiff contacts between boxes, joints, friction stick-slip) amplify a
    one-ulp difference past ``ATOL`` within a few dozen steps. For those a
    free-running comparison tests float rounding, not physics; one step from
    the same state tests the physics.

    Returns what ours did (``Lockstep``), so callers can check the run
    exercised what it was meant to compare.
    """
    gen = torch.Generator().manual_seed(seed)
    if actions is None:
        actions = lambda g: uniform_actions(up, g)  # noqa: E731
    seen = Lockstep(reward_sums=[0.0] * len(ours.agents))
    assert_same_state(up, ours, 0, rtol, atol)
    for step in range(1, steps + 1):
        if resync:
            copy_state(up, ours)
        chosen = actions(gen)
        obs_up, rew_up, _, _ = up.step([a.clone() for a in chosen])
        obs_ours, rew_ours, _, _ = ours.step([a.clone() for a in chosen])
        assert_same_state(up, ours, step, rtol, atol)
        _assert_same_per_agent(ours, "observation", obs_ours, obs_up, step, atol)
        _assert_same_per_agent(ours, "reward", rew_ours, rew_up, step, atol)
        for i in speakers:
            message_up, message = up.agents[i].state.c, ours.agents[i].state.c
            torch.testing.assert_close(
                message, message_up, atol=message_atol, rtol=0,
                msg=lambda m: f"step {step}, {ours.agents[i].name}.c: {m}",
            )
            seen.loudest_message = max(seen.loudest_message, float(message.abs().max()))
        rewards = [value for _, value in by_agent(ours, rew_ours)]
        seen.largest_reward = max([seen.largest_reward] + [float(r.abs().max()) for r in rewards])
        seen.fastest = max(seen.fastest, max(float(e.state.vel.norm(dim=-1).max()) for e in ours.world.entities))
        seen.reward_sums = [total + float(r.sum()) for total, r in zip(seen.reward_sums, rewards)]
    return seen


def assert_same_infos(mine: Sequence[dict], theirs: Sequence[dict], where: str = "") -> None:
    """Per agent, the same info keys in the same order and every value within ``ATOL`` (any dtype)."""
    mine, theirs = (list(v.values()) if isinstance(v, dict) else list(v) for v in (mine, theirs))
    _require(len(mine) == len(theirs), f"{where} ours has {len(mine)} infos, VMAS's {len(theirs)}")
    for i, (ours, up) in enumerate(zip(mine, theirs)):
        _require(list(ours) == list(up), f"{where} info[{i}] keys: ours {list(ours)}, VMAS's {list(up)}")
        for key in up:
            torch.testing.assert_close(
                ours[key].double(), up[key].double(), atol=ATOL, rtol=0, msg=lambda m: f"{where} info[{i}][{key}]: {m}",
            )


def assert_same_outputs(step: int, mine: tuple, theirs: tuple) -> None:
    """One ``env.step``'s ``(obs, rews, dones, infos)`` of ours against VMAS's:
    observations and rewards within ``ATOL``, the same dones, the same infos."""
    (obs, rews, dones, infos), (obs_up, rews_up, dones_up, infos_up) = mine, theirs
    obs, rews, obs_up, rews_up = (list(v.values()) if isinstance(v, dict) else list(v)
                                  for v in (obs, rews, obs_up, rews_up))
    _require(len(obs + rews) == len(obs_up + rews_up), f"step {step}: ours gave {len(obs + rews)} observations and "
             f"rewards, VMAS {len(obs_up + rews_up)}")
    for ours, up in zip(obs + rews, obs_up + rews_up):
        torch.testing.assert_close(ours, up, atol=ATOL, rtol=0, msg=lambda m: f"step {step}: {m}")
    _require(torch.equal(dones, dones_up),
             f"step {step}: dones differ: ours {dones.tolist()}, VMAS's {dones_up.tolist()}")
    assert_same_infos(infos, infos_up, f"step {step}")
