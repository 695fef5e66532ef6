"""Joints: keep two entities' anchor points together (VMAS ``Joint`` semantics).

A joint of length 0 is a single pin constraint. A joint of length ``dist > 0``
becomes a rigid rod: a line (or, with ``width``, a box) landmark pinned to both
entities at its ends, so the rod itself can collide, carry mass and rotate.
The world turns every constraint into rows of one batched joint kernel.
"""
from __future__ import annotations

from typing import Optional, Tuple

import torch

from vmas_ros.simulator.shapes import Box, Line
from vmas_ros.simulator.utils import Color, Observer, TorchUtils, X, Y

__all__ = ["Joint", "JointConstraint"]


def _check_ends(entity_a, entity_b, anchor_a: Tuple[float, float], anchor_b: Tuple[float, float], dist: float) -> None:
    """Raise ValueError unless two distinct entities are joined at anchors in [-1, 1]^2 by a rod of length >= 0."""
    if entity_a is entity_b:
        raise ValueError(f"cannot join {entity_a.name!r} to itself")
    for anchor in (anchor_a, anchor_b):
        if len(anchor) != 2 or max(anchor) > 1 or min(anchor) < -1:
            raise ValueError(f"joint anchors are (x, y) in [-1, 1] shape units, got {anchor}")
    if dist < 0:
        raise ValueError(f"joint dist must be >= 0, got {dist}")


class JointConstraint:
    """A pin between ``anchor_a`` on ``entity_a`` and ``anchor_b`` on ``entity_b``.

    ``rotate=False`` also locks the relative angle to ``fixed_rotation``
    (``rot_a - rot_b``), a float or a [batch, 1] tensor.
    """

    def __init__(
        self,
        entity_a,
        entity_b,
        anchor_a: Tuple[float, float] = (0.0, 0.0),
        anchor_b: Tuple[float, float] = (0.0, 0.0),
        dist: float = 0.0,
        rotate: bool = True,
        fixed_rotation: Optional[float] = None,
    ) -> None:
        _check_ends(entity_a, entity_b, anchor_a, anchor_b, dist)
        if rotate and fixed_rotation is not None:
            raise ValueError("a fixed_rotation needs rotate=False")
        self.entity_a, self.entity_b = entity_a, entity_b
        self.anchor_a, self.anchor_b = anchor_a, anchor_b
        self.dist = dist
        self.rotate = rotate
        self.fixed_rotation = 0.0 if fixed_rotation is None else fixed_rotation

    def _anchor_of(self, entity):
        if entity is self.entity_a:
            return self.anchor_a
        if entity is self.entity_b:
            return self.anchor_b
        raise ValueError(f"{entity.name!r} is not part of this joint")

    def get_delta_anchor(self, entity) -> torch.Tensor:
        """World-frame offset [batch, 2] from the entity's centre to its anchor."""
        delta = torch.tensor(entity.shape.get_delta_from_anchor(self._anchor_of(entity)), device=entity.device)
        return TorchUtils.rotate_vector(delta.expand_as(entity.state.pos), entity.state.rot)

    def pos_point(self, entity) -> torch.Tensor:
        """World position [batch, 2] of the entity's anchor."""
        return entity.state.pos + self.get_delta_anchor(entity)


class Joint(Observer):
    """Join two entities, optionally through a rigid rod of length ``dist``."""

    def __init__(
        self,
        entity_a,
        entity_b,
        anchor_a: Tuple[float, float] = (0.0, 0.0),
        anchor_b: Tuple[float, float] = (0.0, 0.0),
        rotate_a: bool = True,
        rotate_b: bool = True,
        dist: float = 0.0,
        collidable: bool = False,
        width: float = 0.0,
        mass: float = 1.0,
        fixed_rotation_a: Optional[float] = None,
        fixed_rotation_b: Optional[float] = None,
    ) -> None:
        from vmas_ros.simulator.entities import Landmark

        _check_ends(entity_a, entity_b, anchor_a, anchor_b, dist)
        if dist == 0 and (collidable or width != 0 or fixed_rotation_a != fixed_rotation_b):
            raise ValueError("a joint with dist 0 cannot be collidable, have a width, or differ in fixed rotations")
        if (fixed_rotation_a is not None and rotate_a) or (fixed_rotation_b is not None and rotate_b):
            raise ValueError("a fixed_rotation_* needs the matching rotate_*=False")
        if width > 0 and not collidable:
            raise ValueError("a joint with a width must be collidable")
        self.entity_a, self.entity_b = entity_a, entity_b
        self.rotate_a, self.rotate_b = rotate_a, rotate_b
        self.fixed_rotation_a, self.fixed_rotation_b = fixed_rotation_a, fixed_rotation_b
        self.dist = dist
        self.landmark = None
        if dist == 0:
            self.joint_constraints = [
                JointConstraint(entity_a, entity_b, anchor_a, anchor_b, 0.0, rotate_a and rotate_b, fixed_rotation_a)
            ]
            return
        self.landmark = Landmark(
            name=f"joint {entity_a.name} {entity_b.name}",
            collide=collidable,
            movable=True,
            rotatable=True,
            mass=mass,
            shape=Box(length=dist, width=width) if width != 0 else Line(length=dist),
            color=Color.BLACK,
            is_joint=True,
        )
        self.joint_constraints = [
            JointConstraint(self.landmark, entity_a, (-1, 0), anchor_a, 0.0, rotate_a, fixed_rotation_a),
            JointConstraint(self.landmark, entity_b, (1, 0), anchor_b, 0.0, rotate_b, fixed_rotation_b),
        ]
        entity_a.subscribe(self)
        entity_b.subscribe(self)

    def notify(self, observable, *args, **kwargs) -> None:
        """An end moved by hand (set_pos/set_rot): put the rod back between the anchors."""
        if self.landmark is None or self.landmark.batch_dim is None:
            return
        if self.entity_a.state.pos is None or self.entity_b.state.pos is None:
            return
        # only the envs whose end moved are touched (VMAS re-places the rod in every env,
        # which made reset_at of some envs nudge the rods of all the others)
        batch_index = kwargs.get("batch_index")
        start = self.joint_constraints[0].pos_point(self.entity_a)
        end = self.joint_constraints[1].pos_point(self.entity_b)
        angle = torch.atan2(end[:, Y] - start[:, Y], end[:, X] - start[:, X]).unsqueeze(-1)
        mid = (start + end) / 2
        if batch_index is None:
            self.landmark.set_pos(mid, batch_index=None)
            self.landmark.set_rot(angle, batch_index=None)
        else:
            self.landmark.set_pos(mid[batch_index], batch_index=batch_index)
            self.landmark.set_rot(angle[batch_index], batch_index=batch_index)
        for constraint, entity, rotate, fixed in (
            (self.joint_constraints[0], self.entity_a, self.rotate_a, self.fixed_rotation_a),
            (self.joint_constraints[1], self.entity_b, self.rotate_b, self.fixed_rotation_b),
        ):
            if rotate or fixed is not None:
                continue
            target = angle - entity.state.rot
            previous = constraint.fixed_rotation
            if batch_index is None or not isinstance(previous, torch.Tensor):
                constraint.fixed_rotation = target
            else:
                updated = previous.clone()
                updated[batch_index] = target[batch_index]
                constraint.fixed_rotation = updated

    def render(self, env_index: int = 0) -> list:
        return []
