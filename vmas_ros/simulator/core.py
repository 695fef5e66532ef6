"""Public face of the engine with VMAS 1.5's module path ``simulator.core``.

The classes live in smaller modules (shapes, entities, world); this module
gathers them so ``from vmas_ros.simulator.core import Agent, World, ...`` works
exactly like ``from vmas.simulator.core import ...``.
"""
from vmas_ros.simulator.dynamics.common import Dynamics
from vmas_ros.simulator.dynamics.holonomic import Holonomic
from vmas_ros.simulator.entities import Action, Agent, AgentState, Entity, EntityState, Landmark
from vmas_ros.simulator.joints import Joint
from vmas_ros.simulator.sensors import Sensor
from vmas_ros.simulator.shapes import Box, Line, Shape, Sphere
from vmas_ros.simulator.utils import (
    ANGULAR_FRICTION, COLLISION_FORCE, DRAG, JOINT_FORCE, LINE_MIN_DIST, LINEAR_FRICTION, TORQUE_CONSTRAINT_FORCE, X, Y,
    Color, Observable, TorchUtils, override,
)
from vmas_ros.simulator.world import World

# VMAS's core module also hands out the engine's constants and helpers; code written for it imports them from here
__all__ = [
    "ANGULAR_FRICTION", "COLLISION_FORCE", "DRAG", "JOINT_FORCE", "LINE_MIN_DIST", "LINEAR_FRICTION",
    "TORQUE_CONSTRAINT_FORCE", "X", "Y",
    "Action", "Agent", "AgentState", "Box", "Color", "Dynamics", "Entity", "EntityState", "Holonomic", "Joint",
    "Landmark", "Line", "Observable", "Sensor", "Shape", "Sphere", "TorchUtils", "World", "override",
]
