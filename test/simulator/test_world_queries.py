"""World queries (get_distance, is_overlapping) on hand-made layouts."""
from __future__ import annotations

import math

import pytest
import torch

from test.simulator.physics_helpers import (
    T,
    place,
)
from vmas_ros.simulator.core import Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.utils import LINE_MIN_DIST

# ----------------------------------------------------------------- world queries

D = LINE_MIN_DIST


def _query_world(device, shape_a, shape_b, pos_a, pos_b, rot_a=0.0, rot_b=0.0):
    world = World(batch_dim=1, device=device)
    a, b = Landmark("a", shape=shape_a), Landmark("b", shape=shape_b)
    world.add_landmark(a)
    world.add_landmark(b)
    place(a, device, pos=pos_a, rot=rot_a)
    place(b, device, pos=pos_b, rot=rot_b)
    return world, a, b


# (shape a, shape b, pos a, pos b, rot a, rot b, expected distance, overlapping)
QUERIES = {
    "sphere-sphere apart": (Sphere(0.1), Sphere(0.2), (0, 0), (1.0, 0), 0, 0, 0.7, False),
    "sphere-sphere overlap": (Sphere(0.1), Sphere(0.2), (0, 0), (0, 0.25), 0, 0, -0.05, True),
    "sphere-box apart": (Sphere(0.1), Box(0.4, 0.2), (1.0, 0), (0, 0), 0, 0, 0.7 - D, False),
    "sphere-box rotated": (Sphere(0.1), Box(0.4, 0.2), (0, 1.0), (0, 0), 0, math.pi / 2, 0.7 - D, False),
    "sphere-box touching": (Sphere(0.1), Box(0.4, 0.2), (0.25, 0), (0, 0), 0, 0, -1.0, True),
    "sphere inside box": (Sphere(0.01), Box(0.4, 0.4), (0.05, 0), (0, 0), 0, 0, -1.0, True),
    "sphere-line apart": (Sphere(0.1), Line(0.4), (0.5, 0), (0, 0), 0, 0, 0.2 - D, False),
    "sphere-line side": (Sphere(0.1), Line(0.4), (0.1, 0.3), (0, 0), 0, 0, 0.2 - D, False),
    "sphere-line overlap": (Sphere(0.1), Line(0.4), (0.1, 0.05), (0, 0), 0, 0, -0.05 - D, True),
    "line-line parallel": (Line(0.4), Line(0.4), (0, 0), (0, 0.3), 0, 0, 0.3 - D, False),
    "line-line T": (Line(0.4), Line(0.4), (0, 0), (0.5, 0), 0, math.pi / 2, 0.3 - D, False),
    "line-line crossing": (Line(0.4), Line(0.4), (0, 0), (0, 0), 0, math.pi / 2, -D, True),
    "box-line apart": (Box(0.4, 0.2), Line(0.4), (0, 0), (0, 0.5), 0, 0, 0.4 - D, False),
    "box-line crossing": (Box(0.4, 0.2), Line(0.4), (0, 0), (0, 0.1), 0, math.pi / 2, -D, True),
    "box-box apart": (Box(0.4, 0.2), Box(0.2, 0.2), (0, 0), (0.6, 0), 0, 0, 0.3 - D, False),
    "box-box corner": (Box(0.2, 0.2), Box(0.2, 0.2), (0, 0), (0.5, 0.5), 0, 0, math.sqrt(0.18) - D, False),
    "box-box overlap": (Box(0.2, 0.2), Box(0.2, 0.2), (0, 0), (0.15, 0.05), 0, 0, -D, True),
}


@pytest.mark.parametrize("case", list(QUERIES))
def test_get_distance_and_is_overlapping(device, case):
    shape_a, shape_b, pos_a, pos_b, rot_a, rot_b, expected, overlapping = QUERIES[case]
    world, a, b = _query_world(device, shape_a, shape_b, pos_a, pos_b, rot_a, rot_b)
    for first, second in ((a, b), (b, a)):  # symmetric
        dist = world.get_distance(first, second)
        assert dist.shape == (1,)
        assert dist.item() == pytest.approx(expected, abs=1e-5), case
        assert world.is_overlapping(first, second).tolist() == [overlapping], case
        assert world.get_distance(first, second, env_index=0).item() == pytest.approx(expected, abs=1e-5)


