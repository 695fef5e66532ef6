"""Joints hold their geometry: rods keep their length, pins keep anchors together."""
from __future__ import annotations

import math

import pytest

from test.simulator.physics_helpers import (
    DT,
    T,
    all_finite,
)
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.joints import Joint

# ------------------------------------------------------------------------- joints


def _jointed_pair(device, dist, anchor_a=(0.0, 0.0), anchor_b=(0.0, 0.0)):
    world = World(batch_dim=1, device=device, dt=DT, substeps=5, drag=0.25)
    a = Agent("a", shape=Sphere(0.05), rotatable=True)
    b = Agent("b", shape=Sphere(0.05), rotatable=True)
    world.add_agent(a)
    world.add_agent(b)
    world.add_joint(Joint(a, b, anchor_a=anchor_a, anchor_b=anchor_b, dist=dist))
    gap = dist + a.shape.get_delta_from_anchor(anchor_a)[0] - b.shape.get_delta_from_anchor(anchor_b)[0]
    a.set_pos(T([-gap / 2, 0.0], device), batch_index=None)
    b.set_pos(T([gap / 2, 0.0], device), batch_index=None)
    return world, a, b


def _anchor_gap(world, a, b):
    constraint_a = world.joints[0] if len(world.joints) == 1 else None
    if constraint_a is not None:
        return (constraint_a.pos_point(a) - constraint_a.pos_point(b)).norm(dim=-1)
    rod_a, rod_b = world.joints
    return (rod_a.pos_point(a) - rod_b.pos_point(b)).norm(dim=-1)


@pytest.mark.parametrize("direction", [1.0, -1.0], ids=["pulled-apart", "pushed-together"])
def test_rod_joint_holds_its_length(device, direction):
    d, pull = 0.5, 0.5
    world, a, b = _jointed_pair(device, d)
    assert len(world.landmarks) == 1 and world.landmarks[0].shape.length == d
    gaps = []
    for step in range(200):
        # opposite actions along the rod (with a sideways wobble so the rod also turns)
        side = 0.5 * math.sin(step / 10)
        a.state.force = T([[-pull * direction, side]], device)
        b.state.force = T([[pull * direction, -side]], device)
        world.step()
        assert all_finite(world)
        gaps.append(float(_anchor_gap(world, a, b)))
    assert max(abs(g - d) for g in gaps) <= 0.05 * d, f"rod length drifted: min {min(gaps)}, max {max(gaps)}"
    assert abs(float(world.landmarks[0].state.rot)) > 0.05, "the sideways push should have turned the rod"


@pytest.mark.parametrize("direction", [1.0, -1.0], ids=["pulled-apart", "pushed-together"])
def test_rod_joint_stretches_like_two_springs_in_series(device, direction):
    """Steady pull F on a rod pinned at both ends by springs of stiffness k: length d + 2 F / k."""
    d, pull = 0.5, 0.5
    world, a, b = _jointed_pair(device, d)
    for _ in range(200):
        a.state.force = T([[-pull * direction, 0.0]], device)
        b.state.force = T([[pull * direction, 0.0]], device)
        world.step()
    stretch = float(_anchor_gap(world, a, b)) - d
    assert stretch == pytest.approx(direction * 2 * pull / world.joint_force, rel=0.05)
    # nothing sideways: the chain stays on the x axis and does not turn
    assert float(a.state.pos[0, 1].abs()) < 1e-6 and float(world.landmarks[0].state.rot.abs()) < 1e-6


def test_pin_joint_keeps_anchors_together(device):
    world, a, b = _jointed_pair(device, 0.0, anchor_a=(1.0, 0.0), anchor_b=(-1.0, 0.0))
    assert world.landmarks == [], "a dist-0 joint carries no rod"
    constraint = world.joints[0]
    pull = 1.0
    gaps = []
    for _ in range(200):
        a.state.force = T([[-pull, 0.3]], device)
        b.state.force = T([[pull, 0.3]], device)
        world.step()
        assert all_finite(world)
        gaps.append(float((constraint.pos_point(a) - constraint.pos_point(b)).norm()))
    # the pin is a spring of stiffness k = joint_force: at rest it parts by F / k; a suddenly
    # applied load overshoots to at most twice that (plus the soft model's margin)
    k = world.joint_force
    assert max(gaps) < 2 * pull / k + 2 * world.contact_margin, f"pinned anchors separated by {max(gaps)}"
    assert gaps[-1] == pytest.approx(pull / k, rel=0.1)
    # and the pair as a whole moved up under the common sideways force
    assert float(a.state.pos[0, 1]) > 0.1 and float(b.state.pos[0, 1]) > 0.1


def test_joints_need_substeps(device):
    world = World(batch_dim=1, device=device, substeps=1)
    a, b = Agent("a"), Agent("b")
    world.add_agent(a)
    world.add_agent(b)
    with pytest.raises(ValueError, match="substeps"):
        world.add_joint(Joint(a, b, dist=0.2))
