"""Per-entity property tables and contact pair lists, built once per world layout.

The step is a fixed sequence of batched kernels over ``[n_entities, batch, ...]``
tensors (entity-major: each entity's ``[batch, ...]`` block is contiguous, so a
per-entity constant broadcasts over one long contiguous run instead of
alternating every two floats). Everything that does not change from step to step (masses, limits,
which pairs can touch and with which kernel) is gathered here into tensors
when entities are added or a property changes, never inside the step.
"""
from __future__ import annotations

import itertools
import math
from functools import cached_property
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Dict, List, Optional, Sequence, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.shapes import Box, Line, Sphere

if TYPE_CHECKING:
    from vmas_ros.simulator.entities import Entity
    from vmas_ros.simulator.physics.constants import StepConstants
    from vmas_ros.simulator.physics.scales import DynamicsScales

#: collision kernels, keyed by the (first, second) shape kinds they take
PAIR_KINDS: Tuple[Tuple[str, str], ...] = (
    ("sphere", "sphere"),
    ("line", "sphere"),
    ("line", "line"),
    ("box", "sphere"),
    ("box", "line"),
    ("box", "box"),
)
_KIND_ORDER = {"box": 0, "line": 1, "sphere": 2}


def incidence(index: Tensor, n_entities: int, dtype: torch.dtype) -> Tensor:
    """``[N, P]`` 0/1 matrix with a 1 at (index[p], p): ``M @ values`` adds each pair's ``[P, B]`` value
    onto its entity (a scatter as one GEMM; see physics.scatter.scatter_by_gemm)."""
    members = index.tolist()  # built once per layout, in Python: a few hundred cells at most (see physics)
    rows = [[1.0 if member == entity else 0.0 for member in members] for entity in range(n_entities)]
    return torch.tensor(rows, device=index.device, dtype=dtype).reshape(n_entities, len(members))


class _Incidence:
    """Cached dense incidence matrices of a pair list, per (number of entities, dtype)."""

    def incidence_ab(self, n_entities: int, dtype: torch.dtype) -> Tuple[Tensor, Tensor]:
        """(``[N, P]`` of the first members, ``[N, P]`` of the second ones)."""
        cache = self.__dict__.setdefault("_incidence", {})
        key = (n_entities, dtype)
        if key not in cache:
            cache[key] = (incidence(self.index_a, n_entities, dtype), incidence(self.index_b, n_entities, dtype))
        return cache[key]

    def incidence_opposite(self, n_entities: int, dtype: torch.dtype) -> Tensor:
        """``[N, P]``: +1 at the first member, -1 at the second (a value on a, its opposite on b)."""
        cache = self.__dict__.setdefault("_incidence", {})
        key = ("opposite", n_entities, dtype)
        if key not in cache:
            on_a, on_b = self.incidence_ab(n_entities, dtype)
            cache[key] = on_a - on_b
        return cache[key]


@dataclass
class PairTable(_Incidence):
    """Entity indices of every pair handled by one collision kernel, plus shape params."""

    kind: Tuple[str, str]
    index_a: Tensor  # [P] long
    index_b: Tensor  # [P] long
    params: Dict[str, Tensor] = field(default_factory=dict)  # each [P, 1] (broadcasts over the batch)

    @cached_property
    def index_ab(self) -> Tensor:
        """[2P] indices a0, b0, a1, b1, ... for scattering both sides in pair order."""
        return torch.stack([self.index_a, self.index_b], dim=1).flatten()

    @cached_property
    def contact_distance(self) -> Tensor:
        """[P, 1] sum of the two radii (sphere pairs): centres closer than this touch."""
        return self.params["a_radius"] + self.params["b_radius"]

    @property
    def size(self) -> int:
        return int(self.index_a.numel())


