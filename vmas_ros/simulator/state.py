"""Batched state of entities and agents' actions.

``EntityState`` holds one tensor per quantity for every env of the batch
(``pos`` is [batch, 2]); ``Action`` holds an agent's physical action ``u`` and
message ``c`` for the current step. Setters validate shape and device, so a
wrong tensor fails where it is written, not deep inside a step.

After a step, pos/vel/rot/ang_vel live in the world's
:class:`~vmas_ros.simulator.world_state.WorldState` (``World.state``); an
entity fetches a field from there the first time it is read (see that module
for why), and holds a tensor of its own only for a field set since. An agent's
action ``force``/``torque`` is a row of the world's
:class:`~vmas_ros.simulator.action_block.ActionBlock`: setting it copies into
the row.
"""
from __future__ import annotations

from typing import Dict, List, Optional

import torch
from torch import Tensor

from vmas_ros.simulator.action_block import ACTION_FIELDS, ActionBlock
from vmas_ros.simulator.world_state import DETACHED, STORED_FIELDS, WorldState
from vmas_ros.simulator.utils import TorchUtils

__all__ = ["EntityState", "AgentState", "Action"]


class _Batched:
    """Something that lives in a world: knows the batch size and device."""

    def __init__(self) -> None:
        self._batch_dim: Optional[int] = None
        self._device: Optional[torch.device] = None

    @property
    def batch_dim(self) -> Optional[int]:
        return self._batch_dim

    @batch_dim.setter
    def batch_dim(self, value: int) -> None:
        self._batch_dim = value

    @property
    def device(self) -> Optional[torch.device]:
        return self._device

    @device.setter
    def device(self, value) -> None:
        self._device = torch.device(value) if value is not None else None

    def _check_tensor(self, owner: str, name: str, value: Tensor) -> Tensor:
        if self._batch_dim is None:
            raise RuntimeError(f"add {owner} to a world before setting its {name}")
        if not isinstance(value, Tensor):
            raise TypeError(f"{owner}.{name} must be a torch.Tensor, got {type(value).__name__}")
        if value.dim() == 0 or value.shape[0] != self._batch_dim:
            raise ValueError(
                f"{owner}.{name} must have batch dimension {self._batch_dim} first, "
                f"got shape {tuple(value.shape)}"
            )
        # the common case (already there) skips a dispatcher call: setters run several times per step
        return value if value.device == self._device else value.to(self._device)

    def _check_rows(self, name: str, value: Tensor, width: int) -> Tensor:
        """``_check_tensor`` for a ``[batch, width]`` field of this state."""
        value = self._check_tensor(self._owner_name, name, value)
        if value.dim() != 2 or value.shape[1] != width:
            raise ValueError(
                f"{self._owner_name}.{name} must have shape [{self._batch_dim}, {width}], "
                f"got {tuple(value.shape)}"
            )
        return value


def _action_tensor(name: str, width: int, doc: str):
    """A validated [batch, width] action field of an agent state (kept in the world's action block)."""
    attr = "_" + name

    def fget(self):
        return self.__dict__[attr]

    def fset(self, value: Tensor) -> None:
        value = self._check_rows(name, value, width)
        self._set_action(name, value)

    return property(fget, fset, doc=doc)


def _stored_tensor(name: str, width: int, doc: str):
    """A [batch, width] field the world state holds after a step (validated by _check_rows).

    The entity holds a tensor of its own only when it was set since the world
    state last adopted a state (its generation number equals the world
    state's); otherwise the getter returns the world state's view, and keeps
    no reference to it: an entity holding last step's view would keep last
    step's stacks alive. The setter keeps the new tensor on the entity and
    tells the world state that the adopted state is no longer the truth.
    """
    attr, gen_attr = "_" + name, "_" + name + "_gen"

    def fget(self):
        world_state = self._world_state
        if self.__dict__[gen_attr] == world_state.generation:
            return self.__dict__[attr]
        self.__dict__[attr] = None  # a tensor set before the last adopted state: the step consumed it
        return world_state.view(name, self._slot)

    def fset(self, value: Tensor) -> None:
        value = self._check_rows(name, value, width)
        self._own(name, value)

    return property(fget, fset, doc=doc)


