"""Shared pieces of the parity tests against upstream VMAS (the oracle).

Every parity test does the same three things: write one initial state into
both worlds (``copy_random_state``, or ``copy_state`` to start ours where
upstream's own reset left it), step both with identical actions, and require
the same states, observations and rewards (``run_lockstep``, which checks
with ``assert_same_state``). The engine tests (``test/simulator``) and the
scenario tests (``test/scenarios``) both use these.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, List, Optional, Sequence

import torch

FIELDS = ("pos", "vel", "rot", "ang_vel")
ATOL = 1e-4
#: relative tolerance of the fields other than ``pos`` (velocities and angles
#: may carry float32 rounding relative to their size); ``pos`` always has rtol 0
RTOL = 1e-4
#: steps of a parity run
STEPS = 50


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
            # each world its own copy: setters keep the tensor, and upstream writes some in place
            getattr(e_up, f"set_{field_name}")(value.to(up.device).clone(), batch_index=None)
            getattr(e_ours, f"set_{field_name}")(value.to(ours.device).clone(), batch_index=None)


def copy_state(up, ours) -> None:
    """Give every entity of ours upstream's ``FIELDS`` (pos, vel, rot, ang_vel) in every env.

    The worlds must list the same entities under the same names, in the same
    order. Moving a joint's end re-places its rod between the ends, so the
    rods (which come before the agents) get their own state back in a second pass.
    """
    assert [e.name for e in up.world.entities] == [e.name for e in ours.world.entities]
    for _ in range(2):
        for e_up, e_ours in zip(up.world.entities, ours.world.entities):
            for field_name in FIELDS:
                value = getattr(e_up.state, field_name)
                if not torch.equal(getattr(e_ours.state, field_name), value):
                    getattr(e_ours, f"set_{field_name}")(value.clone(), batch_index=None)


def uniform_actions(env, gen: torch.Generator) -> List[torch.Tensor]:
    """One action per agent of ``env``, uniform in [-u_range, u_range] per component: [B, action size]."""
    return [
        (torch.rand(env.num_envs, env.get_agent_action_size(a), generator=gen) * 2 - 1) * a.action.u_range_tensor
        for a in env.agents
    ]


def assert_same_state(up, ours, step: int, rtol: float = RTOL) -> None:
    """Same entities (by name), each state field finite, on upstream's device and close to upstream's.

    Positions within ``ATOL`` (absolute only); velocities and angles within
    ``ATOL`` absolute plus ``rtol`` relative (pass ``rtol=0`` for absolute only).
    """
    assert [e.name for e in up.world.entities] == [e.name for e in ours.world.entities]
    for e_up, e_ours in zip(up.world.entities, ours.world.entities):
        for field_name in FIELDS:
            expected, actual = getattr(e_up.state, field_name), getattr(e_ours.state, field_name)
            assert actual.device == expected.device
            assert torch.isfinite(actual).all(), f"{e_ours.name}.{field_name} not finite at step {step}"
            torch.testing.assert_close(
                actual, expected, atol=ATOL, rtol=0 if field_name == "pos" else rtol,
                msg=lambda m: f"step {step}, {e_ours.name}.{field_name}: {m}",
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
) -> Lockstep:
    """Step both envs ``steps`` times with identical actions; they must agree at every step.

    ``actions(gen)`` draws one step's actions from a generator seeded with
    ``seed`` (default: ``uniform_actions`` of upstream's agents). Before the
    first step and after each one: ``assert_same_state`` (with ``rtol``), and
    every observation and reward within ``ATOL`` (absolute, same dtype). For
    the agents at the indices ``speakers`` the messages (``state.c``) must
    also agree within ``message_atol`` (absolute).

    With ``resync``, ours starts every step from upstream's state
    (``copy_state``), so each step is compared from identical inputs. Our
    engine computes lengths as ``sqrt(x * x + y * y)`` on planar components,
    upstream with ``torch.linalg.vector_norm`` on ``[..., 2]`` vectors; the two
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
    assert_same_state(up, ours, 0, rtol)
    for step in range(1, steps + 1):
        if resync:
            copy_state(up, ours)
        chosen = actions(gen)
        obs_up, rew_up, _, _ = up.step([a.clone() for a in chosen])
        obs_ours, rew_ours, _, _ = ours.step([a.clone() for a in chosen])
        assert_same_state(up, ours, step, rtol)
        for mine, theirs in zip(obs_ours + rew_ours, obs_up + rew_up, strict=True):
            torch.testing.assert_close(mine, theirs, atol=ATOL, rtol=0, msg=lambda m: f"step {step}: {m}")
        for i in speakers:
            message_up, message = up.agents[i].state.c, ours.agents[i].state.c
            torch.testing.assert_close(
                message, message_up, atol=message_atol, rtol=0,
                msg=lambda m: f"step {step}, {ours.agents[i].name}.c: {m}",
            )
            seen.loudest_message = max(seen.loudest_message, float(message.abs().max()))
        seen.largest_reward = max([seen.largest_reward] + [float(r.abs().max()) for r in rew_ours])
        seen.fastest = max(seen.fastest, max(float(e.state.vel.norm(dim=-1).max()) for e in ours.world.entities))
        seen.reward_sums = [total + float(r.sum()) for total, r in zip(seen.reward_sums, rew_ours)]
    return seen


def assert_same_infos(mine: Sequence[dict], theirs: Sequence[dict], where: str = "") -> None:
    """Per agent, the same info keys in the same order and every value within ``ATOL`` (any dtype)."""
    for i, (ours, up) in enumerate(zip(mine, theirs, strict=True)):
        assert list(ours) == list(up), f"{where} info[{i}] keys"
        for key in up:
            torch.testing.assert_close(
                ours[key].double(), up[key].double(), atol=ATOL, rtol=0, msg=lambda m: f"{where} info[{i}][{key}]: {m}",
            )


def assert_same_outputs(step: int, mine: tuple, theirs: tuple) -> None:
    """One ``env.step``'s ``(obs, rews, dones, infos)`` of ours against upstream's:
    observations and rewards within ``ATOL``, the same dones, the same infos."""
    (obs, rews, dones, infos), (obs_up, rews_up, dones_up, infos_up) = mine, theirs
    for ours, up in zip(obs + rews, obs_up + rews_up, strict=True):
        torch.testing.assert_close(ours, up, atol=ATOL, rtol=0, msg=lambda m: f"step {step}: {m}")
    assert torch.equal(dones, dones_up), f"step {step}: dones"
    assert_same_infos(infos, infos_up, f"step {step}")