@dataclass
class SphereGroup:
    """Spheres of which every pair may touch, whose contacts a grid finds (``physics.collision.sphere_grid``)
    instead of a pair list: a swarm of ``M`` spheres has ``M^2 / 2`` pairs, most of them far apart.

    Members collide with everything (the default filter), are movable and in no
    joint. ``cell`` is the grid's cell side: the largest contact distance of two
    members with a margin for float rounding of the cell coordinates.
    ``capacity`` is the room in the candidate list per sphere; ``needed``
    (0-d, on the device) the most candidates per sphere a step has met.
    """

    members: Tensor  # [M] long entity indices
    radius: Tensor  # [M]
    cell: float
    capacity: int
    needed: Tensor

    kind = ("sphere", "sphere")

    def grow(self) -> bool:
        """Whether a step met more candidates than ``capacity`` (a host read of ``needed``); if so the
        capacity is raised to the next power of two that holds them, and the step must be computed again."""
        from vmas_ros.simulator.physics.spatial_hash import grown_capacity  # (physics imports the tables)

        needed = int(self.needed)
        if needed <= self.capacity:
            return False
        self.capacity = grown_capacity(needed)
        return True

    @property
    def size(self) -> int:
        return int(self.members.numel())


@dataclass
class JointTable(_Incidence):
    """Static part of all joint constraints; fixed rotations are read per step."""

    constraints: list
    index_a: Tensor  # [J]
    index_b: Tensor  # [J]
    anchor_a: Tensor  # [J, 1, 2] body-frame offsets
    anchor_b: Tensor  # [J, 1, 2]
    dist: Tensor  # [J, 1]
    rotate: Tensor  # [J] bool

    def __post_init__(self) -> None:
        # planar views for the step (physics.joints): anchor components [J, 1], lock as float 0/1
        self.anchor_ax, self.anchor_ay = self.anchor_a[..., 0], self.anchor_a[..., 1]
        self.anchor_bx, self.anchor_by = self.anchor_b[..., 0], self.anchor_b[..., 1]
        self.locked = (~self.rotate).to(self.dist.dtype).reshape(-1, 1)

    @cached_property
    def index_ab(self) -> Tensor:
        return torch.stack([self.index_a, self.index_b], dim=1).flatten()


@dataclass
class WorldTables:
    """Everything the batched step needs to know about the entities, as tensors."""

    n_entities: int
    n_agents: int
    mass: Tensor  # [N, 1, 1]
    inertia: Tensor  # [N, 1, 1]
    movable: Tensor  # [N, 1, 1] bool
    rotatable: Tensor  # [N, 1, 1] bool
    drag: Tensor  # [N, 1, 1]
    linear_friction: Tensor  # [N, 1, 1]
    angular_friction: Tensor  # [N, 1, 1]
    has_friction: bool
    gravity_force: Tensor  # [N, 1 or B, 2] mass * (world + entity gravity)
    has_gravity: bool
    max_speed: Tensor  # [N, 1, 1], inf when unlimited
    v_range: Tensor  # [N, 1, 1], inf when unlimited
    agent_max_f: Tensor  # [A, 1, 1]
    agent_f_range: Tensor  # [A, 1, 1]
    agent_max_t: Tensor  # [A, 1, 1]
    agent_t_range: Tensor  # [A, 1, 1]
    agent_movable: Tensor  # [A, 1, 1] bool
    agent_rotatable: Tensor  # [A, 1, 1] bool
    pairs: List[PairTable]
    joints: JointTable | None
    #: large groups of spheres whose contacts a grid finds; their pairs are in no PairTable
    sphere_groups: List[SphereGroup] = field(default_factory=list)
    #: which limits exist at all: a step skips the clamps no entity needs (clamping to inf is the identity)
    limits_speed: bool = True  # some finite max_speed
    limits_velocity: bool = True  # some finite v_range
    limits_force: bool = True  # some agent with finite max_f or f_range
    limits_torque: bool = True  # some agent with finite max_t or t_range
    #: per-env mass and drag scales (physics.scales); None: as built, the same in every env
    scales: Optional["DynamicsScales"] = field(default=None, repr=False, compare=False)
    #: the physics' constants for these tables (physics.constants.step_constants fills it once)
    step_constants: Optional["StepConstants"] = field(default=None, repr=False, compare=False)
    #: whether some agent cannot move or turn (World._action_input fills it once)
    fixed_agents: Optional[bool] = field(default=None, repr=False, compare=False)


def _value_or(value, default: float) -> float:
    return default if value is None else float(value)


def _column(values, device, dtype=torch.float32) -> Tensor:
    return torch.tensor(values, device=device, dtype=dtype).reshape(-1, 1, 1)


def _pair_collides(world, a, b) -> bool:
    """Static contact eligibility of an entity pair (evaluated when tables are built)."""
    if a is b or not a.collides(b) or not b.collides(a):
        return False
    if not (a.movable or a.rotatable or b.movable or b.rotatable):
        return False
    return frozenset((a.name, b.name)) not in world._joint_constraints


