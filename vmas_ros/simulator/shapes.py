"""Collision shapes: the static geometry an entity carries.

A shape is a few floats; it never holds tensors. The world turns the shapes of
all its entities into per-entity property tables once, so the step never asks
a shape anything.
"""
from __future__ import annotations

import math
from typing import Tuple

__all__ = ["Shape", "Sphere", "Box", "Line"]


class Shape:
    """Base class of the three shape kinds (sphere, box, line)."""

    #: short name used by the collision dispatch table
    kind: str = "shape"

    def moment_of_inertia(self, mass: float) -> float:
        raise NotImplementedError(f"{type(self).__name__} must define its inertia")

    def get_delta_from_anchor(self, anchor: Tuple[float, float]) -> Tuple[float, float]:
        """Offset in the body frame of a point given in normalised [-1, 1] anchor units."""
        raise NotImplementedError(f"{type(self).__name__} must define anchors")

    def circumscribed_radius(self) -> float:
        raise NotImplementedError(f"{type(self).__name__} must define its bounding radius")

    def get_geometry(self):
        """A renderable geom of this shape centred at the origin (see simulator.rendering)."""
        from vmas_ros.simulator import rendering

        return rendering.shape_geom(self)


class Sphere(Shape):
    """A disc of ``radius`` (the world is 2D; the name follows VMAS)."""

    kind = "sphere"

    def __init__(self, radius: float = 0.05):
        if not radius > 0:
            raise ValueError(f"Sphere radius must be > 0, got {radius}")
        self.radius = float(radius)

    def moment_of_inertia(self, mass: float) -> float:
        return (1 / 2) * mass * self.radius**2

    def get_delta_from_anchor(self, anchor: Tuple[float, float]) -> Tuple[float, float]:
        dx, dy = anchor[0] * self.radius, anchor[1] * self.radius
        norm = math.hypot(dx, dy)
        if norm > self.radius:
            # keep the anchor on the rim when a diagonal anchor would leave the disc
            dx, dy = dx * self.radius / norm, dy * self.radius / norm
        return dx, dy

    def circumscribed_radius(self) -> float:
        return self.radius

    def __repr__(self) -> str:
        return f"Sphere(radius={self.radius})"


class Box(Shape):
    """A rectangle: ``length`` along the body x axis, ``width`` along body y.

    A ``hollow`` box only pushes from its outline, so entities can live inside it.
    """

    kind = "box"

    def __init__(self, length: float = 0.3, width: float = 0.1, hollow: bool = False):
        if not length > 0:
            raise ValueError(f"Box length must be > 0, got {length}")
        if not width > 0:
            raise ValueError(f"Box width must be > 0, got {width}")
        self.length = float(length)
        self.width = float(width)
        self.hollow = bool(hollow)

    def moment_of_inertia(self, mass: float) -> float:
        return (1 / 12) * mass * (self.length**2 + self.width**2)

    def get_delta_from_anchor(self, anchor: Tuple[float, float]) -> Tuple[float, float]:
        return anchor[0] * self.length / 2, anchor[1] * self.width / 2

    def circumscribed_radius(self) -> float:
        return math.hypot(self.length / 2, self.width / 2)

    def __repr__(self) -> str:
        return f"Box(length={self.length}, width={self.width}, hollow={self.hollow})"


class Line(Shape):
    """A segment of ``length`` along the body x axis, centred on the entity."""

    kind = "line"

    def __init__(self, length: float = 0.5):
        if not length > 0:
            raise ValueError(f"Line length must be > 0, got {length}")
        self.length = float(length)
        #: drawing width in pixels
        self.width = 2

    def moment_of_inertia(self, mass: float) -> float:
        return (1 / 12) * mass * (self.length**2)

    def get_delta_from_anchor(self, anchor: Tuple[float, float]) -> Tuple[float, float]:
        return anchor[0] * self.length / 2, 0.0

    def circumscribed_radius(self) -> float:
        return self.length / 2

    def __repr__(self) -> str:
        return f"Line(length={self.length})"
