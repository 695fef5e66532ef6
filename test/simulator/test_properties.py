"""Property-based tests of the engine (hypothesis): random worlds never leave the finite, bounded regime.

Hand-written cases only probe the layouts someone thought of; the failures that
matter in a long training run come from the ones nobody did: two bodies
spawned on the same centre, a box exactly on a line, a 1 g agent touching a
1 t landmark. Here hypothesis draws whole worlds (spheres, boxes, lines; sizes
over two orders of magnitude, masses over six; positions snapped to a coarse
grid so exact overlaps and coincident centres are common; substeps, dt, drag
and contact margin over their valid ranges; optional joints) and actions
anywhere in range, bounds included, and checks properties of every step.

**The contact force bound.** Every collision kernel ends in
``physics.collision.contact.soft_contact``: a pair whose contact points are ``d`` apart pushes
with magnitude ``c * k * log(1 + exp((d_min - d) / k))`` while
``1e-6 <= d <= d_min``, else 0 (``c`` = collision_force, ``k`` = contact_margin).
As ``d >= 0`` and ``log(1 + exp(x)) <= max(x, 0) + log 2``, the magnitude is at
most ``c * (d_min + k log 2)``. ``d_min`` is, per kernel, the sum of the radii
(sphere-sphere), ``r + LINE_MIN_DIST`` (line-sphere), ``LINE_MIN_DIST``
(line-line), and for boxes ``LINE_MIN_DIST`` plus the sphere's radius (if
any) plus a "solid depth" per box, which is the projection of a segment from
the box's centre to a point of its outline, so at most the box's
circumscribed radius. Hence, with ``R`` each shape's circumscribed radius::

    |F_pair| <= B_pair = c * (R_a + R_b + LINE_MIN_DIST + k log 2)

and, since the lever arm of a contact torque runs from the centre to a point
of the shape, ``|tau| <= R * B_pair``. The bound does not depend on the
state, so it also proves the state stays finite under contacts alone: the
velocity change of a step is at most ``dt (|F_action| + sum B_pair) / m``.

**Joints** are springs of stiffness ``joint_force`` with no force cap, and
rotation locks are exponential springs; semi-implicit Euler on a spring is
stable only while ``omega * h < 2`` (``h`` = dt / substeps). Joint worlds are
therefore drawn with masses and inertias that keep ``K h^2 / m <= 1/4`` (see
``_joint_mass_floor``); outside that the engine diverges like any explicit
integrator, which ``test_stiff_joint_outside_the_stable_range_diverges``
documents.

The profile is derandomised (the same examples every run) with a moderate
number of examples, so CI is deterministic and the file runs in well under a
minute.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import torch
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from vmas_ros.simulator import physics
from vmas_ros.simulator.physics.collision import pair_forces
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.joints import Joint
from vmas_ros.simulator.utils import JOINT_FORCE, LINE_MIN_DIST, TORQUE_CONSTRAINT_FORCE

BATCH = 3  # env 0 as drawn, env 1 jittered, env 2 mirrored: the batch broad phase then spans differing envs
STEPS = 15
PROFILE = settings(
    derandomize=True, max_examples=30, deadline=None, database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
GRID = 0.05  # positions are multiples of this: coincident centres and exact touching are frequent
REL_TOL = 1e-4  # float32 rounding margin on the analytic bounds


# ------------------------------------------------------------------- world specs
@dataclass
class BodySpec:
    """One entity, drawn by hypothesis (printed on failure, so a counterexample is a recipe)."""

    kind: str
    size: Tuple[float, float]  # sphere: (radius, _), box: (length, width), line: (length, _)
    mass: float
    is_agent: bool
    movable: bool
    rotatable: bool
    hollow: bool
    pos: Tuple[float, float]
    rot: float
    vel: Tuple[float, float]
    ang_vel: float
    u_range: float
    max_f: Optional[float]
    action: Tuple[float, float]  # as a fraction of u_range, in [-1, 1]


@dataclass
class WorldSpec:
    dt: float
    substeps: int
    drag: float
    contact_margin: float
    bodies: List[BodySpec]
    joints: List[Tuple[int, int, float, Tuple[float, float], Tuple[float, float], bool, bool]] = field(default_factory=list)
    x_semidim: Optional[float] = None


def _log_uniform(low: float, high: float) -> st.SearchStrategy[float]:
    """Floats whose logarithm is uniform: masses and sizes over orders of magnitude, ends included."""
    return st.one_of(
        st.sampled_from([low, high]),
        st.floats(math.log10(low), math.log10(high)).map(lambda e: float(10.0**e)),
    )


def _shape_size(kind: str) -> st.SearchStrategy[Tuple[float, float]]:
    return st.tuples(_log_uniform(0.01, 1.0), _log_uniform(0.01, 1.0))


@st.composite
def bodies(draw, mass_floor: float = 1e-3, still: bool = False) -> BodySpec:
    kind = draw(st.sampled_from(["sphere", "box", "line"]))
    grid = st.integers(-6, 6).map(lambda i: i * GRID)
    is_agent = draw(st.booleans())
    fraction = st.one_of(st.sampled_from([-1.0, 0.0, 1.0]), st.floats(-1.0, 1.0))  # bounds included
    return BodySpec(
        kind=kind,
        size=draw(_shape_size(kind)),
        mass=draw(_log_uniform(mass_floor, 1e3)),
        is_agent=is_agent,
        movable=True if is_agent else draw(st.booleans()),
        rotatable=draw(st.booleans()),
        hollow=draw(st.booleans()) if kind == "box" else False,
        pos=(draw(grid), draw(grid)),
        rot=draw(st.sampled_from([0.0, math.pi / 2, math.pi / 4, -math.pi])),
        vel=(0.0, 0.0) if still else (draw(st.floats(-2, 2)), draw(st.floats(-2, 2))),
        ang_vel=0.0 if still else draw(st.floats(-5, 5)),
        u_range=draw(_log_uniform(0.1, 10.0)),
        max_f=draw(st.none() | st.floats(0.05, 5.0)),
        action=(0.0, 0.0) if still else (draw(fraction), draw(fraction)),
    )


@st.composite
def worlds(draw, with_joints: bool = False) -> WorldSpec:
    substeps = draw(st.integers(2 if with_joints else 1, 10))
    dt = draw(st.sampled_from([0.01, 0.05, 0.1]) | st.floats(0.005, 0.2))
    floor = _joint_mass_floor(dt / substeps) if with_joints else 1e-3
    n = draw(st.integers(2, 6))
    specs = [draw(bodies(mass_floor=floor)) for _ in range(n)]
    if draw(st.booleans()) and n >= 2:  # a coincident centre on purpose
        specs[1].pos = specs[0].pos
    joints = []
    if with_joints:
        for _ in range(draw(st.integers(1, 2))):
            a, b = draw(st.lists(st.integers(0, n - 1), min_size=2, max_size=2, unique=True))
            if any({a, b} == {j[0], j[1]} for j in joints):
                continue  # one joint per pair of bodies (a second would add a rod of the same name)
            dist = draw(st.sampled_from([0.0, 0.1]) | st.floats(0.05, 0.6))
            anchor = st.tuples(st.sampled_from([-1.0, 0.0, 1.0]), st.sampled_from([-1.0, 0.0, 1.0]))
            rotate_a, rotate_b = (True, True) if dist == 0 else (draw(st.booleans()), draw(st.booleans()))
            joints.append((a, b, dist, draw(anchor), draw(anchor), rotate_a, rotate_b))
        for spec in specs:  # the lock spring is stiff in angle: give every body the inertia it needs
            spec.size = tuple(max(s, _lock_size_floor(spec, dt / substeps)) for s in spec.size)
        # the floor covers relative angles up to a radian; a body spinning at a few rad/s turns
        # further than that within one step, where the lock's stiffness grows as exp|delta| and no
        # explicit step is stable. Bodies under a lock therefore start without spin.
        for a, b, _, _, _, rotate_a, rotate_b in joints:
            if not (rotate_a and rotate_b):
                specs[a].ang_vel = specs[b].ang_vel = 0.0
    return WorldSpec(
        dt=dt, substeps=substeps, drag=draw(st.sampled_from([0.0, 0.25, 1.0]) | st.floats(0.0, 1.0)),
        contact_margin=draw(st.sampled_from([1e-3]) | _log_uniform(1e-4, 1e-2)), bodies=specs, joints=joints,
        x_semidim=draw(st.none() | st.sampled_from([0.3, 1.0])),
    )


def _joint_mass_floor(h: float) -> float:
    """Smallest mass keeping ``K h^2 / m <= 1/4`` for a joint spring, its lever arms included (3K: a line's)."""
    return 4 * 3 * JOINT_FORCE * h * h


def _lock_size_floor(spec: BodySpec, h: float) -> float:
    """Smallest size whose inertia keeps the rotation lock stable: ``e c_t h^2 / I <= 1/4``, with I >= m s^2 / 12.

    The lock torque is ``c_t (exp|delta| - 1)``, whose stiffness is ``c_t e`` at
    ``|delta| = 1``: ``e`` covers angles up to a radian.
    """
    return math.sqrt(4 * 12 * math.e * TORQUE_CONSTRAINT_FORCE * h * h / spec.mass)


def _rod_mass(h: float, dist: float) -> float:
    """Mass of a joint's rod (a line of length ``dist``): above the spring floor, and heavy enough in
    inertia (m L^2 / 12) for the two rotation locks it may carry (``2 e c_t h^2 / I <= 1/4``)."""
    return max(1.0, _joint_mass_floor(h), 4 * 2 * 12 * math.e * TORQUE_CONSTRAINT_FORCE * h * h / (dist * dist))


def _shape(spec: BodySpec):
    a, b = spec.size
    if spec.kind == "sphere":
        return Sphere(radius=a)
    if spec.kind == "box":
        return Box(length=a, width=b, hollow=spec.hollow)
    return Line(length=a)


def build(spec: WorldSpec, collide: bool = True) -> Tuple[World, List]:
    """The world of ``spec`` with its bodies placed; returns it and the entities in spec order."""
    world = World(batch_dim=BATCH, device="cpu", dt=spec.dt, substeps=spec.substeps, drag=spec.drag,
                  contact_margin=spec.contact_margin, x_semidim=spec.x_semidim)
    entities = []
    for i, b in enumerate(spec.bodies):
        common = dict(shape=_shape(b), movable=b.movable, rotatable=b.rotatable, mass=b.mass, collide=collide)
        if b.is_agent:
            entity = Agent(f"agent_{i}", u_range=b.u_range, max_f=b.max_f, **common)
            world.add_agent(entity)
        else:
            entity = Landmark(f"landmark_{i}", **common)
            world.add_landmark(entity)
        entities.append(entity)
    # joints first, states after, as scenarios do (joints in make_world, states in reset): placing an
    # end re-places the rod and takes the current relative angle as a lock's target, so locks start
    # relaxed instead of a full turn away from their target
    for a, b, dist, anchor_a, anchor_b, rotate_a, rotate_b in spec.joints:
        world.add_joint(Joint(entities[a], entities[b], anchor_a=anchor_a, anchor_b=anchor_b, dist=dist,
                              rotate_a=rotate_a, rotate_b=rotate_b,
                              mass=_rod_mass(spec.dt / spec.substeps, dist) if dist > 0 else 1.0))
    for b, entity in zip(spec.bodies, entities):
        x, y = b.pos
        # env 1: a small jitter; env 2: mirrored, so envs of one batch hold different contact sets
        pos = torch.tensor([[x, y], [x + 0.013, y - 0.007], [-x, y]])
        entity.set_pos(pos, batch_index=None)
        entity.set_rot(torch.full((BATCH, 1), b.rot), batch_index=None)
        entity.set_vel(torch.tensor([b.vel] * BATCH), batch_index=None)
        entity.set_ang_vel(torch.full((BATCH, 1), b.ang_vel), batch_index=None)
    return world, entities


def apply_actions(spec: WorldSpec, entities) -> None:
    """Each agent's force for the next step: its drawn fraction of ``u_range`` (Holonomic: force = u)."""
    for b, entity in zip(spec.bodies, entities):
        if b.is_agent:
            force = torch.tensor([b.action[0] * b.u_range, b.action[1] * b.u_range])
            entity.state.force = force.expand(BATCH, 2).clone()


def state_tensors(world: World) -> List[torch.Tensor]:
    return [world.stacked_state(name) for name in ("pos", "vel", "rot", "ang_vel")]


def pair_bounds(world: World, pair) -> torch.Tensor:
    """``B_pair`` of the module docstring for each pair of one kernel, [P]."""
    radius = torch.tensor([e.shape.circumscribed_radius() for e in world.entities])
    reach = radius[pair.index_a] + radius[pair.index_b] + LINE_MIN_DIST + world.contact_margin * math.log(2)
    return world.collision_force * reach


# ------------------------------------------------------------------- properties
def _force_budget(world: World) -> torch.Tensor:
    """Per entity, the sum of ``B_pair`` over every pair it belongs to, [N]."""
    budget = torch.zeros(len(world.entities))
    for pair in world.tables.pairs:
        b = pair_bounds(world, pair)
        budget.index_add_(0, pair.index_a, b)
        budget.index_add_(0, pair.index_b, b)
    return budget


def _check_pair_forces(world: World, step: int) -> None:
    """Every pair's force within ``B_pair`` and torque within ``R * B_pair``, all finite, in the current state."""
    state = physics.BodyState(*state_tensors(world))
    radius = torch.tensor([e.shape.circumscribed_radius() for e in world.entities])
    for pair in world.tables.pairs:
        f_a, f_b, t_a, t_b = pair_forces(pair, state, world._step_params())
        bound = pair_bounds(world, pair).view(-1, 1) * (1 + REL_TOL)
        for f in (f_a, f_b):
            norm = torch.linalg.vector_norm(f, dim=-1)
            assert torch.isfinite(f).all(), f"{pair.kind}: non-finite contact force at step {step}"
            assert (norm <= bound).all(), f"{pair.kind}: |F| {norm.max():.4g} over bound {bound.max():.4g} at step {step}"
        for t, index in ((t_a, pair.index_a), (t_b, pair.index_b)):
            lever = radius[index].view(-1, 1) * bound
            assert torch.isfinite(t).all() and (t[..., 0].abs() <= lever).all(), (
                f"{pair.kind}: torque {t.abs().max():.4g} over |r| B at step {step}")


@settings(PROFILE, max_examples=40)
@given(spec=worlds())
def test_random_worlds_stay_finite_with_bounded_contact_forces(spec: WorldSpec) -> None:
    """Any drawn world, stepped with in-range actions (bounds included), for every step:

    - every pair's contact force is finite and within ``B_pair``, its torques within ``R * B_pair``;
    - every movable body's speed obeys ``|v'| <= (1 - drag)|v| + dt (|F_action| + sum of its B_pair) / m``,
      the integral form of the bound that keeps a long run finite (it would also catch a force that
      escapes the per-pair check: a scatter onto the wrong entity, a substep applied twice);
    - the whole state (pos, vel, rot, ang_vel) is finite.
    """
    world, entities = build(spec)
    budget = _force_budget(world)
    index = {e: i for i, e in enumerate(world.entities)}
    for step in range(STEPS):
        _check_pair_forces(world, step)
        apply_actions(spec, entities)
        before = world.stacked_state("vel").clone()
        world.step()
        for name, value in zip(("pos", "vel", "rot", "ang_vel"), state_tensors(world)):
            assert torch.isfinite(value).all(), f"non-finite {name} after step {step + 1}"
        after = world.stacked_state("vel")
        for b, entity in zip(spec.bodies, entities):
            if not b.movable:  # an immovable body keeps whatever velocity it was given, undamped
                continue
            i = index[entity]
            action = math.hypot(*b.action) * b.u_range if b.is_agent else 0.0
            limit = (1 - spec.drag) * torch.linalg.vector_norm(before[i], dim=-1) + spec.dt * (action + budget[i]) / b.mass
            speed = torch.linalg.vector_norm(after[i], dim=-1)
            assert (speed <= limit * (1 + REL_TOL) + 1e-6).all(), (
                f"{entity.name}: |v| {speed.max():.4g} > {limit.max():.4g} after step {step + 1}")


# no shrinking here: while the free-pin bug (test_free_pin_survives_a_long_spin) is open this fails in
# seconds instead of minutes, and that test is the minimal reproduction
@settings(PROFILE, max_examples=25, phases=[Phase.explicit, Phase.reuse, Phase.generate])
@given(spec=worlds(with_joints=True))
def test_jointed_worlds_in_the_stable_range_stay_finite(spec: WorldSpec) -> None:
    """Joints (pins and rods, free or locked rotation) with masses above the stability floor: finite state.

    Contacts are off here: a contact force is bounded but not small (``B_pair``
    is 130 N for two 0.6 m bodies), and on a light body it loads a rotation lock
    far up its exponential, whose stiffness then exceeds what any explicit step
    can follow. Contacts are covered, joint-free, by the tests above.
    """
    world, entities = build(spec, collide=False)
    for step in range(2 * STEPS):
        apply_actions(spec, entities)
        world.step()
        for name, value in zip(("pos", "vel", "rot", "ang_vel"), state_tensors(world)):
            assert torch.isfinite(value).all(), f"non-finite {name} after step {step + 1}"


@settings(PROFILE, max_examples=15)
@given(spec=worlds(), spacing=st.floats(0.05, 1.0))
def test_zero_actions_and_no_contacts_mean_no_motion(spec: WorldSpec, spacing: float) -> None:
    """Bodies at rest, apart (broad phase never reached) or not colliding, with zero actions: bit-identical state."""
    for b in spec.bodies:
        b.vel, b.ang_vel, b.action = (0.0, 0.0), 0.0, (0.0, 0.0)
    reach = max(max(b.size) for b in spec.bodies)  # >= every circumscribed radius (a box's is hypot(l, w) / 2)
    for i, b in enumerate(spec.bodies):  # on a line, centres 4 reach + spacing apart: circles never near
        b.pos = (i * (4 * reach + spacing), 0.0)
    spec.x_semidim = None
    world, entities = build(spec)
    start = [t.clone() for t in state_tensors(world)]
    for _ in range(5):
        apply_actions(spec, entities)
        world.step()
    for before, after in zip(start, state_tensors(world)):
        assert torch.equal(before, after)


@settings(PROFILE, max_examples=20)
@given(spec=worlds())
def test_contacts_conserve_linear_momentum(spec: WorldSpec) -> None:
    """All bodies movable, no drag, no actions, no walls, no limits: contacts only move momentum around.

    Each kernel applies equal and opposite forces, so the total ``sum m v``
    stays put to float32 rounding (relative to the momentum scale involved).
    """
    for b in spec.bodies:
        b.movable, b.action, b.max_f = True, (0.0, 0.0), None
    spec.drag, spec.x_semidim = 0.0, None
    world, entities = build(spec)
    mass = torch.tensor([e.mass for e in world.entities]).view(-1, 1, 1)
    v0 = world.stacked_state("vel").clone()
    p0 = (mass * v0).sum(0)
    for _ in range(STEPS):
        world.step()
    v1 = world.stacked_state("vel")
    p1 = (mass * v1).sum(0)
    scale = (mass * v1).abs().sum(0) + (mass * v0).abs().sum(0) + 1e-6
    assert ((p1 - p0).abs() <= 1e-4 * scale + 1e-6).all(), f"momentum moved by {(p1 - p0).abs().max():.4g}"


def test_stiff_joint_outside_the_stable_range_diverges() -> None:
    """Why joint worlds are drawn above a mass floor: a pin between two 1 g spheres at h = 0.05 blows up.

    ``omega h = sqrt(2K/m) h = sqrt(2 * 130 / 0.001) * 0.05 = 25 >> 2``: semi-implicit
    Euler amplifies the joint's oscillation every substep. This test pins down
    that limit (it fails if the engine ever starts damping it, which would be
    worth knowing) and shows the floor used above is on the safe side of it.
    """
    def run(mass: float) -> bool:
        world = World(batch_dim=1, device="cpu", dt=0.1, substeps=2, drag=0.0)
        a = Landmark("a", shape=Sphere(0.05), movable=True, rotatable=False, mass=mass, collide=False)
        b = Landmark("b", shape=Sphere(0.05), movable=True, rotatable=False, mass=mass, collide=False)
        world.add_landmark(a)
        world.add_landmark(b)
        a.set_pos(torch.tensor([[0.0, 0.0]]), batch_index=None)
        b.set_pos(torch.tensor([[0.2, 0.0]]), batch_index=None)
        world.add_joint(Joint(a, b, dist=0.0))
        grew = False
        for _ in range(200):
            world.step()
            state = torch.cat([t.flatten() for t in state_tensors(world)])
            if not torch.isfinite(state).all() or state.abs().max() > 1e6:
                grew = True
                break
        return grew

    assert run(1e-3), "a 1 g pinned pair at h = 0.05 was expected to diverge"
    assert not run(_joint_mass_floor(0.05)), "the mass floor used by the joint strategy must be stable"


def test_free_pin_survives_a_long_spin() -> None:
    """A pin with free rotation must not care how far its bodies have turned (found by the joint property test).

    Two spheres pinned at their centres (``Joint(a, b)``: rotate_a = rotate_b =
    True, so no rotation lock), one spinning at 50 rad/s without drag. After
    about 18 steps its angle passes 88.7 rad, where ``exp`` of the (unused) lock's
    relative angle overflows float32 to inf; the lock is then switched off by
    multiplying with 0, and inf * 0 = NaN, which poisons both bodies. Any wheel,
    rotor or spinning agent on a free pin hits this after ~14 turns.
    """
    world = World(batch_dim=1, device="cpu", dt=0.1, substeps=2, drag=0.0)
    a = Landmark("a", shape=Sphere(0.1), movable=True, rotatable=True, collide=False)
    b = Landmark("b", shape=Sphere(0.1), movable=True, rotatable=True, collide=False)
    world.add_landmark(a)
    world.add_landmark(b)
    world.add_joint(Joint(a, b, dist=0.0))
    b.set_ang_vel(torch.tensor([[50.0]]), batch_index=None)
    for step in range(40):
        world.step()
        for name, value in zip(("pos", "vel", "rot", "ang_vel"), state_tensors(world)):
            assert torch.isfinite(value).all(), f"non-finite {name} after step {step + 1} (b.rot {b.state.rot.item():.1f})"
    # nothing acts on the spin: it keeps its speed exactly, and the pin keeps the centres together
    assert torch.allclose(b.state.ang_vel, torch.tensor([[50.0]]))
