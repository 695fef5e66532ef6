"""The space classes an Environment builds: legacy ``gym``'s under ``install_as_vmas()``, else gymnasium's.

VMAS 1.5 builds its spaces with the legacy ``gym`` package, and TorchRL's
``VmasEnv`` converts them with its ``gym`` backend, refusing gymnasium spaces
(``NotImplementedError: spec of type Box is currently unaccounted for vmas``).
Both libraries name the classes alike (``Box``, ``Discrete``, ``MultiDiscrete``,
``Tuple``, ``Dict``) with the same constructor arguments, so the Environment
asks for the module and builds the same spaces from either. The gymnasium-facing
wrappers convert back (``vmas_ros.envs.wrapper_common.to_gymnasium_space``).
"""
from __future__ import annotations

import types

from gymnasium import spaces as gymnasium_spaces

from vmas_ros.compat.install import gym_spaces_enabled

__all__ = ["space_types"]


def space_types() -> types.ModuleType:
    """``gym.spaces`` while ``install_as_vmas()`` is in effect and gym is installed, else ``gymnasium.spaces``."""
    if gym_spaces_enabled():
        from gym import spaces as gym_spaces  # the optional extra vmas_ros[gym]

        return gym_spaces
    return gymnasium_spaces
