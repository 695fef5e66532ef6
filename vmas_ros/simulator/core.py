"""Public face of the engine with VMAS 1.5's module path ``simulator.core``.

The classes live in smaller modules (shapes, entities, world); this module
gathers them so ``from vmas_ros.simulator.core import Agent, World, ...`` works
exactly like ``from vmas.simulator.core import ...``.
"""
from vmas_ros.simulator.entities import Action, Agent, AgentState, Entity, EntityState, Landmark
from vmas_ros.simulator.shapes import Box, Line, Shape, Sphere
from vmas_ros.simulator.world import World

__all__ = [
    "Action", "Agent", "AgentState", "Box", "Entity", "EntityState", "Landmark", "Line", "Shape",
    "Sphere", "World",
]
