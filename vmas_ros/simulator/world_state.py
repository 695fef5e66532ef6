"""The world's batched state as scenarios read and write it, a mixin of ``World``.

Scenarios that score or observe all entities at once read the state as
stacks (``stacked_state``, ``stacked_xy``) or in the physics step's own layout
(``planar_state``), move several entities at once (``set_positions``) and
have pure functions of the state evaluated with the step (state kernels).
Right after a step all of these are the step's output itself, kept by the
world's :class:`~vmas_ros.simulator.state_store.StateStore`; once an entity's
state changed they are rebuilt from the entities, once per change.
"""
from __future__ import annotations

from typing import Callable, List, Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.entities import Entity
from vmas_ros.simulator.layout import join_xy, split_xy_stacked


def _unchanged(parts: List[Tensor], versions: List[int], current: List[Tensor]) -> bool:
    """Whether ``current`` are the very tensors ``parts`` (or Nones), none written in place since ``versions``."""
    return len(parts) == len(current) and all(
        a is b and (a is None or a._version == v) for a, b, v in zip(parts, current, versions))



class StateAccess:
    """Batched state access; ``World`` provides ``entities``, ``_store``, ``_stacks``, ``_xy_splits``,
    ``_state_kernels``, ``_kernel_outputs`` and ``_planar_from_entities``."""

    def stacked_state(self, field: str = "pos") -> Tensor:
        """``[n_entities, batch, D]``: a state field of every entity, in ``entities`` order.

        Scenarios that score or observe all entities at once use this instead
        of stacking per-entity tensors themselves: right after a step it is the
        physics output itself (no copy), and it is rebuilt only when some
        entity's tensor was replaced or written in place since (tracked by
        identity and torch's version counter, so it is never stale). Treat it
        as read-only: it shares memory with the entities' states.
        Agents are the last ``len(agents)`` rows (``entities`` is landmarks then agents).
        """
        if self._store.clean():
            return self._store.stack(field)
        current = [getattr(e.state, field) for e in self.entities]
        cached = self._stacks.get(field)
        if cached is not None:
            parts, versions, stack = cached
            if _unchanged(parts, versions, current):
                return stack
        stack = torch.stack(current)
        self._stacks[field] = (current, [t._version for t in current], stack)
        return stack

    def stacked_xy(self, field: str = "pos") -> Tuple[Tensor, Tensor]:
        """``(x, y)``, each ``[n_entities, batch]``: a 2D state field of every entity as planar components.

        For scenario code that works per coordinate: ``sqrt(dx * dx + dy * dy)``
        over contiguous rows vectorises, a norm over a trailing dim of 2 does
        not. Right after a step these are rows of the physics state itself (no
        copy); otherwise they are split from :meth:`stacked_state`. Read-only,
        like :meth:`stacked_state`.
        """
        if field not in ("pos", "vel"):
            raise ValueError(f"stacked_xy: field must be 'pos' or 'vel', got {field!r}")
        if self._store.clean():
            planar = self._store.planar()[0 if field == "pos" else 1]
            return planar[0], planar[1]
        stack = self.stacked_state(field)
        split = self._xy_splits.get(field)
        if split is None or split[0] is not stack:
            split = self._xy_splits[field] = (stack, split_xy_stacked(stack.contiguous()))
        return split[1][0], split[1][1]

    def add_state_kernel(self, kernel: Callable[[Tensor, Tensor], object]) -> int:
        """Have every step evaluate ``kernel(q, v)`` on its new planar state; returns the kernel's handle.

        For scenarios whose rewards or observations are a pure function of the
        state (see :meth:`planar_state`): a compiled step runs the kernel right
        after its physics, in the same graph (one call instead of two, which at
        a few envs is most of the cost). Eager steps do not run it: the
        scenario computes the same thing when it is asked for. Read the result
        with :meth:`take_state_kernel_output`.
        """
        self._state_kernels.append(kernel)
        return len(self._state_kernels) - 1

    def replace_state_kernel(self, handle: int, kernel: Optional[Callable[[Tensor, Tensor], object]]) -> None:
        """Put ``kernel`` in place of kernel ``handle`` (None: the slot computes nothing, its output is None),
        for users whose kernel depends on a layout that changed (a compiled step compiles a new copy)."""
        if not 0 <= handle < len(self._state_kernels):
            raise ValueError(f"no state kernel {handle!r}: handles are 0..{len(self._state_kernels) - 1}")
        self._state_kernels[handle] = kernel

    def take_state_kernel_output(self, handle: int):
        """The output of kernel ``handle`` on the current state, handed out once; None when the state
        changed since the step computed it (a reset, a setter, an in-place write) or it was taken
        already: then call the kernel yourself.

        Once only, so that results a scenario hands out without copying are never handed out twice
        (a caller that writes into them would change what the next one gets).
        """
        generation, outputs = self._kernel_outputs
        if generation != self._store.gen or handle >= len(outputs) or not self._store.clean():
            return None
        output, outputs[handle] = outputs[handle], None
        return output

    def set_positions(self, entities: List[Entity], x: Tensor, y: Tensor) -> None:
        """Place several entities in every env at once: ``x``, ``y`` are ``[len(entities), B]``.

        The same as ``entity.set_pos(...)`` for each of them (observers are
        notified alike), but entities that are consecutive rows of
        ``entities`` written right after a step go straight into the step's
        state: two copies, and the next step needs no rebuild (discovery moves
        its covered targets every step). Like a step, it hands every entity
        fresh views of its state.
        """
        if len(entities) != x.shape[0] or x.shape != y.shape:
            raise ValueError(f"set_positions: {len(entities)} entities but x {tuple(x.shape)} and y {tuple(y.shape)}")
        slots = [e.state._slot for e in entities]
        lo = slots[0] if slots else 0
        if slots == list(range(lo, lo + len(slots))) and self._store.clean():
            self._store.write_rows(lo, lo + len(slots), x, y)
            for entity in entities:
                entity.notify_observers(batch_index=None)
            return
        for entity, pos in zip(entities, join_xy(x, y).unbind(0)):
            entity.set_pos(pos, batch_index=None)

    def planar_state(self) -> Tuple[Tensor, Tensor]:
        """``(q, v)``, each ``[3, n_entities, batch]``: (x, y, angle) and (vx, vy, angular velocity) of every entity.

        The physics step's own layout: right after a step these are its output
        (no copy, the same objects until the state changes, so scenarios can
        cache on their identity); otherwise they are stacked from the entities
        once per change. For scenario kernels that compute from the whole state
        at once (see ``compiling.WorldKernel``). Read-only.
        """
        store = self._store
        if store.clean():
            return store.planar()
        fields = ("pos", "rot", "vel", "ang_vel")
        if store.zeroed:  # after a reset: what entities were given since (None: still zero), read nothing else
            current = [e.state._set_since_adopt(f) for f in fields for e in self.entities]
        else:
            current = [getattr(e.state, f) for f in fields for e in self.entities]
        cached = self._stacks.get("planar")
        if cached is not None and cached[3] == store.gen and _unchanged(cached[0], cached[1], current):
            return cached[2]
        state = self._planar_from_entities(self.entities)
        versions = [None if t is None else t._version for t in current]
        self._stacks["planar"] = (current, versions, (state.q, state.v), store.gen)
        return state.q, state.v