def test_queries_are_per_env(device):
    world = World(batch_dim=3, device=device)
    a, b = Landmark("a", shape=Sphere(0.1)), Landmark("b", shape=Box(0.2, 0.2))
    world.add_landmark(a)
    world.add_landmark(b)
    a.set_pos(T([[0.0, 0.0], [0.5, 0.0], [0.05, 0.05]], device), batch_index=None)
    b.set_pos(T([0.0, 0.0], device), batch_index=None)
    assert world.is_overlapping(a, b).tolist() == [True, False, True]
    assert world.get_distance(a, b)[1].item() == pytest.approx(0.5 - 0.1 - 0.1 - D, abs=1e-6)
    torch.testing.assert_close(
        world.get_distance_from_point(a, T([[1.0, 0.0]] * 3, device)),
        T([0.9, 0.4, math.hypot(0.95, 0.05) - 0.1], device),
    )


# ------------------------------------------------------------------ collides
def _pair(world_cls, agent_cls, landmark_cls, shapes, kinds, filters, positions, device):
    """A world of two entities ``a`` and ``b`` built with the given engine's classes."""
    world = world_cls(batch_dim=2, device=device)
    entities = []
    for name, shape, kind, keep, pos in zip("ab", shapes, kinds, filters, positions):
        if kind == "agent":
            entity = agent_cls(name=name, shape=shape)
            world.add_agent(entity)
        else:
            entity = landmark_cls(name=name, shape=shape, collide=kind != "ghost", movable=kind == "movable")
            world.add_landmark(entity)
        if not keep:
            entity.collision_filter = lambda other: False
        entities.append(entity)
    for i, (entity, pos) in enumerate(zip(entities, positions)):  # env 1: far apart
        entity.set_pos(torch.tensor([pos, [5.0 * i, 5.0]], device=device, dtype=torch.float32), batch_index=None)
    return world, entities


# (shape kinds, entity kinds (agent / static / movable / ghost: no collide), filters keep?, positions, expected)
COLLIDES = {
    "agents near": (("sphere", "sphere"), ("agent", "agent"), (True, True), ((0, 0), (0.15, 0)), True),
    "agents far": (("sphere", "sphere"), ("agent", "agent"), (True, True), ((0, 0), (0.3, 0.1)), False),
    "agent and wall": (("sphere", "line"), ("agent", "static"), (True, True), ((0, 0), (0.1, 0)), True),
    "two walls": (("line", "line"), ("static", "static"), (True, True), ((0, 0), (0.1, 0)), False),
    "ghost landmark": (("sphere", "box"), ("agent", "ghost"), (True, True), ((0, 0), (0.1, 0)), False),
    "filtered out": (("sphere", "sphere"), ("agent", "agent"), (True, False), ((0, 0), (0.1, 0)), False),
    "box and box": (("box", "box"), ("agent", "movable"), (True, True), ((0, 0), (0.2, 0.2)), True),
}


def _shape(kind, module):
    return {"sphere": lambda: module.Sphere(0.1), "line": lambda: module.Line(0.4), "box": lambda: module.Box(0.2, 0.2)}[kind]()


@pytest.mark.parametrize("case", list(COLLIDES))
def test_collides_matches_vmas(device, case):
    """``World.collides`` answers as VMAS 1.5's does (collide flags, filters, static pairs, reach in any env)."""
    import vmas.simulator.core as upstream

    from vmas_ros.simulator import core as ours

    kinds, roles, filters, positions, expected = COLLIDES[case]
    answers = []
    for module in (ours, upstream):
        shapes = [_shape(k, module) for k in kinds]
        world, (a, b) = _pair(module.World, module.Agent, module.Landmark, shapes, roles, filters, positions, device)
        answers.append((world.collides(a, b), world.collides(b, a), world.collides(a, a)))
    assert answers[0] == answers[1] == (expected, expected, False), answers
