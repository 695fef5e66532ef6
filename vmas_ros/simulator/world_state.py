"""Every entity's state in a world, with one owner: :class:`WorldState` (``World.state``).

A step computes the new state of all entities at once, as two planar
``[3, n_entities, batch]`` tensors ``q`` (x, y, angle) and ``v`` (vx, vy,
angular velocity). The world state *adopts* them under a new generation
number, and that is all the bookkeeping a step does, whatever the number of
entities. Entities read their fields through it: the first read of
``entity.state.pos`` in a generation returns a view of a stack built once for
all entities (:class:`~vmas_ros.simulator.state_views.StateViews`). Why:
handing every entity its own ``[batch, 2]`` tensors after each step (VMAS's
``entity.state.pos``), and checking before the next step that none changed,
is per-entity work that makes up a large share of a step at a few envs; this
way a step does none, and fields nobody reads are never built.

VMAS's semantics hold:

* ``entity.state.pos`` is a ``[batch, 2]`` tensor; writing it in place
  (``pos[i] = ...``) changes the entity's state, assigning it (``state.pos = t``,
  ``set_pos``) replaces it until the next step, and tensors read before a
  step keep their values.
* The next step, and every batched read below, sees every change. A setter
  keeps the new tensor on the entity (``EntityState``) and marks the world
  state ``dirty``; in-place writes show in torch's version counter, which a
  tensor shares with all of its views, so one check per stack covers every
  entity. While dirty, the state is rebuilt from the entities, once per
  change (entities that were not changed still read the adopted state: it is
  still theirs).

Scenarios that score or observe all entities at once read the state batched
(:meth:`~WorldState.stacked_state`, :meth:`~WorldState.stacked_xy`,
:meth:`~WorldState.planar_state`: right after a step, the step's output
itself), move several entities at once (:meth:`~WorldState.set_positions`)
and register pure functions of the state that compiled steps evaluate with
their physics (:meth:`~WorldState.add_kernel`). ``World`` offers these under
its VMAS-style names.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Dict, List, Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.layout import join_xy, split_xy_stacked, stack_into
from vmas_ros.simulator.physics.types import PlanarState
from vmas_ros.simulator.state_views import StateViews

if TYPE_CHECKING:
    from vmas_ros.simulator.entities import Entity

__all__ = ["DETACHED", "STORED_FIELDS", "WorldState"]

#: the entity state fields the world state holds (force, torque and messages stay with the entity)
STORED_FIELDS = ("pos", "vel", "rot", "ang_vel")
#: the fields in planar order: q's rows (pos, rot), then v's (vel, ang_vel)
_PLANAR_FIELDS = ("pos", "rot", "vel", "ang_vel")

Kernel = Callable[[Tensor, Tensor], object]


def _unchanged(parts: List[Optional[Tensor]], versions: List[Optional[int]], current: List[Optional[Tensor]]) -> bool:
    """Whether ``current`` are the very tensors ``parts`` (or Nones), none written in place since ``versions``."""
    return len(parts) == len(current) and all(
        a is b and (a is None or a._version == v) for a, b, v in zip(parts, current, versions))


def _keeps_grad(fields: List[List[Optional[Tensor]]]) -> bool:
    return torch.is_grad_enabled() and any(t is not None and t.requires_grad for field in fields for t in field)


def _stacked_planar(fields: List[List[Optional[Tensor]]], n: int, batch: int, device) -> Tuple[Tensor, Tensor]:
    """``(q, v)`` ``[3, n, batch]`` from per-entity fields (pos, rot, vel, ang_vel; per entity the tensor,
    or None for a zero), each field written straight into its rows (no gradient kept: ``layout.stack_into``)."""
    present = [t for field in fields for t in field if t is not None]
    dtype = present[0].dtype if present else torch.get_default_dtype()
    allocate = torch.empty if len(present) == 4 * n else torch.zeros
    q, v = (allocate(3, n, batch, device=device, dtype=dtype) for _ in range(2))
    for rows, field in ((q[:2], fields[0]), (q[2:], fields[1]), (v[:2], fields[2]), (v[2:], fields[3])):
        present = [i for i, t in enumerate(field) if t is not None]
        if len(present) == n:
            stack_into(field, rows)
        else:
            for i in present:
                rows[:, i].copy_(field[i].t())
    return q, v


def _planar_with_grad(fields: List[List[Tensor]]) -> Tuple[Tensor, Tensor]:
    """``(q, v)`` from per-entity fields (pos, rot, vel, ang_vel) through differentiable ops."""
    out = []
    for linear, angular in (fields[:2], fields[2:]):
        xy = split_xy_stacked(torch.stack(linear))
        out.append(torch.cat([xy, torch.stack(angular)[..., 0].unsqueeze(0)]))
    return out[0], out[1]


class WorldState:
    """Every entity's pos/vel/rot/ang_vel in ``batch_dim`` envs on ``device``, and what is derived from them.

    ``generation`` moves on whenever a new state is adopted (a step, a reset of
    all envs, :meth:`set_positions`); an entity's field set in an older
    generation was consumed by then. ``dirty``: some entity may hold a field
    that differs from the adopted state (a setter ran, or there is no state).
    """

    def __init__(self, batch_dim: int, device: Optional[torch.device]) -> None:
        self.batch_dim = batch_dim
        self.device = None if device is None else torch.device(device)
        self.generation = 0
        self.dirty = True
        #: the adopted state and what was built from it; None while there is none, or while zeroed
        self._views: Optional[StateViews] = None
        #: every field of every entity is zero, not allocated yet (see reset_all)
        self._zeros = False
        self._entities: List["Entity"] = []
        #: while dirty: field -> (the entity tensors it was stacked from, their versions, the stack),
        #: and "planar" -> (the same, (q, v), the generation it was built in)
        self._stacks: Dict[str, tuple] = {}
        self._xy_splits: Dict[str, Tuple[Tensor, Tuple[Tensor, Tensor]]] = {}  # field -> (stack, [2, N, B])
        self._kernels: List[Optional[Kernel]] = []
        self._kernel_outputs: Tuple[int, list] = (-1, [])  # (generation, one output per kernel)

    # ------------------------------------------------------------------ entities
    def set_entities(self, entities: List["Entity"]) -> None:
        """Make ``entities`` (``World.entities`` order) the world's, entity ``i`` reading row ``i``.

        Rows move when entities are added (landmarks come first), so each
        entity of the old layout first takes what it still read from the
        adopted state as tensors of its own; the next step rebuilds from them.
        """
        self._release()
        self._entities = list(entities)
        for slot, entity in enumerate(self._entities):
            entity.state._join(self, slot)

    def append_entity(self, entity: "Entity") -> bool:
        """Add ``entity`` in the last row without touching the others, when no state is adopted (every
        entity holds its own fields, or reads zero after :meth:`reset_all`); False when the layout must
        be rebuilt with :meth:`set_entities`."""
        if self._views is not None:
            return False
        self._entities.append(entity)
        entity.state._join(self, len(self._entities) - 1)
        self._stacks, self._xy_splits = {}, {}
        self.dirty = True
        return True

    def reset_all(self) -> None:
        """Make every entity's pos/vel/rot/ang_vel zero in every env (``World.reset(None)``), allocating
        nothing until the zeros are read.

        A reset is usually followed by the scenario setting positions, so the
        next step rebuilds its state from the entities anyway; until then a
        zero state nobody reads would be two ``[3, N, B]`` tensors held for
        nothing, right at the first step's peak memory. A rebuild knows which
        fields are still zero (:attr:`zeroed`). Tensors entities were given
        before are dropped: they are stale.
        """
        self.generation += 1
        self._views, self._zeros, self.dirty = None, True, False
        self._stacks, self._xy_splits = {}, {}
        for entity in self._entities:
            entity.state._drop_consumed()

    def to(self, device) -> None:
        """Hand every entity its fields as tensors of its own (for the caller to move), then hold ``device``."""
        self._release()
        self.device = torch.device(device)

    def _release(self) -> None:
        """Let every entity own each field it still reads from here (its current view); afterwards there is
        no adopted state, and every entity holds all of its fields itself."""
        views = self._adopted() if self._zeros else self._views
        if views is not None:
            for slot, entity in enumerate(self._entities):
                for name in STORED_FIELDS:
                    if entity.state._set_since_adopt(name) is None:
                        entity.state._own(name, views.part(name, slot))
        self._views = None
        self._stacks, self._xy_splits = {}, {}
        self.dirty = True

    # --------------------------------------------------------- the adopted state
    @property
    def zeroed(self) -> bool:
        """Whether every field an entity has not set since :meth:`reset_all` is zero, with nothing allocated."""
        return self._zeros

    def clean(self) -> bool:
        """Whether the adopted state is still every entity's state (no setter ran, nothing written in place)."""
        if self.dirty:
            return False
        views = self._views
        if views is not None and views.written():
            self.dirty = True
            return False
        return True

    def still_adopted(self, q: Tensor, v: Tensor) -> bool:
        """Whether ``(q, v)`` is still the clean adopted state (what :meth:`planar_state` would return): the
        check of a cache keyed on that state, in one call (it runs several times per step)."""
        views = self._views
        return (not self.dirty and views is not None and views.q is q and views.v is v
                and not views.written())

    def view(self, name: str, slot: int) -> Tensor:
        """Entity ``slot``'s ``[B, D]`` view of field ``name`` of the adopted state (``EntityState`` reads it)."""
        return (self._views or self._adopted()).part(name, slot)

    def _current_fields(self, names: Tuple[str, ...]) -> List[Tensor]:
        """Every entity's current tensor of each field in ``names`` (field-major, ``World.entities`` order): its
        own when it set one since the last adopt, else its view of the adopted state (no entity getter runs:
        the state is read here, not through the entities and back)."""
        out = []
        for name in names:
            for slot, entity in enumerate(self._entities):
                own = entity.state._set_since_adopt(name)
                out.append(own if own is not None else (self._views or self._adopted()).part(name, slot))
        return out

    def _adopt(self, q: Tensor, v: Tensor) -> None:
        """Take ``q``, ``v`` (``[3, N, B]``) as every entity's current state."""
        self.generation += 1
        self._views, self._zeros, self.dirty = StateViews(q, v), False, False

    def _adopted(self) -> StateViews:
        """The adopted state; the zero state of :meth:`reset_all` is allocated here, when first read (same
        generation: the values do not change). Hot paths call it only when ``_views`` is None."""
        if self._views is None:
            if not self._zeros:
                raise RuntimeError("the world state holds no state to read: every entity holds its own fields")
            q = torch.zeros((3, len(self._entities), self.batch_dim), device=self.device)
            self._views, self._zeros = StateViews(q, torch.zeros_like(q)), False
        return self._views

    # ------------------------------------------------------------ batched reads
    def stacked_state(self, field: str = "pos") -> Tensor:
        """``[n_entities, batch, D]``: field ``field`` of every entity, in ``World.entities`` order.

        Right after a step it is built from the physics output (once per
        state); once an entity's tensor was replaced or written in place, it is
        stacked from the entities, again only when one of them changed
        (tracked by identity and torch's version counter, so it is never
        stale). Read-only: it shares memory with the entities' states.
        """
        if self.clean():
            return (self._views or self._adopted()).stack(field)
        current = self._current_fields((field,))
        cached = self._stacks.get(field)
        if cached is not None:
            parts, versions, stack = cached
            if _unchanged(parts, versions, current):
                return stack
        stack = torch.stack(current)
        self._stacks[field] = (current, [t._version for t in current], stack)
        return stack

    def stacked_xy(self, field: str = "pos") -> Tuple[Tensor, Tensor]:
        """``(x, y)``, each ``[n_entities, batch]``: a 2D field of every entity as planar components.

        Right after a step these are rows of the physics state itself (no
        copy); otherwise they are split from :meth:`stacked_state`. Read-only.
        """
        if field not in ("pos", "vel"):
            raise ValueError(f"stacked_xy: field must be 'pos' or 'vel', got {field!r}")
        if self.clean():
            views = self._views or self._adopted()
            planar = views.q if field == "pos" else views.v
            return planar[0], planar[1]
        stack = self.stacked_state(field)
        split = self._xy_splits.get(field)
        if split is None or split[0] is not stack:
            split = self._xy_splits[field] = (stack, split_xy_stacked(stack.contiguous()))
        return split[1][0], split[1][1]

    def planar_state(self) -> Tuple[Tensor, Tensor]:
        """``(q, v)``, each ``[3, n_entities, batch]``: (x, y, angle) and (vx, vy, angular velocity).

        Right after a step, the step's output (the same objects until the
        state changes, so callers can cache on their identity); otherwise
        rebuilt from the entities, once per change. Read-only.
        """
        if self.clean():
            views = self._views or self._adopted()
            return views.q, views.v
        entities = self._entities
        if self._zeros:  # after a reset: what entities were given since (None: still zero), read nothing else
            current = [e.state._set_since_adopt(f) for f in _PLANAR_FIELDS for e in entities]
        else:
            current = self._current_fields(_PLANAR_FIELDS)
        cached = self._stacks.get("planar")
        if cached is not None and cached[3] == self.generation and _unchanged(cached[0], cached[1], current):
            return cached[2]
        n = len(entities)
        planar = self._rebuild([current[i * n:(i + 1) * n] for i in range(len(_PLANAR_FIELDS))])
        versions = [None if t is None else t._version for t in current]
        self._stacks["planar"] = (current, versions, planar, self.generation)
        return planar

    def _rebuild(self, fields: List[List[Optional[Tensor]]]) -> Tuple[Tensor, Tensor]:
        """``(q, v)`` from the entities' fields (pos, rot, vel, ang_vel; per entity, None where still zero).

        Without a gradient to keep, each field is stacked straight into its
        rows of the new state (:func:`_stacked_planar`: no temporaries, which
        also keeps the heap from fragmenting after every reset).
        """
        if not _keeps_grad(fields):
            return _stacked_planar(fields, len(self._entities), self.batch_dim, self.device)
        if any(t is None for field in fields for t in field):  # fields still zero: read from the zero state
            n = len(self._entities)
            current = self._current_fields(_PLANAR_FIELDS)
            fields = [current[i * n:(i + 1) * n] for i in range(len(_PLANAR_FIELDS))]
        return _planar_with_grad(fields)

    # ------------------------------------------------------------ batched write
    def set_positions(self, entities: List["Entity"], x: Tensor, y: Tensor) -> None:
        """Place several entities in every env at once: ``x``, ``y`` are ``[len(entities), B]``.

        The same as ``entity.set_pos(...)`` for each of them (observers are
        notified alike), but entities that are consecutive rows written while
        the state is clean go into a copy of the adopted state: two copies,
        and the next step needs no rebuild. The copy is adopted as a new state,
        as after a step, so everything keyed on the old one's identity sees the
        change, views handed out before keep their values, and every entity
        fetches fresh views.
        """
        if len(entities) != x.shape[0] or x.shape != y.shape:
            raise ValueError(f"set_positions: {len(entities)} entities but x {tuple(x.shape)} and y {tuple(y.shape)}")
        slots = [e.state._slot for e in entities]
        lo = slots[0] if slots else 0
        if slots == list(range(lo, lo + len(slots))) and self.clean():
            views = self._adopted()
            q = views.q.clone()
            q[0, lo:lo + len(slots)] = x
            q[1, lo:lo + len(slots)] = y
            self._adopt(q, views.v)
            for entity in entities:
                entity.notify_observers(batch_index=None)
            return
        for entity, pos in zip(entities, join_xy(x, y).unbind(0)):
            entity.set_pos(pos, batch_index=None)

    # --------------------------------------------------------------- the step
    def step_input(self) -> Tuple[PlanarState, bool]:
        """The state the next step starts from, and whether it was rebuilt from the entities' own tensors.

        What was stacked from the old state is stale once the step runs: it is
        freed here, before the step allocates its own tensors (peak memory).
        """
        rebuilt = not self.clean()
        if rebuilt:
            state = PlanarState(*self.planar_state())
        else:
            views = self._adopted()
            state = PlanarState(views.q, views.v)
            views.drop()
        self._stacks, self._xy_splits = {}, {}
        return state, rebuilt

    def adopt_step(self, new: PlanarState, outputs: tuple, rebuilt: bool) -> None:
        """Adopt a step's output ``new`` and its kernels' ``outputs``; ``rebuilt``: from :meth:`step_input`
        (the entities' own tensors went into the step and are stale now, so they are dropped)."""
        self._adopt(new.q, new.v)
        if rebuilt:
            for entity in self._entities:
                entity.state._drop_consumed()
        self._kernel_outputs = (self.generation, list(outputs))

    # ---------------------------------------------------------- state kernels
    @property
    def kernels(self) -> Tuple[Optional[Kernel], ...]:
        """The registered state kernels, by handle (None: a slot that computes nothing)."""
        return tuple(self._kernels)

    def add_kernel(self, kernel: Kernel) -> int:
        """Have every compiled step evaluate ``kernel(q, v)`` on its new planar state; returns its handle.

        For scenarios whose rewards or observations are a pure function of the
        state: a compiled step runs the kernel right after its physics, in the
        same graph (one call instead of two, which at a few envs is most of
        the cost). Eager steps do not run it: the scenario computes the same
        thing when it is asked for. Read the result with :meth:`take_kernel_output`.
        """
        self._kernels.append(kernel)
        return len(self._kernels) - 1

    def replace_kernel(self, handle: int, kernel: Optional[Kernel]) -> None:
        """Put ``kernel`` in place of kernel ``handle`` (None: the slot computes nothing, its output is None)."""
        if not 0 <= handle < len(self._kernels):
            raise ValueError(f"no state kernel {handle!r}: handles are 0..{len(self._kernels) - 1}")
        self._kernels[handle] = kernel

    def take_kernel_output(self, handle: int):
        """The output of kernel ``handle`` on the current state, handed out once; None when the state
        changed since the step computed it (a reset, a setter, an in-place write) or it was taken already.

        Once only, so that results handed out without copying are never handed
        out twice (a caller that writes into them would change what the next one gets).
        """
        generation, outputs = self._kernel_outputs
        if generation != self.generation or handle >= len(outputs) or not self.clean():
            return None
        output, outputs[handle] = outputs[handle], None
        return output


#: the world state of entity states not in a world: it never adopts a state, so its generation stays 0
#: and no field an entity sets is ever stale
DETACHED = WorldState(batch_dim=0, device=None)
