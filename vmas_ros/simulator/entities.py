"""Entities: agents and landmarks (their batched state lives in ``state.py``).

An entity is a user-facing object with VMAS 1.5's attributes. Its *state* holds
one tensor per quantity for every env of the batch (``pos`` is [batch, 2]); its
*properties* (mass, shape, drag, ...) are plain Python values. The world reads
all properties into per-entity tables once and rebuilds them only when a
property changes (see ``World._tables``), so the step never touches an entity
property.
"""
from __future__ import annotations

from typing import Callable, List, Optional, Sequence, Union

import torch
from torch import Tensor

from vmas_ros.simulator.shapes import Shape, Sphere
from vmas_ros.simulator.state import Action, AgentState, EntityState, _Batched
from vmas_ros.simulator.tables import collide_with_all
from vmas_ros.simulator.utils import Color, Observable

__all__ = ["EntityState", "AgentState", "Action", "Entity", "Landmark", "Agent", "collide_with_all"]


def _table_property(name: str, doc: str):
    """A physical property; changing it tells the world to rebuild its tables."""
    attr = "_" + name

    def fget(self):
        return getattr(self, attr)

    def fset(self, value) -> None:
        setattr(self, attr, value)
        self._properties_changed()

    return property(fget, fset, doc=doc)


class Entity(_Batched, Observable):
    """Something in the world with a shape and a batched state (VMAS ``Entity``)."""

    def __init__(
        self,
        name: str,
        movable: bool = False,
        rotatable: bool = False,
        collide: bool = True,
        density: float = 25.0,
        mass: float = 1.0,
        shape: Optional[Shape] = None,
        v_range: Optional[float] = None,
        max_speed: Optional[float] = None,
        color=Color.GRAY,
        is_joint: bool = False,
        drag: Optional[float] = None,
        linear_friction: Optional[float] = None,
        angular_friction: Optional[float] = None,
        gravity=None,
        collision_filter: Callable[["Entity"], bool] = collide_with_all,
    ) -> None:
        _Batched.__init__(self)
        Observable.__init__(self)
        if not isinstance(name, str) or not name:
            raise ValueError(f"entity name must be a non-empty string, got {name!r}")
        if not mass > 0:
            raise ValueError(f"mass of {name!r} must be > 0, got {mass}")
        self._world = None
        self._name = name
        self._movable = movable
        self._rotatable = rotatable
        self._collide = collide
        self._density = density
        self._mass = mass
        self._shape = shape if shape is not None else Sphere()
        self._v_range = v_range
        self._max_speed = max_speed
        self._color = color
        self._is_joint = is_joint
        self._drag = drag
        self._linear_friction = linear_friction
        self._angular_friction = angular_friction
        self._gravity = gravity
        self._collision_filter = collide_with_all if collision_filter is None else collision_filter
        self._state = self._make_state()
        self._goal = None
        self._render: Optional[Tensor] = None

    def _make_state(self) -> EntityState:
        return EntityState(self._name)

    def _properties_changed(self) -> None:
        if self._world is not None:
            self._world._invalidate_tables()

    name = property(lambda self: self._name)
    state = property(lambda self: self._state)
    is_joint = property(lambda self: self._is_joint)
    density = property(lambda self: self._density)
    movable = _table_property("movable", "whether forces move the entity")
    rotatable = _table_property("rotatable", "whether torques rotate the entity")
    collide = _table_property("collide", "whether the entity takes part in contacts")
    mass = _table_property("mass", "mass in kg")
    shape = _table_property("shape", "collision shape")
    v_range = _table_property("v_range", "per-axis velocity limit (None: none)")
    max_speed = _table_property("max_speed", "speed limit on the velocity norm (None: none)")
    drag = _table_property("drag", "velocity damping per step; None uses the world's")
    linear_friction = _table_property("linear_friction", "None uses the world's")
    angular_friction = _table_property("angular_friction", "None uses the world's")
    gravity = _table_property("gravity", "extra per-entity gravity (x, y) or None")
    collision_filter = _table_property("collision_filter", "callable(other) -> bool")

    @property
    def color(self):
        return self._color

    @color.setter
    def color(self, value) -> None:
        self._color = value

    @property
    def goal(self):
        return self._goal

    @goal.setter
    def goal(self, value) -> None:
        self._goal = value

    @property
    def moment_of_inertia(self) -> float:
        return self._shape.moment_of_inertia(self._mass)

    @property
    def is_rendering(self) -> Tensor:
        if self._render is None:
            self.reset_render()
        return self._render

    def reset_render(self) -> None:
        self._render = torch.ones(self._batch_dim, dtype=torch.bool, device=self._device)

    def collides(self, entity: "Entity") -> bool:
        return bool(self._collide) and bool(self._collision_filter(entity))

    def _attach(self, world) -> None:
        self._world = world
        self.batch_dim = world.batch_dim
        self.device = world.device
        for part in self._batched_parts():
            part.batch_dim = world.batch_dim
            part.device = world.device
        self._state._spawn(world.dim_c, world.dim_p)

    def _batched_parts(self) -> list:
        return [self._state]

    def _reset(self, env_index, stored: bool = True) -> None:
        self._state._reset(env_index, stored)

    def zero_grad(self) -> None:
        self._state.zero_grad()

    def to(self, device) -> None:
        """Move the entity's state and action tensors to ``device`` (in a world: after ``World.to`` released them)."""
        self.device = device
        self._state.device = device
        for name, value in self._state.tensors().items():
            self._state._assign(name, value.to(device))
        for part in self._batched_parts()[1:]:
            part.device = device
            for key, value in list(vars(part).items()):
                if isinstance(value, Tensor):
                    setattr(part, key, value.to(device))

    def _set_state(self, name: str, value: Tensor, batch_index) -> None:
        if self._batch_dim is None:
            raise RuntimeError(f"add {self._name!r} to a world before setting its {name}")
        if not isinstance(value, Tensor):
            value = torch.as_tensor(value, dtype=torch.float32)
        value = value.to(self._device)
        if batch_index is None:
            if value.dim() > 1 and value.shape[0] == self._batch_dim:
                setattr(self._state, name, value)
            else:
                setattr(self._state, name, value.reshape(1, -1).repeat(self._batch_dim, 1))
        else:
            getattr(self._state, name)[batch_index] = value
        self.notify_observers(batch_index=batch_index)

    def set_pos(self, pos: Tensor, batch_index) -> None:
        """Set the position of all envs (``batch_index=None``) or of the selected ones."""
        self._set_state("pos", pos, batch_index)

    def set_vel(self, vel: Tensor, batch_index) -> None:
        self._set_state("vel", vel, batch_index)

    def set_rot(self, rot: Tensor, batch_index) -> None:
        self._set_state("rot", rot, batch_index)

    def set_ang_vel(self, ang_vel: Tensor, batch_index) -> None:
        self._set_state("ang_vel", ang_vel, batch_index)

    def render(self, env_index: int = 0) -> list:
        """Geoms drawing this entity in env ``env_index`` (used by the renderer)."""
        from vmas_ros.simulator import rendering

        if not bool(self.is_rendering[env_index]):
            return []
        geom = self._shape.get_geometry()
        xform = rendering.Transform()
        xform.set_translation(*self._state.pos[env_index].tolist())
        xform.set_rotation(float(self._state.rot[env_index]))
        geom.add_attr(xform)
        color = self._color.value if isinstance(self._color, Color) else self._color
        if isinstance(color, Tensor):
            color = (color[env_index] if color.dim() > 1 else color).tolist()
        geom.set_color(*color, alpha=getattr(self, "alpha", 1.0))
        return [geom]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._name!r}, {self._shape!r})"


