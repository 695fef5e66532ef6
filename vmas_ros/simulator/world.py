"""The world: the entities of a batch of envs, the queries about them, and the call of their step.

Public API follows VMAS 1.5's ``World``. Three things live elsewhere:

- the entities' state: :class:`~vmas_ros.simulator.world_state.WorldState`
  (``World.state``) holds every entity's pos/vel/rot/ang_vel between steps;
  entities read and write through it, and the batched reads scenarios use
  (``stacked_state``, ``planar_state``, ...) are its methods, offered here
  under VMAS-style names;
- the physics: a step runs :func:`vmas_ros.simulator.physics.pipeline.advance`
  on that state, eagerly or compiled;
- ray casting: :mod:`vmas_ros.simulator.rays`.

Property tables (``tables``) are cached and rebuilt only when the set of
entities or one of their physical properties changes.
"""
from __future__ import annotations

from typing import Callable, Dict, List, Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator import physics, rays
from vmas_ros.simulator.background_compile import BackgroundCompiler
from vmas_ros.simulator.compiled_world import CompiledWorld
from vmas_ros.simulator.entities import Agent, Entity, Landmark
from vmas_ros.simulator.action_block import ActionBlock
from vmas_ros.simulator.physics.actions import agents_action_input
from vmas_ros.simulator.physics.joints import fixed_rotations
from vmas_ros.simulator.physics.pipeline import advance
from vmas_ros.simulator.shapes import Box, Line, Sphere
from vmas_ros.simulator.tables import PAIR_KINDS, WorldTables, build_tables
from vmas_ros.simulator.utils import (
    ANGULAR_FRICTION, COLLISION_FORCE, DRAG, JOINT_FORCE, LINE_MIN_DIST, LINEAR_FRICTION, TORQUE_CONSTRAINT_FORCE,
)
from vmas_ros.simulator.world_state import WorldState

__all__ = ["World"]

#: shape-kind pairs a collision kernel exists for, each sorted by name
_COLLIDABLE_KINDS = frozenset(tuple(sorted(kinds)) for kinds in PAIR_KINDS)


def _no_entity(_: Entity) -> bool:
    return False