def _shape_params(prefix: str, shape) -> Dict[str, float]:
    if isinstance(shape, Sphere):
        return {f"{prefix}radius": shape.radius}
    if isinstance(shape, Line):
        return {f"{prefix}length": shape.length}
    if isinstance(shape, Box):
        return {f"{prefix}length": shape.length, f"{prefix}width": shape.width, f"{prefix}solid": float(not shape.hollow)}
    raise TypeError(f"unsupported shape {shape!r}")


def collide_with_all(other: "Entity") -> bool:
    """The default collision filter: collide with every entity. The step recognises it (by identity)
    to know that every pair of a group of spheres may touch (see SphereGroup)."""
    return True


def grid_members(world, entities) -> List[int]:
    """Entities a :class:`SphereGroup` can hold (spheres that collide with everything, movable, in no
    joint), if there are enough of them for the grid to pay off; else none."""
    from vmas_ros.simulator.thresholds import GRID_MIN_SPHERES

    minimum = GRID_MIN_SPHERES if world.sphere_grid == "auto" else (0 if world.sphere_grid == "on" else None)
    if minimum is None:
        return []
    jointed = {name for pair in world._joint_constraints for name in pair}
    members = [i for i, e in enumerate(entities)
               if isinstance(e.shape, Sphere) and e._collide and e._collision_filter is collide_with_all
               and e.movable and e.name not in jointed]
    return members if len(members) >= max(minimum, 2) else []


def build_sphere_group(world, entities, members: List[int]) -> List[SphereGroup]:
    if not members:
        return []
    from vmas_ros.simulator.thresholds import GRID_START_CAPACITY

    radii = [entities[i].shape.radius for i in members]
    device = world.device
    return [SphereGroup(
        members=torch.tensor(members, device=device, dtype=torch.long),
        radius=torch.tensor(radii, device=device, dtype=torch.float32),
        cell=2.0 * max(radii) * 1.01,  # the margin keeps touching spheres in adjacent cells despite float rounding
        capacity=GRID_START_CAPACITY,
        needed=torch.zeros((), device=device, dtype=torch.long),
    )]


def build_pairs(world, entities, grouped: Sequence[int] = ()) -> List[PairTable]:
    """Bucket every eligible entity pair by the collision kernel that handles it; pairs of two
    ``grouped`` entities are left to their :class:`SphereGroup`."""
    buckets: Dict[Tuple[str, str], list] = {kind: [] for kind in PAIR_KINDS}
    in_group = set(grouped)
    colliding = [i for i, e in enumerate(entities) if e._collide]  # no pair without both (goals, marks)
    others = [i for i in colliding if i not in in_group]
    if not in_group:
        found = itertools.combinations(colliding, 2)
    else:  # only pairs with a member outside the group: |others| x N, not N^2
        found = sorted((min(i, j), max(i, j)) for i in others for j in colliding
                       if j != i and (j in in_group or j > i))
    for i, j in found:
        a, b = entities[i], entities[j]
        if not _pair_collides(world, a, b):
            continue
        ia, ib = (i, j) if _KIND_ORDER[a.shape.kind] <= _KIND_ORDER[b.shape.kind] else (j, i)
        kind = (entities[ia].shape.kind, entities[ib].shape.kind)
        if kind not in buckets:
            raise TypeError(f"no collision kernel for shapes {kind}")
        buckets[kind].append((ia, ib))
    tables = []
    device = world.device
    for kind, pairs in buckets.items():
        if not pairs:
            continue
        rows = [
            {
                **_shape_params("a_", entities[ia].shape),
                **_shape_params("b_", entities[ib].shape),
                "reach": entities[ia].shape.circumscribed_radius() + entities[ib].shape.circumscribed_radius(),
            }
            for ia, ib in pairs
        ]
        params = {key: torch.tensor([row[key] for row in rows], device=device).reshape(-1, 1) for key in rows[0]}
        tables.append(
            PairTable(
                kind=kind,
                index_a=torch.tensor([p[0] for p in pairs], device=device, dtype=torch.long),
                index_b=torch.tensor([p[1] for p in pairs], device=device, dtype=torch.long),
                params=params,
            )
        )
    return tables