class EntityState(_Batched):
    """Batched kinematic state of one entity across all envs."""

    pos = _stored_tensor("pos", 2, "position [batch, 2] in the world frame")
    vel = _stored_tensor("vel", 2, "velocity [batch, 2] in the world frame")
    rot = _stored_tensor("rot", 1, "heading [batch, 1], radians, counter-clockwise")
    ang_vel = _stored_tensor("ang_vel", 1, "angular velocity [batch, 1], rad/s")

    _fields = STORED_FIELDS

    def __init__(self, owner_name: str = "entity") -> None:
        super().__init__()
        self._owner_name = owner_name
        #: the world state this entity reads through and its row there (see WorldState.set_entities)
        self._world_state: WorldState = DETACHED
        self._slot = -1
        for name in STORED_FIELDS:
            self.__dict__["_" + name] = None
            self.__dict__["_" + name + "_gen"] = DETACHED.generation

    # The methods below are the world state's side of the protocol (world_state.py calls them).

    def _own(self, name: str, value: Optional[Tensor]) -> None:
        """Make ``value`` this entity's ``name`` until the next step; the adopted state no longer holds it."""
        world_state = self._world_state
        self.__dict__["_" + name] = value
        self.__dict__["_" + name + "_gen"] = world_state.generation
        world_state.dirty = True

    def _set_since_adopt(self, name: str) -> Optional[Tensor]:
        """The tensor this entity was given for ``name`` since the world state last adopted a state, or None
        (it reads the adopted state)."""
        return self.__dict__["_" + name] if self.__dict__["_" + name + "_gen"] == self._world_state.generation else None

    def _drop_consumed(self) -> None:
        """Let go of fields set before the world state's last adopted state: the step consumed them (they are stale).

        The getter does the same lazily, but a field nobody reads after the
        step would keep its old tensor alive until the next setter (a reset's
        positions would be held through every later step).
        """
        generation = self._world_state.generation
        for name in STORED_FIELDS:
            if self.__dict__["_" + name + "_gen"] != generation:
                self.__dict__["_" + name] = None

    def _join(self, world_state: WorldState, slot: int) -> None:
        """Read from ``world_state`` at row ``slot`` from now on (the caller made sure this entity holds every
        field itself: a new entity does, and ``WorldState.set_entities`` hands the others theirs first)."""
        for name in STORED_FIELDS:
            self.__dict__["_" + name + "_gen"] = world_state.generation
        self._world_state, self._slot = world_state, slot
        world_state.dirty = True

    def _spawn(self, dim_c: int, dim_p: int) -> None:
        zeros = lambda width: torch.zeros(self._batch_dim, width, device=self._device)  # noqa: E731
        for name, width in (("pos", dim_p), ("vel", dim_p), ("rot", 1), ("ang_vel", 1)):
            self._own(name, zeros(width))

    def _assign(self, name: str, value: Tensor) -> None:
        """Set a field without validation (internal: resets, device moves, detaching)."""
        if name in STORED_FIELDS:
            self._own(name, value)
        else:
            setattr(self, "_" + name, value)

    def _reset(self, env_index, stored: bool = True) -> None:
        """Zero every field in ``env_index`` (all envs when None); ``stored=False`` leaves pos/vel/rot/ang_vel
        alone (``World.reset`` zeroes those of all entities at once in its world state)."""
        for name in self._fields if stored else self._fields[len(STORED_FIELDS):]:
            value = getattr(self, name)
            if value is None:
                continue
            if env_index is None:
                self._assign(name, torch.zeros_like(value))
            else:
                self._assign(name, TorchUtils.where_from_index(env_index, 0.0, value))

    def zero_grad(self) -> None:
        for name in self._fields:
            value = getattr(self, name)
            if value is not None:
                self._assign(name, value.detach())

    def tensors(self) -> Dict[str, Tensor]:
        """Every batched tensor this state holds, by field name (for device moves)."""
        values = {name: getattr(self, name) for name in self._fields}
        return {name: value for name, value in values.items() if isinstance(value, Tensor)}


class AgentState(EntityState):
    """Entity state plus the agent's message ``c`` and its action ``force``/``torque``."""

    _fields = EntityState._fields + ("c", "force", "torque")

    def __init__(self, owner_name: str = "agent") -> None:
        super().__init__(owner_name)
        self._c = self._force = self._torque = None
        #: the world's action block and this agent's row there (None: not in a world yet)
        self._actions: Optional[ActionBlock] = None
        self._action_slot = -1
        self._force_is_row = self._torque_is_row = False

    # c's width depends on the world, so it has its own setter
    @property
    def c(self) -> Optional[Tensor]:
        return self._c

    @c.setter
    def c(self, value: Tensor) -> None:
        self._c = self._check_tensor(self._owner_name, "c", value)

    force = _action_tensor("force", 2, "action force [batch, 2] for the next step (a row of the world's actions)")
    torque = _action_tensor("torque", 1, "action torque [batch, 1] for the next step (a row of the world's actions)")

    def _spawn(self, dim_c: int, dim_p: int) -> None:
        super()._spawn(dim_c, dim_p)
        if dim_c > 0:
            self._c = torch.zeros(self._batch_dim, dim_c, device=self._device)
        self._set_action("force", torch.zeros(self._batch_dim, dim_p, device=self._device))
        self._set_action("torque", torch.zeros(self._batch_dim, 1, device=self._device))

    # The methods below are the action block's side of the protocol (action_block.py, World.add_agent).

    def _join_actions(self, block: ActionBlock) -> None:
        """Keep ``force``/``torque`` in a row of ``block`` from now on, starting from their current values."""
        force, torque = self._force, self._torque
        self._actions, self._action_slot = block, block.append(self)
        self._force_is_row = self._torque_is_row = False
        self._set_action("force", force)
        self._set_action("torque", torque)

    def _set_action(self, name: str, value: Tensor) -> None:
        """Copy ``value`` into this agent's row; keep it instead when it needs gradients (the block turns loose)."""
        block, fields = self._actions, self.__dict__
        if block is None or value.requires_grad:
            fields["_" + name], fields["_" + name + "_is_row"] = value, False
            if block is not None:
                block.loose = True
            return
        row = fields["_" + name] if fields["_" + name + "_is_row"] else block.row(name, self._action_slot)
        row.copy_(value)
        fields["_" + name], fields["_" + name + "_is_row"] = row, True

    def _move_action_rows(self, block: ActionBlock, slot: int) -> None:
        """The block's tensors were replaced (grown, moved): hold views of the new rows."""
        for name in ACTION_FIELDS:
            if self.__dict__["_" + name + "_is_row"]:
                self.__dict__["_" + name] = block.row(name, slot)

    def _assign(self, name: str, value: Tensor) -> None:
        if name in ACTION_FIELDS:
            self._set_action(name, value)
        else:
            super()._assign(name, value)


