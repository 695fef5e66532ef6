"""Headless visualisation: world rendering, frame/video export and the Foxglove bridge.

Nothing here opens a window or imports OpenGL/pyglet, so rendering works on
servers and in CI. Scenario-level drawing primitives (VMAS's ``rendering``
module), the Pillow canvas they draw on and the frame writer (behind VMAS's
``save_video``) live in the simulator (:mod:`vmas_ros.simulator.rendering`,
:mod:`~vmas_ros.simulator.canvas`, :mod:`~vmas_ros.simulator.video`); the
canvas and the writer are re-exported here.
"""
from vmas_ros.simulator.canvas import Canvas
from vmas_ros.viz.scene import bounds_geoms, comm_geoms, entity_geoms, render_world, view_bounds
from vmas_ros.simulator.video import VIDEO_SUFFIXES, save_frames

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