def build_joints(world, entities) -> JointTable | None:
    constraints = list(world._joint_constraints.values())
    if not constraints:
        return None
    index = {id(e): i for i, e in enumerate(entities)}
    # VMAS visits joints in entity-pair order; summing in that order keeps bit parity
    constraints.sort(key=lambda c: sorted((index[id(c.entity_a)], index[id(c.entity_b)])))
    device = world.device
    return JointTable(
        constraints=constraints,
        index_a=torch.tensor([index[id(c.entity_a)] for c in constraints], device=device, dtype=torch.long),
        index_b=torch.tensor([index[id(c.entity_b)] for c in constraints], device=device, dtype=torch.long),
        anchor_a=torch.tensor([c.entity_a.shape.get_delta_from_anchor(c.anchor_a) for c in constraints],
                              device=device).reshape(-1, 1, 2),
        anchor_b=torch.tensor([c.entity_b.shape.get_delta_from_anchor(c.anchor_b) for c in constraints],
                              device=device).reshape(-1, 1, 2),
        dist=torch.tensor([float(c.dist) for c in constraints], device=device).reshape(-1, 1),
        rotate=torch.tensor([bool(c.rotate) for c in constraints], device=device),
    )


def _gravity_force(world, entities) -> Tuple[Tensor, bool]:
    device = world.device
    rows = []
    batched = False
    for e in entities:
        g = world.gravity.to(device).reshape(1, 2)
        if e.gravity is not None:
            own = e.gravity if isinstance(e.gravity, Tensor) else torch.tensor(e.gravity, dtype=torch.float32)
            own = own.to(device=device, dtype=torch.float32)
            batched = batched or (own.dim() == 2 and own.shape[0] > 1)
            g = g + own.reshape(-1, 2)
        rows.append(g * e.mass)
    if batched:
        rows = [r.expand(world.batch_dim, 2) for r in rows]
    force = torch.stack(rows, dim=0)  # [N, 1 or B, 2]
    has_gravity = bool((force != 0).any())
    return force, has_gravity


def build_tables(world) -> WorldTables:
    """Read every entity property once into tensors on the world's device."""
    entities = world.entities
    agents = world.agents
    device = world.device
    world_lin, world_ang = world._linear_friction, world._angular_friction
    lin = [_value_or(e.linear_friction, world_lin) for e in entities]
    ang = [_value_or(e.angular_friction, world_ang) for e in entities]
    gravity_force, has_gravity = _gravity_force(world, entities)
    grouped = grid_members(world, entities)
    inf = math.inf
    return WorldTables(
        n_entities=len(entities),
        n_agents=len(agents),
        mass=_column([e.mass for e in entities], device),
        inertia=_column([e.moment_of_inertia for e in entities], device),
        movable=_column([bool(e.movable) for e in entities], device, torch.bool),
        rotatable=_column([bool(e.rotatable) for e in entities], device, torch.bool),
        drag=_column([_value_or(e.drag, world._drag) for e in entities], device),
        linear_friction=_column(lin, device),
        angular_friction=_column(ang, device),
        has_friction=any(v > 0 for v in lin + ang),
        gravity_force=gravity_force,
        has_gravity=has_gravity,
        max_speed=_column([_value_or(e.max_speed, inf) for e in entities], device),
        v_range=_column([_value_or(e.v_range, inf) for e in entities], device),
        agent_max_f=_column([_value_or(a.max_f, inf) for a in agents], device),
        agent_f_range=_column([_value_or(a.f_range, inf) for a in agents], device),
        agent_max_t=_column([_value_or(a.max_t, inf) for a in agents], device),
        agent_t_range=_column([_value_or(a.t_range, inf) for a in agents], device),
        agent_movable=_column([bool(a.movable) for a in agents], device, torch.bool),
        agent_rotatable=_column([bool(a.rotatable) for a in agents], device, torch.bool),
        pairs=build_pairs(world, entities, grouped),
        joints=build_joints(world, entities),
        sphere_groups=build_sphere_group(world, entities, grouped),
        limits_speed=any(e.max_speed is not None for e in entities),
        limits_velocity=any(e.v_range is not None for e in entities),
        limits_force=any(a.max_f is not None or a.f_range is not None for a in agents),
        limits_torque=any(a.max_t is not None or a.t_range is not None for a in agents),
        scales=world._dynamics_scales,
    )
