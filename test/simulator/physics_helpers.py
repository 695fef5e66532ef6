"""Small builders shared by the first-principles engine tests."""
from __future__ import annotations

import torch

from vmas_ros.simulator.core import Box, Landmark, Line, Sphere

DT = 0.1


def T(values, device):
    return torch.tensor(values, dtype=torch.float32, device=device)


def place(entity, device, pos=(0.0, 0.0), vel=(0.0, 0.0), rot=0.0, ang_vel=0.0):
    """Write one state into every env of the entity's world."""
    entity.set_pos(T(pos, device), batch_index=None)
    entity.set_vel(T(vel, device), batch_index=None)
    entity.set_rot(T([rot], device), batch_index=None)
    entity.set_ang_vel(T([ang_vel], device), batch_index=None)


def body(name, shape, mass=1.0, movable=True, rotatable=True, **kwargs):
    return Landmark(name=name, shape=shape, movable=movable, rotatable=rotatable, mass=mass, collide=True, **kwargs)


def make_shape(kind):
    return {
        "sphere": lambda: Sphere(radius=0.1),
        "box": lambda: Box(length=0.3, width=0.2),
        "line": lambda: Line(length=0.4),
    }[kind]()


def momentum(entities):
    return sum(e.mass * e.state.vel for e in entities)


def angular_momentum(entities):
    """About the world origin: sum of m (r x v) + I w, per env [B]."""
    total = 0.0
    for e in entities:
        r, v = e.state.pos, e.state.vel
        total = total + e.mass * (r[:, 0] * v[:, 1] - r[:, 1] * v[:, 0]) + e.moment_of_inertia * e.state.ang_vel[:, 0]
    return total


def all_finite(world):
    return all(
        bool(torch.isfinite(getattr(e.state, f)).all()) for e in world.entities for f in ("pos", "vel", "rot", "ang_vel")
    )
