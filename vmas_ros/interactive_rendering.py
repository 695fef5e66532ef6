"""VMAS's module path ``vmas.interactive_rendering``: the keyboard player lives in vmas_ros/viz/interactive.py.

``InteractiveEnv`` is VMAS's name for the player class; ours is ``InteractivePlayer``.
"""
from vmas_ros.viz.interactive import InteractivePlayer, render_interactively

InteractiveEnv = InteractivePlayer

__all__ = ["InteractiveEnv", "InteractivePlayer", "render_interactively"]