def _per_component(value, size: int, name: str) -> List[float]:
    if isinstance(value, (list, tuple)):
        if len(value) != size:
            raise ValueError(f"{name} has {len(value)} entries but the action has {size} components")
        return [float(v) for v in value]
    return [float(value)] * size


class Action(_Batched):
    """An agent's physical action ``u`` and message ``c`` for the current step."""

    def __init__(self, u_range, u_multiplier, u_noise, action_size: int) -> None:
        super().__init__()
        self.action_size = action_size
        self._u_range = u_range
        self._u_multiplier = u_multiplier
        self._u_noise = u_noise
        for name, value in (("u_range", u_range), ("u_multiplier", u_multiplier), ("u_noise", u_noise)):
            _per_component(value, action_size, name)  # validates list lengths early
        self._u: Optional[Tensor] = None
        self._c: Optional[Tensor] = None
        self._tensor_cache: dict = {}
        #: the world's action block and this agent's row in its stacked ``u`` (see ActionBlock.publish_u),
        #: and the block's ``u_version`` this action last took (or overrode) its row at
        self._block: Optional[ActionBlock] = None
        self._slot = -1
        self._u_seen = 0

    def _join_rows(self, block: ActionBlock, slot: int) -> None:
        """Take ``u`` from row ``slot`` of the block's stacked actions whenever a step publishes some."""
        self._block, self._slot, self._u_seen = block, slot, block.u_version

    @property
    def u(self) -> Optional[Tensor]:
        block = self._block
        if block is not None and block.u_version != self._u_seen:  # a step published stacked actions
            self._u_seen = block.u_version
            if block.u_rows is not None:
                self._u = block.u_rows[self._slot]
        return self._u

    @u.setter
    def u(self, value: Tensor) -> None:
        self._set_u(self._check_tensor("action", "u", value))

    def _set_u(self, value: Optional[Tensor]) -> None:
        """Hold ``value`` (checked) as ``u``, over any stacked row published before."""
        self._u = value
        if self._block is not None:
            self._u_seen = self._block.u_version

    @property
    def c(self) -> Optional[Tensor]:
        return self._c

    @c.setter
    def c(self, value: Tensor) -> None:
        self._c = self._check_tensor("action", "c", value)

    @property
    def u_range(self):
        return self._u_range

    @property
    def u_multiplier(self):
        return self._u_multiplier

    @property
    def u_noise(self):
        return self._u_noise

    def _as_tensor(self, name: str) -> Tensor:
        key = (name, self._device)
        if key not in self._tensor_cache:
            values = _per_component(getattr(self, name), self.action_size, name)
            self._tensor_cache[key] = torch.tensor(values, device=self._device, dtype=torch.float32)
        return self._tensor_cache[key]

    @property
    def u_range_tensor(self) -> Tensor:
        return self._as_tensor("u_range")

    @property
    def u_multiplier_tensor(self) -> Tensor:
        return self._as_tensor("u_multiplier")

    @property
    def u_noise_tensor(self) -> Tensor:
        return self._as_tensor("u_noise")

    def _reset(self, env_index) -> None:
        self._set_u(self.u)  # the published row, if any, becomes the agent's own before it is reset
        for name in ("_u", "_c"):
            value = getattr(self, name)
            if value is None:
                continue
            if env_index is None:
                setattr(self, name, torch.zeros_like(value))
            else:
                setattr(self, name, TorchUtils.where_from_index(env_index, 0.0, value))

    def zero_grad(self) -> None:
        self._set_u(self.u)
        for name in ("_u", "_c"):
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, value.detach())
