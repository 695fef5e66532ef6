"""The one way a world's lidars are cast: ``Lidar.measure()`` asks the world's :class:`LidarCaster`.

Why one caster per world: a scenario observes one agent at a time, and each
agent's ``measure()`` alone is a dozen small tensor ops over ``[targets,
envs, rays]``; at a few envs those calls, not the arithmetic, are the cost.
So the first ``measure()`` in a state casts every lidar of the same layout
(ray count and range) that will be asked for in it, in one batch, and the
others read their row. Scenarios, the ROS node and tools all just call
``measure()``; how it is cast is decided here and nowhere else:

* a swarm, :data:`~vmas_ros.simulator.thresholds.GRID_MIN_LIDARS` or more lidars
  that see one set of spheres through a layout-static filter: the grid cast
  (``lidar_grid.GridCast``), each lidar's rays against the spheres within its
  reach only, one ``[L, B, R]`` stack whose rows the lidars read. Equal to the
  lidar alone to float rounding; no gradient is kept (a caller in grad mode
  on a state that needs one gets the casts below);
* the world compiles its physics and envs x rays is at most
  :data:`~vmas_ros.simulator.thresholds.COMPILED_LIDAR_BATCH_MAX_ELEMENTS`: one compiled function of the
  planar state for the whole batch (``lidar_batch.CompiledCast``; sphere
  targets only). Equal to the lidar alone to float rounding, as every
  compiled path is;
* envs x rays at most :data:`~vmas_ros.simulator.thresholds.LIDAR_BATCH_MAX_ELEMENTS`: one eager batched cast
  (``lidar_batch.BatchedLidars``), bit-equal to each lidar cast alone;
* otherwise, and for lidars that cannot be cast together, each lidar alone
  when it is asked for (``Lidar.cast_alone``): there the cost is memory
  traffic, not calls, and one lidar's temporaries stay in cache where all
  lidars' together do not.

Which lidars go into the batch: those of the layout asked for in the
previous state, and those never asked for yet (on the first state, all of
the layout). A scenario that reads every agent's lidar (flocking, pollock)
gets them all in one cast; one that reads a single lidar casts only that one
from the second state on, not the whole layout for one row. A lidar asked
for that was not in the batch is cast then.

Readings are kept for the state they were cast in: the identity of
``world.planar_state()``'s tensors, which every change of state replaces (a
step, a reset, a setter, an in-place write), and of the world's tables,
which every change of an entity's collision properties replaces. Entity
filters are asked once per state (``layout_static`` ones once per tables,
see ``World.ray_targets``); a filter that reads anything but the world's
state must not change its answers within one state. A reading is shared by
everyone who asks in that state: read-only, like ``planar_state``. One cast
under ``no_grad`` is cast again for a caller in grad mode, so that
differentiable envs keep their gradients. A scenario that observes the whole
swarm at once asks :meth:`LidarCaster.stacked_readings` (``Lidar.stacked_measure``)
for every reading in one ``[L, B, R]`` tensor.

The world's lidars hold the caster (``Lidar.measure`` finds it on the first
of them that has one), so the world itself needs no LIDAR state.
"""
from __future__ import annotations

from typing import Callable, Dict, List, Optional, Sequence, Tuple

import torch

from vmas_ros.simulator.lidar_batch import BatchedLidars, CompiledCast
from vmas_ros.simulator.lidar_grid import GridCast
from vmas_ros.simulator.thresholds import (COMPILED_LIDAR_BATCH_MAX_ELEMENTS, GRID_MIN_LIDARS,
                                           LIDAR_BATCH_MAX_ELEMENTS)

__all__ = ["LidarCaster"]


def _layout(sensor) -> Tuple[int, float]:
    """What lidars cast together must share: the ray count and the range."""
    return sensor.n_rays, float(sensor.max_range)


