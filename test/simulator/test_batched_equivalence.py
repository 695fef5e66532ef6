"""Env i of a batch evolves exactly like the same env simulated alone.

A batch of N envs is N independent simulations that share kernels. We build a
scenario with num_envs=8, make the envs differ (random resets, per-env
perturbations and per-env actions), copy env i's state into a num_envs=1 env of
the same scenario and step both with env i's actions: the states must agree.

``World.broad_phase = "env"`` makes the contact broad phase per env; the default
"batch" mode (VMAS 1.5 behaviour) shares it across the batch, which matters only
near the circumscribed-radius threshold of line/box pairs (see
``physics.pair_forces``). The last tests pin down both sides of that.
"""
from __future__ import annotations

import pytest
import torch

import vmas_ros
from vmas_ros.simulator.core import Agent, Landmark, Line, Sphere, World
from vmas_ros.simulator.utils import LINE_MIN_DIST

N = 8
STEPS = 50
#: float32 kernels take vectorised paths for a batch and scalar paths for one env, which
#: round the last bit differently; 50 steps of piled-up contacts grow that to ~1e-6
ATOL = 1e-5
FIELDS = ("pos", "vel", "rot", "ang_vel")


def _copy_env_state(src_env, index: int, dst_env) -> None:
    """Write env ``index`` of ``src_env`` into env 0 of ``dst_env`` (state setters: no joint callbacks)."""
    for e_src, e_dst in zip(src_env.world.entities, dst_env.world.entities):
        assert e_src.name == e_dst.name
        for field in FIELDS:
            setattr(e_dst.state, field, getattr(e_src.state, field)[index : index + 1].clone())


def _assert_env_equal(batch_env, index: int, single_env, step: int, atol: float = ATOL) -> None:
    # exact checks cover every field; tolerant checks (chaotic joints) cover positions
    fields = FIELDS if atol == ATOL else ("pos",)
    for e_b, e_s in zip(batch_env.world.entities, single_env.world.entities):
        for field in fields:
            torch.testing.assert_close(
                getattr(e_s.state, field)[0], getattr(e_b.state, field)[index],
                atol=atol, rtol=0,
                msg=lambda m: f"step {step}, env {index}, {e_b.name}.{field}: {m}",
            )


def _perturb_waterfall(env, gen) -> None:
    """Shift and turn the free boxes differently in every env (the chain keeps its joints intact)."""
    n = env.num_envs
    for e in env.world.landmarks:
        if e.name.startswith("landmark "):
            e.state.pos = e.state.pos + (torch.rand(n, 2, generator=gen) - 0.5) * 0.1
            e.state.rot = e.state.rot + (torch.rand(n, 1, generator=gen) - 0.5) * 0.5


def _make(name: str, num_envs: int, broad_phase: str, seed: int = 1):
    env = vmas_ros.make_env(name, num_envs=num_envs, device="cpu", seed=seed)
    env.world.broad_phase = broad_phase
    return env


def _actions(name: str, env, gen) -> list:
    """Per-env actions that drive contacts: spread agents pile up at the origin, the
    waterfall chain heads down into the boxes; plus per-env noise."""
    n = env.num_envs
    actions = []
    for agent in env.agents:
        noise = (torch.rand(n, 2, generator=gen) * 2 - 1) * 0.5
        if name == "simple_spread":
            target = -2.0 * agent.state.pos
        else:
            target = torch.tensor([0.0, -1.0]).expand(n, 2)
        actions.append((target + noise).clamp(-1.0, 1.0))
    return actions


def _touching(name: str, env) -> bool:
    """Did a contact happen in some env (so the equivalence covers contact forces)?"""
    if name == "simple_spread":
        agents = env.world.agents
        return any(
            bool(env.world.is_overlapping(a, b).any()) for i, a in enumerate(agents) for b in agents[i + 1 :]
        )
    # the tilted boxes are moved by nothing but contacts
    return any(bool(e.state.vel.abs().max() > 0) for e in env.world.landmarks if e.name.startswith("landmark "))


def _run_equivalence(name: str, indices, broad_phase: str, seed: int, atol: float = ATOL, steps: int = STEPS) -> None:
    gen = torch.Generator().manual_seed(seed)
    batch = _make(name, N, broad_phase)
    if name == "waterfall":
        _perturb_waterfall(batch, gen)
    singles = {i: _make(name, 1, broad_phase) for i in indices}
    for i, single in singles.items():
        _copy_env_state(batch, i, single)
        _assert_env_equal(batch, i, single, 0)
    spread = max(float((e.state.pos - e.state.pos[:1]).abs().max()) for e in batch.world.entities)
    assert spread > 1e-2, "the envs of the batch must differ, or the test proves nothing"
    touched = False
    for step in range(1, steps + 1):
        actions = _actions(name, batch, gen)
        batch.step(actions)
        for i, single in singles.items():
            single.step([a[i : i + 1].clone() for a in actions])
            _assert_env_equal(batch, i, single, step, atol)
        touched = touched or _touching(name, batch)
    assert touched, "no contact happened: the equivalence would not cover contact forces"


def test_simple_spread_batch_equals_single_envs_env_broad_phase():
    _run_equivalence("simple_spread", range(N), "env", seed=0)


