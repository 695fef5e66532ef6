"""The world's copy of every entity's state, handed out to entities lazily.

A step computes the new state of all entities at once, as two planar
``[3, n_entities, batch]`` tensors ``q`` (x, y, angle) and ``v`` (vx, vy,
angular velocity). :class:`StateStore` keeps them with a generation number.
An entity's field whose generation is older than the store's is read from
the store the first time it is asked for (a view of a stack built once per
generation and field). Why: handing every entity its own ``[batch, 2]``
tensors after each step (VMAS's ``entity.state.pos``), and checking before
the next step that none changed, is per-entity work that makes up a large
share of a step at a few envs; this way a step does none, and fields nobody
reads are never built.

What stays VMAS's semantics:

* ``entity.state.pos`` is a ``[batch, 2]`` tensor; writing it in place
  (``pos[i] = ...``) changes the entity's state, and assigning it
  (``state.pos = t``, ``set_pos``) replaces it, until the next step.
* The next step (and :meth:`World.stacked_state`) sees every change. Writes
  through a setter mark the store ``dirty``; in-place writes are caught by
  torch's version counter, which a tensor shares with all of its views, so one
  check per stack covers every entity.

While the store is clean, :meth:`planar` and :meth:`stack` are the current
state of all entities; once dirty, the world rebuilds it from the entities
(see ``World.step``). Entities that were not changed still read their values
from the store then: those are still their current values.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.layout import join_xy

__all__ = ["StateStore", "STORED_FIELDS", "DETACHED"]

#: the entity state fields the store holds (force, torque and messages stay with the entity)
STORED_FIELDS = ("pos", "vel", "rot", "ang_vel")


class StateStore:
    """Every entity's pos/vel/rot/ang_vel after the last step, as planar tensors and lazily built stacks."""

    def __init__(self) -> None:
        #: bumped by :meth:`adopt`; an entity field older than this is read from here
        self.gen = 0
        self._q: Optional[Tensor] = None
        self._v: Optional[Tensor] = None
        self._versions: Tuple[int, int] = (0, 0)
        #: field -> [stack [N, B, D], its version when built, its per-entity views (or None)]
        self._stacks: Dict[str, list] = {}
        #: the interleaved pos/vel stacks once built, and their versions then (rot and ang_vel are views
        #: of q and v, whose version counter they share, so q's and v's checks cover them)
        self._pos: Optional[Tensor] = None
        self._vel: Optional[Tensor] = None
        self._pos_version = self._vel_version = 0
        #: True when some entity may differ from ``q``/``v`` (a setter ran, or there is no step output)
        self.dirty = True
        #: (shape, device) of an all-zero state not allocated yet (see :meth:`adopt_zeros`), else None
        self._zeros: Optional[tuple] = None

    # ------------------------------------------------------------ ownership
    def adopt(self, q: Tensor, v: Tensor) -> None:
        """Take a step's output ``q``, ``v`` (``[3, N, B]``) as every entity's current state."""
        self.gen += 1
        self._q, self._v = q, v
        self._versions = (q._version, v._version)
        self._stacks = {}
        self._pos = self._vel = None
        self._zeros = None
        self.dirty = False

    def adopt_zeros(self, shape: Tuple[int, int, int], device) -> None:
        """Make every entity's state zero (``World.reset`` of all envs), allocating it only when read.

        A reset is usually followed by the scenario setting positions, so the
        next step rebuilds its state from the entities anyway; until then a
        zero state nobody reads would be two ``[3, N, B]`` tensors held for
        nothing, right at the first step's peak memory.
        Rebuilding knows which fields are still zero (:attr:`zeroed`).
        """
        self.gen += 1
        self._q = self._v = None
        self._stacks = {}
        self._pos = self._vel = None
        self._zeros = (tuple(shape), device)
        self.dirty = False

    @property
    def zeroed(self) -> bool:
        """Whether every field an entity has not set since the last adopt is zero, with nothing allocated."""
        return self._zeros is not None

    def _materialize(self) -> None:
        """Allocate the zero state of :meth:`adopt_zeros` (same generation: the values do not change)."""
        shape, device = self._zeros
        q = torch.zeros(shape, device=device)
        self._q, self._v = q, torch.zeros_like(q)
        self._versions = (self._q._version, self._v._version)
        self._zeros = None

    def release(self, states: List["object"]) -> None:
        """Hand every field still held here to its entity (``states``: the entities' states), then let go.

        For changes that invalidate the layout (entities added, a device move):
        afterwards every entity owns plain tensors and the store is dirty.
        """
        if self._zeros is not None:
            self._materialize()
        if self._q is not None:
            for state in states:
                state._take_from_store()
        self._q = self._v = self._pos = self._vel = None
        self._stacks = {}
        self.dirty = True

    def drop_views(self) -> None:
        """Forget the stacks and views built from ``q``/``v`` (only while clean, just before a step adopts
        a new state): nobody reads them in between, and they would add to the step's peak."""
        self._stacks = {}
        self._pos = self._vel = None

    def clean(self) -> bool:
        """Whether ``q``/``v`` are still every entity's state (no setter ran, nothing written in place).

        Called several times per step (every ``stacked_state``), so it is four
        version reads in straight-line code.
        """
        if self.dirty:
            return False
        if self._zeros is not None:
            return True
        if (self._q._version != self._versions[0] or self._v._version != self._versions[1]
                or (self._pos is not None and self._pos._version != self._pos_version)
                or (self._vel is not None and self._vel._version != self._vel_version)):
            self.dirty = True
            return False
        return True

    def write_rows(self, lo: int, hi: int, x: Tensor, y: Tensor) -> None:
        """Set the positions of entities ``lo:hi`` to ``(x, y)`` (``[hi - lo, B]`` each); only while clean.

        Into a copy of ``q``, not in place: the state is a new object, as after
        a step, so everything keyed on the old one's identity (scenario caches
        of ``planar_state``) sees the change, and views handed out before keep
        their values. The store stays clean, the stacks built from the old
        positions are dropped and the generation moves on, so every entity
        fetches fresh views (no entity holds an override while the store is
        clean, so none is lost).
        """
        if self._zeros is not None:
            self._materialize()
        q = self._q.clone()
        q[0, lo:hi] = x
        q[1, lo:hi] = y
        self.adopt(q, self._v)

    # -------------------------------------------------------------- reading
    def planar(self) -> Tuple[Tensor, Tensor]:
        """``q``, ``v`` of the last step (only meaningful while :meth:`clean`)."""
        if self._zeros is not None:
            self._materialize()
        return self._q, self._v

    def stack(self, name: str) -> Tensor:
        """``[N, B, D]`` stack of one field, built once per generation (``pos``/``vel`` interleaved, ``rot``/``ang_vel`` views)."""
        entry = self._stacks.get(name)
        if entry is None:
            entry = self._build(name)
        return entry[0]

    def part(self, name: str, slot: int) -> Tensor:
        """Entity ``slot``'s ``[B, D]`` view of :meth:`stack` (all views made with one ``unbind``)."""
        entry = self._stacks.get(name)
        if entry is None:
            entry = self._build(name)
        parts = entry[2]
        if parts is None:
            parts = entry[2] = entry[0].unbind(0)
        return parts[slot]

    def _build(self, name: str) -> list:
        if self._zeros is not None:
            self._materialize()
        q, v = self._q, self._v
        if name == "pos":
            stack = join_xy(q[0], q[1])
        elif name == "vel":
            stack = join_xy(v[0], v[1])
        elif name == "rot":
            stack = q[2].unsqueeze(-1)  # a view: shares q's version counter, so writes are seen
        elif name == "ang_vel":
            stack = v[2].unsqueeze(-1)
        else:
            raise KeyError(f"the state store holds {STORED_FIELDS}, not {name!r}")
        entry = self._stacks[name] = [stack, stack._version, None]
        if name == "pos":
            self._pos, self._pos_version = stack, stack._version
        elif name == "vel":
            self._vel, self._vel_version = stack, stack._version
        return entry


#: the store of states not attached to a world: it never adopts a step, so its generation stays 0
#: and no field is ever stale
DETACHED = StateStore()