class LidarCaster:
    """Every lidar of one world, cast together once per state (all of the world's lidars share one).

    ``reading(sensor)`` is the sensor's distances ``[B, n_rays]`` in the
    current state. ``find_lidars(world)`` returns the world's lidars (every
    agent's, in order): a lidar added later is found on the next cast.
    """

    def __init__(self, find_lidars: Callable[[object], list]) -> None:
        self._find_lidars = find_lidars
        self._state: Optional[tuple] = None  # (q, tables) the readings below belong to
        #: sensor -> (its filter when cast, whether grad mode was on, its reading)
        self._readings: Dict[object, Tuple[object, bool, torch.Tensor]] = {}
        self._asked: set = set()  # lidars asked for in this state
        self._asked_before: set = set()  # ... in the previous state
        self._asked_ever: set = set()  # ... in any state
        self._batched = BatchedLidars()
        self._compiled: Dict[tuple, CompiledCast] = {}  # per batch of lidars
        self._grid = GridCast()
        #: the last stacked cast in this state: (its sensors, sensor -> row, grad mode, [L, B, R]) or None
        self._stack: Optional[tuple] = None
        #: the last list of lidars stacked: (the list, lidar -> row, whether they share one layout)
        self._swarm: Optional[tuple] = None

    def _refresh(self, world) -> None:
        """Forget the readings of an earlier state (the asked-for sets move on by one state)."""
        q, _ = world.planar_state()  # the same object until the state changes
        tables = world.tables
        state = self._state
        if state is None or state[0] is not q or state[1] is not tables:
            if state is not None:
                self._asked_before, self._asked = self._asked, set()
            self._state, self._readings, self._stack = (q, tables), {}, None

    def reading(self, sensor) -> torch.Tensor:
        """``sensor``'s distances ``[B, n_rays]`` in the world's current state, cast at most once per state."""
        world = sensor.world
        self._refresh(world)
        self._asked.add(sensor)
        self._asked_ever.add(sensor)
        grad = torch.is_grad_enabled()  # the reading is to carry the state's gradient, if it has one
        if self._usable(self._readings.get(sensor), sensor, grad):
            return self._readings[sensor][2]
        stack = self._stack
        if stack is not None and sensor in stack[1] and (stack[2] or not grad):
            return stack[3][stack[1][sensor]]
        batch = self._batch(world, sensor, grad)
        readings = self._cast(world, batch)
        if readings is None:  # not castable together, or too large to: this one alone
            batch, readings = [sensor], [sensor.cast_alone()]
        if isinstance(readings, torch.Tensor):  # a grid cast: rows of one stack
            self._stack = (batch, self._rows_of(batch)[0], grad, readings)
            self._state = (world.planar_state()[0], world.tables)
            return readings[self._stack[1][sensor]]
        for member, reading in zip(batch, readings):
            self._readings[member] = (member.entity_filter, grad, reading)
        # the same state, but reading entity fields nobody had read since a reset may have stacked it anew
        self._state = (world.planar_state()[0], world.tables)
        return self._readings[sensor][2]

    def latest(self, sensor) -> Optional[torch.Tensor]:
        """``sensor``'s reading from the latest state it was cast in (None if it was not cast there)."""
        kept = self._readings.get(sensor)
        if kept is not None:
            return kept[2]
        stack = self._stack
        if stack is not None and sensor in stack[1]:
            return stack[3][stack[1][sensor]]
        return None

    def stacked_readings(self, world, sensors: Sequence) -> torch.Tensor:
        """Every one of ``sensors``' distances ``[L, B, R]`` (one layout) in the current state, cast at most
        once per state: for scenarios that observe a whole swarm at once, without a call per lidar."""
        self._refresh(world)
        grad = torch.is_grad_enabled()
        sensors = list(sensors)
        stack = self._stack
        if stack is not None and (stack[2] or not grad) and stack[0] == sensors:
            return stack[3]
        rows, one_layout = self._rows_of(sensors)
        self._asked.update(sensors)
        self._asked_ever.update(sensors)
        readings = self._cast(world, sensors) if one_layout else None
        if readings is None:
            readings = [self.reading(s) for s in sensors]
        stacked = readings if isinstance(readings, torch.Tensor) else torch.stack(readings)
        self._stack = (sensors, rows, grad, stacked)
        self._state = (world.planar_state()[0], world.tables)
        return stacked

    def _rows_of(self, sensors: List) -> Tuple[Dict[object, int], bool]:
        """``(lidar -> row, whether they share one layout)`` of a list of lidars, worked out once per list
        (a swarm's casts take the same list state after state)."""
        known = self._swarm
        if known is None or known[0] != sensors:
            known = self._swarm = (list(sensors), {s: i for i, s in enumerate(sensors)},
                                   len({_layout(s) for s in sensors}) == 1)
        return known[1], known[2]

    @staticmethod
    def _usable(kept: Optional[tuple], sensor, grad: bool) -> bool:
        """Whether a reading kept for this state answers ``sensor`` now: cast with its current filter, and
        cast with grad mode on if it is on now (one cast under ``no_grad`` carries no gradient)."""
        return kept is not None and kept[0] is sensor.entity_filter and (kept[1] or not grad)

    def _batch(self, world, sensor, grad: bool) -> List:
        """``sensor`` and the lidars of its layout that were asked for in the previous state or never, and
        have no usable reading in this one, in the world's order (a compiled cast is planned per batch)."""
        layout, before, ever, readings = _layout(sensor), self._asked_before, self._asked_ever, self._readings
        batch = []
        for other in self._find_lidars(world):
            if other is sensor:
                batch.append(other)
            elif (_layout(other) == layout and (other in before or other not in ever)
                  and not self._usable(readings.get(other), other, grad)):
                batch.append(other)
        return batch if sensor in batch else [sensor] + batch  # (a lidar on an agent outside the world)

    def _cast(self, world, batch: Sequence):
        """Readings of ``batch`` from one cast (a list, or one ``[L, B, R]`` stack from the grid), or None:
        cast the lidar asked for alone."""
        elements = world.batch_dim * batch[0].n_rays
        readings = None
        if len(batch) >= GRID_MIN_LIDARS and not (torch.is_grad_enabled() and world.planar_state()[0].requires_grad):
            stacked = self._grid.cast(world, batch)  # the spheres near each lidar only (no gradient)
            if stacked is not None:
                return stacked
        if world.physics_compiled and elements <= COMPILED_LIDAR_BATCH_MAX_ELEMENTS:
            key = tuple(batch)
            caster = self._compiled.get(key)
            if caster is None:
                caster = self._compiled[key] = CompiledCast()
            readings = caster.cast(world, batch)
        if readings is None and len(batch) > 1 and elements <= LIDAR_BATCH_MAX_ELEMENTS:
            # gradients are recorded where the caller's grad mode and the state ask for them, as measure() does
            readings = self._batched.cast(world, batch, keep_grad=True)
        return readings