class World:
    """A batch of ``batch_dim`` 2D worlds sharing the same entities (VMAS ``World``)."""

    def __init__(
        self,
        batch_dim: int,
        device,
        dt: float = 0.1,
        substeps: int = 1,
        drag: float = DRAG,
        linear_friction: float = LINEAR_FRICTION,
        angular_friction: float = ANGULAR_FRICTION,
        x_semidim: Optional[float] = None,
        y_semidim: Optional[float] = None,
        dim_c: int = 0,
        collision_force: float = COLLISION_FORCE,
        joint_force: float = JOINT_FORCE,
        torque_constraint_force: float = TORQUE_CONSTRAINT_FORCE,
        contact_margin: float = 1e-3,
        gravity: Tuple[float, float] = (0.0, 0.0),
    ) -> None:
        if not isinstance(batch_dim, int) or batch_dim <= 0:
            raise ValueError(f"batch_dim must be a positive int, got {batch_dim!r}")
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        if not isinstance(substeps, int) or substeps < 1:
            raise ValueError(f"substeps must be an int >= 1, got {substeps!r}")
        if not contact_margin > 0:
            raise ValueError(f"contact_margin must be > 0, got {contact_margin}")
        self._batch_dim = batch_dim
        self._device = torch.device(device)
        self._dt = dt
        self._substeps = substeps
        self._drag = drag
        self._linear_friction = linear_friction
        self._angular_friction = angular_friction
        self._x_semidim = x_semidim
        self._y_semidim = y_semidim
        self._dim_c = dim_c
        self._dim_p = 2
        self._collision_force = collision_force
        self._joint_force = joint_force
        self._torque_constraint_force = torque_constraint_force
        self._contact_margin = contact_margin
        self._gravity = torch.tensor(gravity, device=self._device, dtype=torch.float32)
        self._agents: List[Agent] = []
        self._landmarks: List[Landmark] = []
        self._names: set = set()  # every entity's name: adding one checks it in O(1)
        self._joint_constraints: Dict[frozenset, object] = {}
        self._tables: Optional[WorldTables] = None
        self._dynamics_scales: Optional[physics.DynamicsScales] = None  # per-env mass and drag (scale_dynamics)
        #: every entity's pos/vel/rot/ang_vel, and everything derived from them (see world_state.py)
        self._state = WorldState(batch_dim, self._device)
        #: every agent's action force and torque, one row each (see action_block.py)
        self._actions = ActionBlock(batch_dim, self._dim_p, self._device)
        self.entity_index_map: Dict[Entity, int] = {}
        self._broad_phase = self.default_broad_phase
        self._sphere_grid = "auto"
        #: the step and the ray kernels: eager, or compiled (compile_physics)
        self._compiled = CompiledWorld()
        #: what ray_targets knows of layout-static lidar filters (see rays.ray_targets)
        self._static_ray_targets: rays.TargetCache = {}

    #: How contacts near the broad-phase radius are decided: "batch" (VMAS 1.5
    #: behaviour, bit-for-bit parity) or "env" (each env independent of the others).
    default_broad_phase: str = "batch"

    @property
    def broad_phase(self) -> str:
        return self._broad_phase

    @broad_phase.setter
    def broad_phase(self, value: str) -> None:
        if value not in ("batch", "env"):
            raise ValueError(f"broad_phase must be 'batch' or 'env', got {value!r}")
        self._broad_phase = value

    @property
    def sphere_grid(self) -> str:
        """Contacts among spheres that may all touch: ``"auto"`` (a grid from thresholds.GRID_MIN_SPHERES
        of them), ``"on"`` (a grid) or ``"off"`` (every pair). Same contacts, forces to float rounding."""
        return self._sphere_grid

    @sphere_grid.setter
    def sphere_grid(self, value: str) -> None:
        if value not in ("auto", "on", "off"):
            raise ValueError(f"sphere_grid must be 'auto', 'on' or 'off', got {value!r}")
        self._sphere_grid = value
        self._invalidate_tables()

    def compile_physics(self, enabled: bool = True, mode: Optional[str] = None, background: bool = False,
                        after_steps: int = 0) -> None:
        """Run the physics step and the LIDAR's ray kernels through ``torch.compile`` (docs/engine.md).

        The first compiled step compiles (seconds; a CPU needs a C++
        compiler), and so does a new batch size or a change of entities.
        ``mode`` goes to ``torch.compile`` (``"reduce-overhead"``: CUDA graphs).
        Results equal the eager step to float rounding, not bit for bit, so
        parity with VMAS is bit-exact on the eager path only.
        ``after_steps=n``: step eagerly ``n`` more steps, then compile
        (``compiled_from_step``; the default mode's switch, set by the
        workload, never the clock). ``background=True``: compile each function
        on a thread of its own while the world steps eagerly, each running
        compiled once ready (sim_node; ``background_compile``).
        """
        self._compiled.request(enabled, mode, background, after_steps, self._device)

    @property
    def compiled_from_step(self) -> Optional[int]:
        """The first of this world's steps (counted from 0) that runs compiled, planned or past; None when
        none is (eager, or a compiler that was missing when it was due)."""
        return self._compiled.switch_at

    @property
    def physics_compiled(self) -> bool:
        return self._compiled.compiled

    @property
    def background_compiler(self) -> Optional[BackgroundCompiler]:
        """What compiles this world's functions off its thread (``compile_physics(background=True)``), or None."""
        return self._compiled.background

    @property
    def compile_mode(self) -> Optional[str]:
        """The ``mode`` given to :meth:`compile_physics` (scenario kernels compile with it too)."""
        return self._compiled.mode

    # ------------------------------------------------------------------ registry
    def add_agent(self, agent: Agent) -> None:
        """Only way to add an agent; ``entities`` lists landmarks first, then agents (as VMAS)."""
        self._check_new_name(agent)
        agent._attach(self)
        agent.state._join_actions(self._actions)
        agent.action._join_rows(self._actions, agent.state._action_slot)
        self._agents.append(agent)
        # agents come last: appending one moves no other entity's row (a swarm adds thousands)
        if not self._state.append_entity(agent):
            self._state.set_entities(self.entities)
        self._invalidate_tables()

    def add_landmark(self, landmark: Landmark) -> None:
        self._check_new_name(landmark)
        landmark._attach(self)
        self._landmarks.append(landmark)
        # before any agent, a landmark is the last row too: appending it moves nothing (else the agents shift)
        if not self._agents and self._state.append_entity(landmark):
            self._invalidate_tables()
            return
        self._entities_changed()

    def _entities_changed(self) -> None:
        """Give every entity its row in the world state and rebuild the tables."""
        self._state.set_entities(self.entities)
        self._invalidate_tables()

    def add_joint(self, joint) -> None:
        """Add a joint (and the line landmark a joint of non-zero length carries)."""
        if self._substeps <= 1:
            raise ValueError(f"joints need World(substeps > 1) to stay stable, this world has substeps={self._substeps}")
        if joint.landmark is not None:
            self.add_landmark(joint.landmark)
        for constraint in joint.joint_constraints:
            self._joint_constraints[frozenset((constraint.entity_a.name, constraint.entity_b.name))] = constraint
        self._invalidate_tables()

    def _check_new_name(self, entity: Entity) -> None:
        if entity.name in self._names:
            raise ValueError(f"an entity named {entity.name!r} is already in the world")
        self._names.add(entity.name)

    def _invalidate_tables(self) -> None:
        self._tables = None

    @property
    def tables(self) -> WorldTables:
        """Per-entity property tensors, rebuilt lazily after any change."""
        if self._tables is None:
            self._tables = build_tables(self)
            self.entity_index_map = {e: i for i, e in enumerate(self.entities)}
        return self._tables

    def scale_dynamics(self, mass: Optional[Tensor] = None, drag: Optional[Tensor] = None) -> None:
        """Scale every entity's mass (with its moment of inertia) and drag per env: ``[N, B]`` each, in
        ``entities`` order (None: 1), until set again (:func:`~vmas_ros.simulator.physics.scales.apply`)."""
        physics.scales.apply(self, mass, drag)

    def reset(self, env_index) -> None:
        """Zero every entity's state (and agents' actions) in env ``env_index``, or in all envs when None."""
        entities = self.entities
        if env_index is None and entities:
            # all envs: the world state zeroes every entity's pos/vel/rot/ang_vel at once (allocated when
            # read; a rebuild fills only what the scenario set) instead of four fresh tensors per entity
            self._state.reset_all()
            for e in entities:
                e._reset(None, stored=False)
            return
        for e in entities:
            e._reset(env_index)

    def zero_grad(self) -> None:
        for e in self.entities:
            e.zero_grad()

    def to(self, device) -> None:
        self._device = torch.device(device)
        self._gravity = self._gravity.to(self._device)
        self._state.to(self._device)  # every entity owns its fields again, to move them
        self._actions.to(self._device)  # the agents' action rows move with it
        self._dynamics_scales = physics.scales.moved(self._dynamics_scales, self._device)
        for e in self.entities:
            e.to(self._device)
        self._invalidate_tables()

    # ---------------------------------------------------------------- properties
    state = property(lambda self: self._state, doc="every entity's pos/vel/rot/ang_vel (a ``WorldState``)")
    agents = property(lambda self: self._agents)
    landmarks = property(lambda self: self._landmarks)
    batch_dim = property(lambda self: self._batch_dim)
    device = property(lambda self: self._device)
    dt = property(lambda self: self._dt)
    substeps = property(lambda self: self._substeps)
    sub_dt = property(lambda self: self._dt / self._substeps)
    dim_p = property(lambda self: self._dim_p)
    dim_c = property(lambda self: self._dim_c)
    x_semidim = property(lambda self: self._x_semidim)
    y_semidim = property(lambda self: self._y_semidim)
    drag = property(lambda self: self._drag)
    gravity = property(lambda self: self._gravity)
    collision_force = property(lambda self: self._collision_force)
    joint_force = property(lambda self: self._joint_force)
    contact_margin = property(lambda self: self._contact_margin)
    torque_constraint_force = property(lambda self: self._torque_constraint_force)

    @property
    def joints(self) -> list:
        return list(self._joint_constraints.values())

    @property
    def entities(self) -> List[Entity]:
        return self._landmarks + self._agents

    @property
    def policy_agents(self) -> List[Agent]:
        return [a for a in self._agents if a.action_script is None]

    @property
    def scripted_agents(self) -> List[Agent]:
        return [a for a in self._agents if a.action_script is not None]

    def _step_params(self) -> physics.StepParams:
        """The step's world-level constants: the same object while they stay the same (a compiled step's
        layout is keyed on them, and this runs every step)."""
        values = (self._dt, self._substeps, self._collision_force, self._joint_force, self._torque_constraint_force,
                  self._contact_margin, self._x_semidim, self._y_semidim, self._broad_phase)
        cached = self.__dict__.get("_params_cache")
        if cached is None or cached[0] != values:
            cached = self._params_cache = (values, physics.StepParams(*values))
        return cached[1]

    # ---------------------------------------------------------------------- step
    def step(self) -> None:
        """Advance every env by ``dt``: forces, contacts, joints, integration, messages."""
        self._compiled.tick()  # the default mode's compiled step takes over at a planned step
        tables = self.tables
        if not self.entities:
            return
        state, rebuilt = self._state.step_input()
        actions = self._action_input(tables, state.q)
        fixed_rotation = None
        if tables.joints is not None:
            fixed_rotation = self._joint_fixed_rotations(tables)
        params = self._step_params()
        physics.step_constants(tables, params)  # built eagerly once, also when the step is compiled
        # state kernels ride along in compiled steps only: eagerly, computing them when asked keeps peak memory lower
        kernels = self._state.kernels if self.physics_compiled else ()
        new, outputs = self._advance(state, tables, params, actions, fixed_rotation, kernels)
        # a grid that met more candidates than it had room for: grow it and compute the step again
        # from the same state (its actions are assembled anew: the step may have written into them)
        while any([group.grow() for group in tables.sphere_groups]):  # every group grows, not the first only
            actions = self._action_input(tables, state.q)
            new, outputs = self._advance(state, tables, params, actions, fixed_rotation, kernels)
        del actions, state
        # the step's output becomes every entity's state: entities fetch their views when read
        self._state.adopt_step(new, outputs, rebuilt)
        if self._dim_c > 0:
            for agent in self._agents:
                if not agent.silent and agent.action.c is not None:
                    agent.state._c = agent.action.c

    def _advance(self, state, tables, params, actions, fixed_rotation, kernels):
        if not self._compiled.compiled:  # the eager step: straight to the pipeline
            return advance(state, tables, params, actions, fixed_rotation, kernels)
        return self._compiled.advance(state, tables, params, actions, fixed_rotation, kernels)

    def fall_back_to_eager(self, error: BaseException) -> None:
        """Compiling failed (``error``): log it once per process and step eagerly from now on."""
        self._compiled.fall_back(error)

    def _action_input(self, tables: WorldTables, q: Tensor):
        """The step's action input (:func:`~vmas_ros.simulator.physics.actions.agents_action_input`)."""
        return agents_action_input(self._agents, self._actions, tables, q, self.physics_compiled)

    def _joint_fixed_rotations(self, tables: WorldTables) -> Tensor:
        """[J, B, 1] target relative angles; tensors when a joint follows its line."""
        return fixed_rotations(tables.joints.constraints, self._batch_dim, self._device)

    # ------------------------------------------------------ batched state (World.state)
    def stacked_state(self, field: str = "pos") -> Tensor:
        """``[n_entities, batch, D]``: field ``field`` of every entity, landmarks then agents (agents are the
        last ``len(agents)`` rows). Read-only; the same object until the state changes
        (:meth:`WorldState.stacked_state`)."""
        return self._state.stacked_state(field)

    def stacked_xy(self, field: str = "pos") -> Tuple[Tensor, Tensor]:
        """``(x, y)``, each ``[n_entities, batch]``: ``"pos"`` or ``"vel"`` of every entity as planar components,
        for code that works per coordinate (``sqrt(dx * dx + dy * dy)`` over contiguous rows vectorises, a
        norm over a trailing dim of 2 does not). Read-only (:meth:`WorldState.stacked_xy`)."""
        return self._state.stacked_xy(field)

    def planar_state(self) -> Tuple[Tensor, Tensor]:
        """``(q, v)``, each ``[3, n_entities, batch]``: (x, y, angle) and (vx, vy, angular velocity), the physics
        step's own layout, for scenario kernels that compute from the whole state at once
        (``compiling.WorldKernel``). Read-only (:meth:`WorldState.planar_state`)."""
        return self._state.planar_state()

    def set_positions(self, entities: List[Entity], x: Tensor, y: Tensor) -> None:
        """Place several entities in every env at once, ``x``, ``y`` ``[len(entities), B]``: the same as
        ``set_pos`` for each, in one write when they are consecutive rows (:meth:`WorldState.set_positions`)."""
        self._state.set_positions(entities, x, y)

    def add_state_kernel(self, kernel: Callable[[Tensor, Tensor], object]) -> int:
        """Have every compiled step evaluate ``kernel(q, v)`` on its new planar state, in the step's graph;
        returns the kernel's handle (:meth:`WorldState.add_kernel`). Eager steps leave it to the caller."""
        return self._state.add_kernel(kernel)

    def replace_state_kernel(self, handle: int, kernel: Optional[Callable[[Tensor, Tensor], object]]) -> None:
        """Put ``kernel`` in place of kernel ``handle`` (None: the slot computes nothing), for users whose
        kernel depends on a layout that changed (a compiled step compiles a new copy)."""
        self._state.replace_kernel(handle, kernel)

    def take_state_kernel_output(self, handle: int):
        """The output of kernel ``handle`` on the current state, handed out once; None when the state changed
        since the step computed it or it was taken already (:meth:`WorldState.take_kernel_output`)."""
        return self._state.take_kernel_output(handle)

    # ------------------------------------------------------------------ ray casts
    def cast_ray(self, entity: Entity, angles: Tensor, max_range: float,
                 entity_filter: Callable[[Entity], bool] = _no_entity) -> Tensor:
        """Distance [B] along one ray per env from ``entity`` to the nearest filtered entity."""
        return self.cast_rays(entity, angles.unsqueeze(-1), max_range, entity_filter).squeeze(-1)

    def cast_rays(self, entity: Entity, angles: Tensor, max_range: float,
                  entity_filter: Callable[[Entity], bool] = _no_entity) -> Tensor:
        """Distances [B, R] along rays at world ``angles`` [B, R]; ``max_range`` where nothing is hit."""
        return self.cast_rays_along(entity, torch.cos(angles), torch.sin(angles), max_range, entity_filter)

    def cast_rays_along(self, entity: Entity, cos_a: Tensor, sin_a: Tensor, max_range: float,
                        entity_filter: Callable[[Entity], bool] = _no_entity) -> Tensor:
        """:meth:`cast_rays` for rays given by their direction ``(cos, sin)``, each ``[B, R]``, for sensors
        that know their directions more cheaply (see ``Lidar.ray_directions``)."""
        targets = self.ray_targets(entity, entity_filter)
        if not self._compiled.compiled:
            return rays.cast_rays_along(entity.state.pos, targets, cos_a, sin_a, max_range, rays.EAGER_KERNELS)
        return self._compiled.cast(
            lambda kernels: rays.cast_rays_along(entity.state.pos, targets, cos_a, sin_a, max_range, kernels))

    def ray_targets(self, entity: Entity, entity_filter: Callable[[Entity], bool]) -> List[Entity]:
        """The entities rays from ``entity`` can hit (``entity_filter`` true, not itself); all must collide
        with it. A ``layout_static`` filter is asked once per tables (:func:`rays.ray_targets`)."""
        return rays.ray_targets(self.entities, entity, entity_filter, self.tables, self._static_ray_targets)

    # ------------------------------------------------------------------- queries
    def _pick(self, value: Tensor, env_index) -> Tensor:
        return value if env_index is None else value[env_index]

    def get_distance_from_point(self, entity: Entity, test_point_pos: Tensor, env_index=None) -> Tensor:
        """Distance from points [B, 2] to the entity's outline (negative inside a sphere)."""
        shape, s = entity.shape, entity.state
        if isinstance(shape, Sphere):
            value = torch.linalg.vector_norm(s.pos - test_point_pos, dim=-1) - shape.radius
        elif isinstance(shape, Box):
            closest = geo.closest_point_on_box_boundary(s.pos, s.rot[..., 0], shape.length, shape.width, test_point_pos)
            value = torch.linalg.vector_norm(test_point_pos - closest, dim=-1) - LINE_MIN_DIST
        elif isinstance(shape, Line):
            closest = geo.closest_point_on_segment(s.pos, s.rot[..., 0], shape.length, test_point_pos)
            value = torch.linalg.vector_norm(test_point_pos - closest, dim=-1) - LINE_MIN_DIST
        else:
            raise TypeError(f"distance to {shape!r} is not supported")
        return self._pick(value, env_index)

    def get_distance(self, entity_a: Entity, entity_b: Entity, env_index=None) -> Tensor:
        """Surface-to-surface distance per env (negative or -1 when overlapping)."""
        a, b = entity_a, entity_b
        kinds = {a.shape.kind, b.shape.kind}
        if kinds == {"sphere"}:
            value = self.get_distance_from_point(a, b.state.pos) - b.shape.radius
        elif kinds in ({"box", "sphere"}, {"line", "sphere"}):
            other, sphere = (a, b) if b.shape.kind == "sphere" else (b, a)
            value = self.get_distance_from_point(other, sphere.state.pos) - sphere.shape.radius
            if other.shape.kind == "box":
                value = torch.where(self.is_overlapping(a, b), -1.0, value)
        elif kinds == {"line"}:
            pa, pb = geo.closest_points_segment_segment(
                a.state.pos, a.state.rot[..., 0], a.shape.length, b.state.pos, b.state.rot[..., 0], b.shape.length
            )
            value = torch.linalg.vector_norm(pa - pb, dim=-1) - LINE_MIN_DIST
        elif kinds == {"box", "line"}:
            box, line = (a, b) if a.shape.kind == "box" else (b, a)
            pa, pb = geo.closest_points_box_segment(
                box.state.pos, box.state.rot[..., 0], box.shape.length, box.shape.width,
                line.state.pos, line.state.rot[..., 0], line.shape.length,
            )
            value = torch.linalg.vector_norm(pa - pb, dim=-1) - LINE_MIN_DIST
        elif kinds == {"box"}:
            pa, pb = geo.closest_points_box_box(
                a.state.pos, a.state.rot[..., 0], a.shape.length, a.shape.width,
                b.state.pos, b.state.rot[..., 0], b.shape.length, b.shape.width,
            )
            value = torch.linalg.vector_norm(pa - pb, dim=-1) - LINE_MIN_DIST
        else:
            raise TypeError(f"distance between {a.shape!r} and {b.shape!r} is not supported")
        return self._pick(value, env_index)

    def collides(self, a: Entity, b: Entity) -> bool:
        """Could the two entities exert contact forces on each other now, in some env?

        VMAS 1.5's query: both want to collide with the other (``collide`` and
        each one's ``collision_filter``), at least one can move or turn, a
        collision kernel exists for their shapes, and in at least one env their
        centres are within the sum of their circumscribed radii. A query for
        scenarios, not part of the step: it reads that last test back to the host.
        """
        if a is b or not a.collides(b) or not b.collides(a):
            return False
        if not (a.movable or a.rotatable or b.movable or b.rotatable):
            return False
        if tuple(sorted((a.shape.kind, b.shape.kind))) not in _COLLIDABLE_KINDS:
            return False
        reach = a.shape.circumscribed_radius() + b.shape.circumscribed_radius()
        return bool((torch.linalg.vector_norm(a.state.pos - b.state.pos, dim=-1) <= reach).any())

    def is_overlapping(self, entity_a: Entity, entity_b: Entity, env_index=None) -> Tensor:
        """Bool per env: do the two shapes touch (a sphere inside a solid box counts)?"""
        if {entity_a.shape.kind, entity_b.shape.kind} == {"box", "sphere"}:
            box, sphere = (entity_a, entity_b) if entity_a.shape.kind == "box" else (entity_b, entity_a)
            overlapping = geo.disc_box_overlap(
                box.state.pos, box.state.rot[..., 0], box.shape.length, box.shape.width, sphere.state.pos,
                sphere.shape.radius,
            )
            return self._pick(overlapping, env_index)
        return self.get_distance(entity_a, entity_b, env_index) < 0