class Landmark(Entity):
    """A passive entity: obstacles, goals, packages (VMAS ``Landmark``)."""

    def __init__(
        self,
        name: str,
        shape: Optional[Shape] = None,
        movable: bool = False,
        rotatable: bool = False,
        collide: bool = True,
        density: float = 25.0,
        mass: float = 1.0,
        v_range: Optional[float] = None,
        max_speed: Optional[float] = None,
        color=Color.GRAY,
        is_joint: bool = False,
        drag: Optional[float] = None,
        linear_friction: Optional[float] = None,
        angular_friction: Optional[float] = None,
        gravity=None,
        collision_filter: Callable[[Entity], bool] = collide_with_all,
    ) -> None:
        super().__init__(
            name, movable, rotatable, collide, density, mass, shape, v_range, max_speed,
            color, is_joint, drag, linear_friction, angular_friction, gravity, collision_filter,
        )


class Agent(Entity):
    """An entity that acts: physical action ``u`` through its dynamics, optional messages."""

    def __init__(
        self,
        name: str,
        shape: Optional[Shape] = None,
        movable: bool = True,
        rotatable: bool = True,
        collide: bool = True,
        density: float = 25.0,
        mass: float = 1.0,
        f_range: Optional[float] = None,
        max_f: Optional[float] = None,
        t_range: Optional[float] = None,
        max_t: Optional[float] = None,
        v_range: Optional[float] = None,
        max_speed: Optional[float] = None,
        color=Color.BLUE,
        alpha: float = 0.5,
        obs_range: Optional[float] = None,
        obs_noise: Optional[float] = None,
        u_noise: Union[float, Sequence[float]] = 0.0,
        u_range: Union[float, Sequence[float]] = 1.0,
        u_multiplier: Union[float, Sequence[float]] = 1.0,
        action_script: Optional[Callable] = None,
        sensors: Optional[list] = None,
        c_noise: float = 0.0,
        silent: bool = True,
        adversary: bool = False,
        drag: Optional[float] = None,
        linear_friction: Optional[float] = None,
        angular_friction: Optional[float] = None,
        gravity=None,
        collision_filter: Callable[[Entity], bool] = collide_with_all,
        render_action: bool = False,
        dynamics=None,
        action_size: Optional[int] = None,
        discrete_action_nvec: Optional[List[int]] = None,
    ) -> None:
        from vmas_ros.simulator.dynamics.holonomic import Holonomic

        super().__init__(
            name, movable, rotatable, collide, density, mass, shape, v_range, max_speed,
            color, False, drag, linear_friction, angular_friction, gravity, collision_filter,
        )
        if obs_range == 0.0 and sensors:
            raise ValueError(f"agent {name!r} has obs_range 0 (blind) but was given sensors")
        if action_size is not None and discrete_action_nvec is not None and action_size != len(discrete_action_nvec):
            raise ValueError(
                f"agent {name!r}: action_size {action_size} does not match discrete_action_nvec {discrete_action_nvec}"
            )
        if discrete_action_nvec is not None and not all(n > 1 for n in discrete_action_nvec):
            raise ValueError(f"agent {name!r}: every discrete_action_nvec entry must be > 1, got {discrete_action_nvec}")
        self._f_range, self._max_f = f_range, max_f
        self._t_range, self._max_t = t_range, max_t
        self._obs_range, self._obs_noise = obs_range, obs_noise
        self._action_script = action_script
        self._c_noise = c_noise
        self._silent = silent
        self._adversary = adversary
        self._render_action = render_action
        self._alpha = alpha
        self._sensors: list = []
        for sensor in sensors or []:
            self.add_sensor(sensor)
        self.dynamics = dynamics if dynamics is not None else Holonomic()
        if action_size is not None:
            self.action_size = action_size
        elif discrete_action_nvec is not None:
            self.action_size = len(discrete_action_nvec)
        else:
            self.action_size = self.dynamics.needed_action_size
        self.discrete_action_nvec = list(discrete_action_nvec) if discrete_action_nvec else [3] * self.action_size
        self.dynamics.agent = self
        self._action = Action(u_range, u_multiplier, u_noise, self.action_size)

    def _make_state(self) -> AgentState:
        return AgentState(self._name)

    def _batched_parts(self) -> list:
        return [self._state, self._action]

    def _attach(self, world) -> None:
        if world.dim_c == 0 and not self._silent:
            raise ValueError(f"agent {self._name!r} is not silent but the world has dim_c=0")
        super()._attach(world)
        if self._silent and self._state.c is not None:
            self._state._c = None

    def add_sensor(self, sensor) -> None:
        sensor.agent = self
        self._sensors.append(sensor)

    def action_callback(self, world) -> None:
        """Run the scripted policy and check it produced a valid action."""
        self._action_script(self, world)
        if (self._silent or world.dim_c == 0) and self._action.c is not None:
            raise ValueError(f"agent {self._name!r} must not communicate, but its action script set action.c")
        u = self._action.u
        if u is None or u.shape[1] != self.action_size:
            raise ValueError(f"action script of {self._name!r} must set action.u with {self.action_size} columns")

    def _reset(self, env_index, stored: bool = True) -> None:
        self._action._reset(env_index)
        self.dynamics.reset(env_index)
        super()._reset(env_index, stored)

    def zero_grad(self) -> None:
        self._action.zero_grad()
        self.dynamics.zero_grad()
        super().zero_grad()

    action = property(lambda self: self._action)
    sensors = property(lambda self: self._sensors)
    action_script = property(lambda self: self._action_script)
    u_range = property(lambda self: self._action.u_range)
    u_multiplier = property(lambda self: self._action.u_multiplier)
    u_noise = property(lambda self: self._action.u_noise)
    c_noise = property(lambda self: self._c_noise)
    silent = property(lambda self: self._silent)
    adversary = property(lambda self: self._adversary)
    obs_range = property(lambda self: self._obs_range)
    obs_noise = property(lambda self: self._obs_noise if self._obs_noise is not None else 0)
    render_action = property(lambda self: self._render_action)
    f_range = _table_property("f_range", "per-axis force limit")
    max_f = _table_property("max_f", "force norm limit")
    t_range = _table_property("t_range", "torque limit")
    max_t = _table_property("max_t", "torque norm limit")

    @property
    def alpha(self) -> float:
        return self._alpha

    @alpha.setter
    def alpha(self, value: float) -> None:
        self._alpha = value