def test_waterfall_batch_equals_single_envs_env_broad_phase():
    """Same physics, but not bit-identical: torch.logaddexp (contacts and joints) rounds 1 ulp
    differently on its vectorized path (the batch of 8) than on its scalar path (a lone env), and
    the chain's stiff joints and box contacts amplify that chaotically (about x10 every 10 steps
    here). Positions must agree to the parity tolerance (1e-4) over 25 steps; bit-exact
    independence of envs at equal batch size is test_envs_do_not_depend_on_the_other_envs."""
    # waterfall steps are costly (joints, 5 substeps): check the first and an interior env
    _run_equivalence("waterfall", (0, 5), "env", seed=1, atol=1e-4, steps=25)


def test_simple_spread_batch_equals_single_envs_default_broad_phase():
    """Spheres only: a sphere pair's force is already zero beyond the broad-phase radius,
    so sharing the broad phase across the batch cannot change any env."""
    assert vmas_ros.make_env("simple_spread", num_envs=1).world.broad_phase == "batch", (
        "the VMAS-parity mode must stay the default"
    )
    _run_equivalence("simple_spread", (0, 3, 7), "batch", seed=2)


@pytest.mark.parametrize("name", ["simple_spread", "waterfall"])
def test_envs_do_not_depend_on_the_other_envs(name):
    """Same batch size, so every env row takes the same float kernels: replacing the odd
    envs by different states and actions must leave the even envs bit-identical."""
    gen = torch.Generator().manual_seed(7)
    batch = _make(name, N, "env")
    if name == "waterfall":
        _perturb_waterfall(batch, gen)
    other = _make(name, N, "env", seed=99)
    if name == "waterfall":
        _perturb_waterfall(other, gen)
    odd = torch.arange(N) % 2 == 1
    for e_b, e_o in zip(batch.world.entities, other.world.entities):
        for field in FIELDS:
            mixed = torch.where(odd.unsqueeze(-1), getattr(e_o.state, field), getattr(e_b.state, field))
            setattr(e_o.state, field, mixed.clone())
    assert any(
        not torch.equal(e_b.state.pos[odd], e_o.state.pos[odd])
        for e_b, e_o in zip(batch.world.entities, other.world.entities)
    ), "the odd envs must differ between the two batches"
    touched = False
    for step in range(1, STEPS + 1):
        actions = _actions(name, batch, gen)
        scrambled = [torch.where(odd.unsqueeze(-1), a.flip(0), a) for a in actions]
        batch.step(actions)
        other.step(scrambled)
        for e_b, e_o in zip(batch.world.entities, other.world.entities):
            for field in FIELDS:
                a, b = getattr(e_b.state, field)[~odd], getattr(e_o.state, field)[~odd]
                assert torch.equal(a, b), f"step {step}, {e_b.name}.{field}: max diff {float((a - b).abs().max())}"
        touched = touched or _touching(name, batch)
    assert touched, "no contact happened: the check would not cover contact forces"
    # and the odd envs really evolved differently
    assert any(
        not torch.equal(e_b.state.pos[odd], e_o.state.pos[odd])
        for e_b, e_o in zip(batch.world.entities, other.world.entities)
    )


# -------------------------------------------------------- the broad phase modes


def _threshold_world(broad_phase: str, positions):
    """A fixed bar of length 0.4 at the origin and a ball of radius 0.1 at ``positions`` [2, 2]."""
    world = World(batch_dim=2, device="cpu", dt=0.1, substeps=1, drag=0.0)
    world.broad_phase = broad_phase
    bar = Landmark("bar", shape=Line(length=0.4), movable=False, rotatable=False)
    ball = Agent("ball", shape=Sphere(0.1))
    world.add_landmark(bar)
    world.add_agent(ball)
    ball.set_pos(torch.tensor(positions), batch_index=None)
    return world, ball


# just beyond the bar's end: centres farther apart than the broad-phase reach (0.2 + 0.1),
# but the ball is within the contact band (radius + LINE_MIN_DIST) of the bar's end
NEAR_END = [0.2 + 0.1 + 0.005, 0.0]
OVERLAPPING = [0.0, 0.05]
assert NEAR_END[0] - 0.2 < 0.1 + LINE_MIN_DIST


def test_env_broad_phase_isolates_envs():
    world, ball = _threshold_world("env", [NEAR_END, OVERLAPPING])
    world.step()
    assert float(ball.state.vel[0].abs().max()) == 0.0, "env 0 must not feel env 1's contact"
    assert float(ball.state.vel[1, 1]) > 0.0, "env 1 is pushed off the bar"


def test_batch_broad_phase_shares_the_cut_across_envs():
    """Documented VMAS 1.5 behaviour: a pair near in any env is evaluated in every env."""
    world, ball = _threshold_world("batch", [NEAR_END, OVERLAPPING])
    world.step()
    assert float(ball.state.vel[0, 0]) > 0.0, "in batch mode env 0 gets the bar-end contact"
    # without a near neighbour in the batch, the same env feels nothing
    alone, alone_ball = _threshold_world("batch", [NEAR_END, NEAR_END])
    alone.step()
    assert float(alone_ball.state.vel.abs().max()) == 0.0
