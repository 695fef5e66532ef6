"""Per-field stacks and per-entity views of one planar state, each built the first time it is read.

A step's output is two planar tensors, ``q`` (x, y, angle) and ``v`` (vx, vy,
angular velocity), each ``[3, n_entities, batch]``. Scenarios read it as VMAS
does, one entity and field at a time (``entity.state.pos``: ``[batch, 2]``),
or as stacks ``[n_entities, batch, D]``. :class:`StateViews` builds a field's
stack once (``pos`` and ``vel`` interleaved from the planar rows, ``rot`` and
``ang_vel`` views of them) and every entity's view of it with one ``unbind``,
and only when first asked: fields nobody reads are never built.

One object per state: the world state
(:class:`~vmas_ros.simulator.world_state.WorldState`) makes a new one whenever
it adopts a new state, so nothing here goes stale; what it can tell is
whether its tensors were written in place since (:meth:`StateViews.written`).
"""
from __future__ import annotations

from typing import Dict, Optional

from torch import Tensor

from vmas_ros.simulator.layout import join_xy

__all__ = ["StateViews"]


class StateViews:
    """``q``, ``v`` (each ``[3, N, B]``) and the stacks and views of them built so far."""

    __slots__ = ("q", "v", "_q_version", "_v_version", "_fields", "_pos", "_pos_version", "_vel", "_vel_version")

    def __init__(self, q: Tensor, v: Tensor) -> None:
        self.q, self.v = q, v
        self._q_version, self._v_version = q._version, v._version
        #: field -> [stack [N, B, D], its per-entity views [B, D] (None until one is asked for)]
        self._fields: Dict[str, list] = {}
        #: the interleaved pos/vel stacks once built, and their versions then (rot and ang_vel are views
        #: of q and v, whose version counter they share, so q's and v's checks cover them)
        self._pos: Optional[Tensor] = None
        self._vel: Optional[Tensor] = None
        self._pos_version = self._vel_version = 0

    def written(self) -> bool:
        """Whether ``q``, ``v`` or a stack built from them was written in place since it was made.

        Torch's version counter is shared by a tensor and all of its views, so
        this also sees a write into any entity's view. Called several times
        per step, so it is four version reads in straight-line code.
        """
        return (self.q._version != self._q_version or self.v._version != self._v_version
                or (self._pos is not None and self._pos._version != self._pos_version)
                or (self._vel is not None and self._vel._version != self._vel_version))

    def drop(self) -> None:
        """Forget the stacks and views built so far (just before a step replaces this state: nobody reads
        them in between, and they would add to the step's peak memory)."""
        self._fields = {}
        self._pos = self._vel = None

    def stack(self, name: str) -> Tensor:
        """``[N, B, D]`` stack of one field, built once (``pos``/``vel`` interleaved, ``rot``/``ang_vel`` views)."""
        entry = self._fields.get(name)
        if entry is None:
            entry = self._build(name)
        return entry[0]

    def part(self, name: str, slot: int) -> Tensor:
        """Entity ``slot``'s ``[B, D]`` view of :meth:`stack` (all views made with one ``unbind``)."""
        entry = self._fields.get(name)
        if entry is None:
            entry = self._build(name)
        parts = entry[1]
        if parts is None:
            parts = entry[1] = entry[0].unbind(0)
        return parts[slot]

    def _build(self, name: str) -> list:
        q, v = self.q, self.v
        if name == "pos":
            stack = self._pos = join_xy(q[0], q[1])
            self._pos_version = stack._version
        elif name == "vel":
            stack = self._vel = join_xy(v[0], v[1])
            self._vel_version = stack._version
        elif name == "rot":
            stack = q[2].unsqueeze(-1)  # a view: shares q's version counter, so writes are seen
        elif name == "ang_vel":
            stack = v[2].unsqueeze(-1)
        else:
            raise KeyError(f"a planar state holds 'pos', 'vel', 'rot' and 'ang_vel', not {name!r}")
        entry = self._fields[name] = [stack, None]
        return entry
