"""Headless visualisation: Pillow canvas, world rendering and frame/video export.

Nothing here opens a window or imports OpenGL/pyglet, so rendering works on
servers and in CI. Scenario-level drawing primitives (VMAS's ``rendering``
module) live in :mod:`vmas_ros.simulator.rendering`.
"""
from vmas_ros.viz.canvas import Canvas
from vmas_ros.viz.scene import bounds_geoms, comm_geoms, entity_geoms, render_world, view_bounds
from vmas_ros.viz.video import VIDEO_SUFFIXES, save_frames

__all__ = [
    "Canvas",
    "render_world",
    "view_bounds",
    "entity_geoms",
    "bounds_geoms",
    "comm_geoms",
    "save_frames",
    "VIDEO_SUFFIXES",
]
