"""First-principles physics of the engine: free motion, contacts, torques and limits.

Every expected value is derived by hand: each test builds a tiny World, steps it
and compares with a closed form or a conservation law. Parity with upstream VMAS
is covered by test_parity.py; here the oracle is the physics itself.
"""
from __future__ import annotations

import math

import pytest
import torch

from test.simulator.physics_helpers import (
    DT,
    T,
    all_finite,
    angular_momentum,
    body,
    make_shape,
    momentum,
    place,
)
from vmas_ros.simulator import physics
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.physics.collision import pair_forces
from vmas_ros.simulator.utils import LINE_MIN_DIST, TorchUtils

# --------------------------------------------------------------------- free motion


@pytest.mark.parametrize("substeps", [1, 4])
def test_free_body_under_drag_follows_geometric_series(device, substeps):
    drag, n = 0.2, 12
    world = World(batch_dim=2, device=device, dt=DT, substeps=substeps, drag=drag)
    ball = Landmark("ball", shape=Sphere(0.05), movable=True, rotatable=True, collide=False)
    world.add_landmark(ball)
    x0, v0, w0 = T([0.3, -0.2], device), T([1.5, -0.5], device), 2.0
    place(ball, device, pos=x0.tolist(), vel=v0.tolist(), ang_vel=w0)
    for _ in range(n):
        world.step()
    keep = 1 - drag
    # drag acts once per step, on the first substep: v_k = v0 (1 - drag)^k
    torch.testing.assert_close(ball.state.vel, (v0 * keep**n).expand(2, 2), rtol=1e-5, atol=1e-7)
    torch.testing.assert_close(ball.state.ang_vel, torch.full((2, 1), w0 * keep**n, device=device), rtol=1e-5, atol=1e-7)
    # within a step the velocity is constant, so x_n = x0 + dt v0 sum_{k=1..n} (1 - drag)^k
    geometric = keep * (1 - keep**n) / drag
    torch.testing.assert_close(ball.state.pos, (x0 + DT * v0 * geometric).expand(2, 2), rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(ball.state.rot, torch.full((2, 1), DT * w0 * geometric, device=device), rtol=1e-5, atol=1e-6)


def test_entity_drag_overrides_world_drag(device):
    world = World(batch_dim=1, device=device, drag=0.25)
    fast = Landmark("own_drag", shape=Sphere(0.05), movable=True, collide=False, drag=0.5)
    slow = Landmark("world_drag", shape=Sphere(0.05), movable=True, collide=False)
    world.add_landmark(fast)
    world.add_landmark(slow)
    place(fast, device, vel=(1.0, 0.0))
    place(slow, device, pos=(1.0, 0.0), vel=(1.0, 0.0))
    for _ in range(3):
        world.step()
    assert fast.state.vel[0, 0].item() == pytest.approx(0.5**3, rel=1e-6)
    assert slow.state.vel[0, 0].item() == pytest.approx(0.75**3, rel=1e-6)


@pytest.mark.parametrize("substeps", [1, 3])
@pytest.mark.parametrize("mass", [1.0, 2.5])
def test_constant_force_semi_implicit_euler(device, substeps, mass):
    n = 7
    world = World(batch_dim=1, device=device, dt=DT, substeps=substeps, drag=0.0)
    agent = Agent("a", shape=Sphere(0.05), mass=mass, collide=False)
    world.add_agent(agent)
    x0, v0, force = T([0.1, 0.2], device), T([0.3, -0.4], device), T([0.7, -1.3], device)
    place(agent, device, pos=x0.tolist(), vel=v0.tolist())
    for _ in range(n):
        agent.state.force = force.reshape(1, 2).clone()
        world.step()
    h, N = DT / substeps, n * substeps
    acc = force / mass
    # v_j = v_{j-1} + a h ; x_j = x_{j-1} + v_j h  =>  x_N = x0 + v0 N h + a h^2 N (N + 1) / 2
    torch.testing.assert_close(agent.state.vel[0], v0 + acc * h * N, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(agent.state.pos[0], x0 + v0 * N * h + acc * h * h * N * (N + 1) / 2, rtol=1e-5, atol=1e-6)


def test_gravity_accelerates_independently_of_mass(device):
    g_world, g_own = (0.0, -2.0), (0.5, 0.0)
    world = World(batch_dim=1, device=device, dt=DT, substeps=2, drag=0.0, gravity=g_world)
    light = Landmark("light", shape=Sphere(0.05), movable=True, collide=False, mass=0.5)
    heavy = Landmark("heavy", shape=Sphere(0.05), movable=True, collide=False, mass=8.0)
    light_own = Landmark("light_own", shape=Sphere(0.05), movable=True, collide=False, mass=0.5, gravity=g_own)
    heavy_own = Landmark("heavy_own", shape=Sphere(0.05), movable=True, collide=False, mass=8.0, gravity=g_own)
    pinned = Landmark("pinned", shape=Sphere(0.05), movable=False, collide=False, mass=3.0)
    for e in (light, heavy, light_own, heavy_own, pinned):
        world.add_landmark(e)
    n, substeps = 5, 2
    for _ in range(n):
        world.step()
    h, N = DT / substeps, n * substeps
    for e, g in ((light, g_world), (heavy, g_world), (light_own, (0.5, -2.0)), (heavy_own, (0.5, -2.0))):
        g = T(g, device)
        torch.testing.assert_close(e.state.vel[0], g * h * N, rtol=1e-5, atol=1e-6, msg=e.name)
        torch.testing.assert_close(e.state.pos[0], g * h * h * N * (N + 1) / 2, rtol=1e-5, atol=1e-6, msg=e.name)
    assert torch.equal(pinned.state.pos, torch.zeros(1, 2, device=device))
    assert torch.equal(pinned.state.vel, torch.zeros(1, 2, device=device))


def test_rotation_integrates_torque_with_moment_of_inertia(device):
    world = World(batch_dim=1, device=device, dt=DT, substeps=1, drag=0.0)
    agent = Agent("spinner", shape=Box(length=0.4, width=0.2), mass=3.0, collide=False)
    world.add_agent(agent)
    inertia = 3.0 * (0.4**2 + 0.2**2) / 12
    assert agent.moment_of_inertia == pytest.approx(inertia)
    for _ in range(4):
        agent.state.torque = T([[0.05]], device)
        world.step()
    alpha = 0.05 / inertia
    assert agent.state.ang_vel.item() == pytest.approx(alpha * DT * 4, rel=1e-5)
    assert agent.state.rot.item() == pytest.approx(alpha * DT * DT * 10, rel=1e-5)
    torch.testing.assert_close(agent.state.pos, torch.zeros(1, 2, device=device))


# ----------------------------------------------------------- contacts: Newton's third law

# (kind a, kind b, pos a, pos b, rot a, rot b): every pair in contact, none symmetric.
# Outlines must not cross: crossing outlines have zero closest distance, where the
# soft contact model (as in VMAS) switches off.
CONTACTS = {
    "sphere-sphere": ("sphere", "sphere", (0.0, 0.0), (0.15, 0.04), 0.0, 0.0),
    "sphere-box": ("sphere", "box", (0.0, 0.17), (0.03, 0.0), 0.0, 0.3),
    # b's corner (-0.15, -0.1) turned to point along -x, 3 mm from a's right face
    "box-box": ("box", "box", (0.0, 0.0), (0.15 + math.hypot(0.15, 0.1) + 0.003, 0.02), 0.0, -math.atan2(0.1, 0.15)),
    "line-sphere": ("line", "sphere", (0.0, 0.0), (0.12, 0.08), 0.1, 0.0),
    "line-line": ("line", "line", (0.0, 0.0), (0.1, 0.005), 0.0, 0.01),
    "box-line": ("box", "line", (0.0, 0.0), (0.0, 0.104), 0.0, 0.01),
}


def _contact_world(device, case, drag=0.0, substeps=1, batch_dim=1):
    kind_a, kind_b, pos_a, pos_b, rot_a, rot_b = CONTACTS[case]
    world = World(batch_dim=batch_dim, device=device, dt=DT, substeps=substeps, drag=drag)
    a = body("a", make_shape(kind_a), mass=1.0)
    b = body("b", make_shape(kind_b), mass=3.0)
    world.add_landmark(a)
    world.add_landmark(b)
    place(a, device, pos=pos_a, rot=rot_a, vel=(0.05, -0.02))
    place(b, device, pos=pos_b, rot=rot_b, vel=(-0.1, 0.03))
    return world, a, b


@pytest.mark.parametrize("case", list(CONTACTS))
def test_pair_forces_are_equal_and_opposite(device, case):
    world, a, b = _contact_world(device, case)
    tables = world.tables
    assert len(tables.pairs) == 1
    pair = tables.pairs[0]
    state = physics.BodyState(
        pos=torch.stack([e.state.pos for e in world.entities]),
        vel=torch.stack([e.state.vel for e in world.entities]),
        rot=torch.stack([e.state.rot for e in world.entities]),
        ang_vel=torch.stack([e.state.ang_vel for e in world.entities]),
    )
    f_a, f_b, t_a, t_b = pair_forces(pair, state, world._step_params())
    assert float(f_a.norm()) > 1e-3, "the configuration must actually be in contact"
    assert torch.equal(f_a, -f_b)
    # the two forces act along one line: torques about the origin cancel (angular momentum)
    ia, ib = pair.index_a, pair.index_b
    r_a, r_b = state.pos[ia], state.pos[ib]
    total_torque = TorchUtils.cross(r_a, f_a) + TorchUtils.cross(r_b, f_b) + t_a + t_b
    assert float(total_torque.abs().max()) < 1e-5 * float(f_a.norm())


@pytest.mark.parametrize("substeps", [1, 4])
@pytest.mark.parametrize("case", list(CONTACTS))
def test_contacts_conserve_momentum(device, case, substeps):
    world, a, b = _contact_world(device, case, drag=0.0, substeps=substeps)
    p0, l0 = momentum([a, b]), angular_momentum([a, b])
    va0, vb0 = a.state.vel.clone(), b.state.vel.clone()
    for _ in range(10):
        world.step()
    # velocity changes are opposite, scaled by mass: m_a dv_a = -m_b dv_b
    dpa = a.mass * (a.state.vel - va0)
    dpb = b.mass * (b.state.vel - vb0)
    assert float(dpa.norm()) > 1e-3, "the bodies must have pushed each other"
    torch.testing.assert_close(dpa, -dpb, atol=1e-6, rtol=0)
    torch.testing.assert_close(momentum([a, b]), p0, atol=1e-6, rtol=0)
    # symplectic Euler with central contact forces also conserves angular momentum exactly
    torch.testing.assert_close(angular_momentum([a, b]), l0, atol=1e-5, rtol=0)


# ----------------------------------------------------------------- deep overlap


def _max_force_bound(world, a, b):
    """Largest contact force the soft model can produce for this pair.

    penetration = k log(1 + exp((d_min - d) / k)) <= d_min + k ln 2 (d >= 0) and
    d_min <= r_a + r_b + LINE_MIN_DIST (a solid box's inner depth is at most its
    circumscribed radius).
    """
    d_min = a.shape.circumscribed_radius() + b.shape.circumscribed_radius() + LINE_MIN_DIST
    return world.collision_force * (d_min + world.contact_margin * math.log(2))


DEEP = {
    "spheres-same-centre": (Sphere(0.1), Sphere(0.1), (0.0, 0.0), (0.0, 0.0)),
    "spheres-99pct": (Sphere(0.1), Sphere(0.1), (0.0, 0.0), (0.002, 0.0)),
    "small-sphere-in-big": (Sphere(0.3), Sphere(0.05), (0.0, 0.0), (0.01, 0.01)),
    "sphere-in-box": (Box(0.4, 0.4), Sphere(0.05), (0.0, 0.0), (0.01, -0.02)),
    "box-inside-box": (Box(0.5, 0.4), Box(0.1, 0.1), (0.0, 0.0), (0.02, 0.01)),
    "same-boxes-same-centre": (Box(0.3, 0.2), Box(0.3, 0.2), (0.0, 0.0), (0.0, 0.0)),
    "line-through-box": (Box(0.3, 0.3), Line(0.5), (0.0, 0.0), (0.0, 0.01)),
}


@pytest.mark.parametrize("case", list(DEEP))
def test_deep_overlap_does_not_explode(device, case):
    shape_a, shape_b, pos_a, pos_b = DEEP[case]
    drag = 0.25
    world = World(batch_dim=1, device=device, dt=DT, substeps=2, drag=drag)
    a, b = body("a", shape_a, mass=1.0), body("b", shape_b, mass=1.0)
    world.add_landmark(a)
    world.add_landmark(b)
    place(a, device, pos=pos_a)
    place(b, device, pos=pos_b, rot=0.3 if case == "box-inside-box" else 0.0)
    f_max = _max_force_bound(world, a, b)
    # v_{n+1} <= (1 - drag) v_n + f_max / m * dt  =>  v <= f_max dt / (m drag), from rest
    v_bound = f_max * DT / (1.0 * drag)
    w_bound = [f_max * e.shape.circumscribed_radius() * DT / (e.moment_of_inertia * drag) for e in (a, b)]
    for _ in range(100):
        world.step()
        assert all_finite(world)
        for e, wb in zip((a, b), w_bound):
            assert float(e.state.vel.norm(dim=-1).max()) <= v_bound
            assert float(e.state.ang_vel.abs().max()) <= wb
    # nothing flew off: total momentum stays zero, so the centre of mass stays put
    com0 = (torch.tensor(pos_a) + torch.tensor(pos_b)) / 2
    com = (a.state.pos + b.state.pos).cpu() / 2
    torch.testing.assert_close(com[0], com0, atol=1e-5, rtol=0)


def test_partial_overlap_separates_spheres(device):
    world = World(batch_dim=1, device=device, dt=DT, substeps=2, drag=0.25)
    a, b = body("a", Sphere(0.1)), body("b", Sphere(0.1))
    world.add_landmark(a)
    world.add_landmark(b)
    place(a, device, pos=(0.0, 0.0))
    place(b, device, pos=(0.002, 0.0))
    for _ in range(100):
        world.step()
    gap = float((a.state.pos - b.state.pos).norm())
    assert gap > 0.19, f"99% overlapping spheres should be pushed to touching distance, gap {gap}"
    assert a.state.pos[0, 0] < 0 < b.state.pos[0, 0]
    assert abs(float(a.state.pos[0, 1])) < 1e-6 and abs(float(b.state.pos[0, 1])) < 1e-6


# ----------------------------------------------------------------------- torques


@pytest.mark.parametrize("end,expected_sign", [(1.0, -1.0), (-1.0, 1.0)])
def test_sphere_hitting_end_of_line_spins_it(device, end, expected_sign):
    """A ball falling on the right end of a pivoted bar turns it clockwise (left end: counter-clockwise)."""
    world = World(batch_dim=1, device=device, dt=DT, substeps=2, drag=0.0)
    bar = body("bar", Line(length=1.0), movable=False, rotatable=True)
    ball = body("ball", Sphere(0.05), rotatable=False)
    world.add_landmark(bar)
    world.add_landmark(ball)
    place(bar, device)
    place(ball, device, pos=(0.45 * end, 0.08), vel=(0.0, -0.5))
    for _ in range(10):
        world.step()
    w = float(bar.state.ang_vel)
    assert w * expected_sign > 1e-3, f"bar should spin with sign {expected_sign}, got ang_vel {w}"
    assert float(bar.state.rot) * expected_sign > 0
    assert torch.equal(bar.state.pos, torch.zeros(1, 2, device=device)), "a non-movable bar must not translate"


@pytest.mark.parametrize("offset,expected_sign", [(0.07, -1.0), (-0.07, 1.0), (0.0, 0.0)])
def test_box_pushed_off_centre_rotates(device, offset, expected_sign):
    """A ball hitting the left face above the centre turns the box clockwise; head-on, it does not turn."""
    world = World(batch_dim=1, device=device, dt=DT, substeps=2, drag=0.0)
    box = body("box", Box(length=0.4, width=0.2), mass=1.0)
    ball = body("ball", Sphere(0.05), mass=1.0, rotatable=False)
    world.add_landmark(box)
    world.add_landmark(ball)
    place(box, device)
    place(ball, device, pos=(-0.3, offset), vel=(1.0, 0.0))
    for _ in range(10):
        world.step()
    assert float(box.state.vel[0, 0]) > 0.1, "the box must have been pushed"
    w = float(box.state.ang_vel)
    if expected_sign == 0:
        assert abs(w) < 1e-6
    else:
        assert w * expected_sign > 1e-2, f"box should spin with sign {expected_sign}, got {w}"



# --------------------------------------------------------------- limits and flags


def test_non_movable_entities_never_move(device):
    world = World(batch_dim=2, device=device, dt=DT, substeps=2, drag=0.1)
    wall = Landmark("wall", shape=Box(0.1, 1.0), movable=False, rotatable=False)
    post = Landmark("post", shape=Sphere(0.1), movable=False, rotatable=True)
    rammer = Agent("rammer", shape=Sphere(0.1))
    pinned = Agent("pinned", shape=Sphere(0.05), movable=False)
    for e in (wall, post):
        world.add_landmark(e)
    world.add_agent(rammer)
    world.add_agent(pinned)
    place(wall, device, pos=(0.3, 0.0))
    place(post, device, pos=(-0.3, 0.0))
    place(rammer, device, vel=(0.0, 0.0))
    place(pinned, device, pos=(0.0, -0.8))
    for step in range(60):
        rammer.state.force = T([[3.0, 0.0], [-3.0, 0.0]], device)
        pinned.state.force = T([[1.0, 1.0], [-1.0, 0.5]], device)
        world.step()
    for e, pos in ((wall, (0.3, 0.0)), (post, (-0.3, 0.0)), (pinned, (0.0, -0.8))):
        torch.testing.assert_close(e.state.pos, T([pos, pos], device), atol=0, rtol=0, msg=e.name)
        assert not e.state.vel.any(), e.name
    # the rammer was stopped by the wall (env 0) and the post (env 1), not passing through
    assert float(rammer.state.pos[0, 0]) < 0.3 - 0.05
    assert float(rammer.state.pos[1, 0]) > -0.3


def test_non_rotatable_entities_never_rotate(device):
    world = World(batch_dim=1, device=device, dt=DT, substeps=2, drag=0.0)
    fixed = body("fixed", Box(0.4, 0.2), rotatable=False)
    free = body("free", Box(0.4, 0.2), rotatable=True)
    ball_1, ball_2 = body("ball_1", Sphere(0.05)), body("ball_2", Sphere(0.05))
    for e in (fixed, free, ball_1, ball_2):
        world.add_landmark(e)
    place(fixed, device, pos=(0.0, 1.0))
    place(free, device, pos=(0.0, -1.0))
    place(ball_1, device, pos=(-0.3, 1.07), vel=(1.0, 0.0))
    place(ball_2, device, pos=(-0.3, -0.93), vel=(1.0, 0.0))
    for _ in range(10):
        world.step()
    assert float(fixed.state.vel[0, 0]) > 0.1
    assert float(fixed.state.rot) == 0.0 and float(fixed.state.ang_vel) == 0.0
    assert abs(float(free.state.ang_vel)) > 1e-2, "the control box (rotatable) must spin"


def test_max_speed_caps_the_speed(device):
    world = World(batch_dim=1, device=device, dt=DT, drag=0.0)
    agent = Agent("fast", shape=Sphere(0.05), max_speed=0.3, collide=False)
    world.add_agent(agent)
    speeds = []
    for _ in range(20):
        agent.state.force = T([[3.0, 4.0]], device)
        world.step()
        speeds.append(float(agent.state.vel.norm()))
    assert max(speeds) <= 0.3 + 1e-6
    assert speeds[-1] == pytest.approx(0.3, rel=1e-5)
    # the direction is kept: (3, 4) / 5
    torch.testing.assert_close(agent.state.vel[0], T([0.18, 0.24], device), atol=1e-6, rtol=0)


def test_v_range_caps_each_component(device):
    world = World(batch_dim=1, device=device, dt=DT, drag=0.0)
    agent = Agent("fast", shape=Sphere(0.05), v_range=0.2, collide=False)
    world.add_agent(agent)
    for _ in range(20):
        agent.state.force = T([[5.0, -1.0]], device)
        world.step()
        assert float(agent.state.vel.abs().max()) <= 0.2 + 1e-7
    # x saturates at 0.2, y (a = -1) reaches -0.2 after 2 s
    torch.testing.assert_close(agent.state.vel[0], T([0.2, -0.2], device), atol=1e-6, rtol=0)


def test_semidims_bound_positions(device):
    world = World(batch_dim=2, device=device, dt=DT, drag=0.0, x_semidim=0.5, y_semidim=0.25)
    agent = Agent("runner", shape=Sphere(0.05), collide=False)
    world.add_agent(agent)
    for _ in range(40):
        agent.state.force = T([[2.0, 2.0], [-2.0, -2.0]], device)
        world.step()
        assert float(agent.state.pos[:, 0].abs().max()) <= 0.5
        assert float(agent.state.pos[:, 1].abs().max()) <= 0.25
    torch.testing.assert_close(agent.state.pos, T([[0.5, 0.25], [-0.5, -0.25]], device))


def test_action_force_limits(device):
    world = World(batch_dim=1, device=device, dt=DT, drag=0.0)
    capped = Agent("capped", shape=Sphere(0.05), collide=False, max_f=1.0)
    ranged = Agent("ranged", shape=Sphere(0.05), collide=False, f_range=0.5)
    world.add_agent(capped)
    world.add_agent(ranged)
    capped.state.force = T([[3.0, 4.0]], device)
    ranged.state.force = T([[3.0, -0.25]], device)
    world.step()
    torch.testing.assert_close(capped.state.vel[0], T([0.06, 0.08], device), atol=1e-7, rtol=0)
    torch.testing.assert_close(ranged.state.vel[0], T([0.05, -0.025], device), atol=1e-7, rtol=0)
    # the clamped force is written back, as in VMAS
    torch.testing.assert_close(capped.state.force[0], T([0.6, 0.8], device), atol=1e-7, rtol=0)


# ----------------------------------------------------------------- contact magnitude
def test_softplus_of_overlap_matches_logaddexp_where_contacts_are_active():
    """The fast contact magnitude equals ``log(1 + exp(x))`` to float rounding for every ``x >= 0``
    (active contacts), is finite below 0 (masked out later), and has the same gradient."""
    from vmas_ros.simulator.physics.collision.contact import softplus_of_overlap

    x = torch.linspace(0, 60, 200_001)
    exact = torch.logaddexp(torch.zeros(()), x.double()).float()
    torch.testing.assert_close(softplus_of_overlap(x.clone()), exact, rtol=2.5e-7, atol=0)
    assert torch.isfinite(softplus_of_overlap(torch.tensor([-1e6, -200.0, -1.0]))).all()
    xg = torch.linspace(0, 30, 301, requires_grad=True)
    softplus_of_overlap(xg).sum().backward()
    torch.testing.assert_close(xg.grad, torch.sigmoid(xg.detach()), rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("batch", [1, 40])
def test_pair_scatter_by_gemm_equals_index_add(batch, device, monkeypatch):
    """Pair forces added through the dense incidence GEMM, or its product summed over the pairs, equal the
    index_add scatter to rounding."""
    from vmas_ros.simulator.physics import scatter
    from vmas_ros.simulator.tables import PairTable

    gen = torch.Generator().manual_seed(7)
    n = 7
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)] + [(0, 1)]  # a repeated pair sums twice
    table = PairTable(("sphere", "sphere"), torch.tensor([i for i, _ in pairs], device=device),
                      torch.tensor([j for _, j in pairs], device=device))
    on_a = torch.randn(2, len(pairs), batch, generator=gen).to(device)
    start = torch.randn(2, n, batch, generator=gen).to(device)
    results = []
    for cells in (0, scatter.GEMM_SCATTER_MAX_CELLS):
        monkeypatch.setattr(scatter, "GEMM_SCATTER_MAX_CELLS", cells)
        monkeypatch.setattr(torch, "get_num_threads", lambda: 2)
        force = start.clone()
        scatter.add_pairs_opposite(force, table, on_a)
        results.append(force)
    # as a compiled step traces it: the product summed over the pairs at one env, the GEMM at 40
    from vmas_ros.simulator.tracing import traced

    with traced():
        force = start.clone()
        scatter.add_pairs_opposite(force, table, on_a)
    results.append(force)
    assert (len(pairs) * n * batch <= scatter.SUMMED_SCATTER_MAX_ELEMENTS) == (batch == 1)
    expected = start.clone()
    for p, (i, j) in enumerate(pairs):
        expected[:, i] += on_a[:, p]
        expected[:, j] -= on_a[:, p]
    for got in results:
        torch.testing.assert_close(got, expected, rtol=1e-5, atol=1e-5)
    assert scatter.scatter_by_gemm(n, len(pairs), batch)
    assert not scatter.scatter_by_gemm(n, scatter.GEMM_SCATTER_MAX_CELLS, batch), "too large for a dense matrix"
    # a few pairs over many envs: index_add_ (as fast, without the BLAS kernel's resident code); at a few envs the GEMM
    few = scatter.GEMM_SCATTER_MIN_PAIRS - 1
    assert scatter.scatter_by_gemm(n, few, batch) == (batch < scatter.SCATTER_TRANSPOSE_BELOW)


def test_no_dense_incidence_beyond_the_gemm_cap(device):
    """Worlds with more (entity, pair) cells than a GEMM scatter may use build no dense incidence matrix
    (1,000 spheres once allocated 6 GB of them at the first step); small ones build theirs up front."""
    from vmas_ros.simulator.core import Agent, Sphere, World
    from vmas_ros.simulator.thresholds import GEMM_SCATTER_MAX_CELLS

    def stepped(n):
        world = World(batch_dim=2, device=device)
        for i in range(n):
            world.add_agent(Agent(name=f"s{i}", shape=Sphere(0.05)))
        world.reset(None)
        world.step()
        return world.tables.pairs[0]

    big = stepped(60)
    assert 60 * len(big.index_a) > GEMM_SCATTER_MAX_CELLS
    assert not big.__dict__.get("_incidence")
    small = stepped(4)
    assert set(small.__dict__["_incidence"]) == {(4, torch.float32), ("opposite", 4, torch.float32)}
    first, second = small.incidence_ab(4, torch.float32)
    assert first.shape == (4, 6) and torch.equal(first.sum(0), torch.ones(6)) and torch.equal(second.sum(0), torch.ones(6))
    assert torch.equal(first.argmax(0).cpu(), small.index_a.cpu()) and torch.equal(second.argmax(0).cpu(), small.index_b.cpu())
