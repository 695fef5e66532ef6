"""VMAS's package path ``vmas.simulator.environment.gym``: the wrappers live in vmas_ros/envs/.

Each wrapper loads on first use, so importing this package needs neither legacy
``gym`` (an optional extra) nor gymnasium.
"""
import importlib

#: wrapper class -> the module that defines it
_HOMES = {
    "GymWrapper": "vmas_ros.envs.gym_env",
    "GymnasiumWrapper": "vmas_ros.envs.gymnasium_env",
    "GymnasiumVectorizedWrapper": "vmas_ros.envs.gymnasium_vec",
}

__all__ = list(_HOMES)


def __getattr__(name: str):
    if name in _HOMES:
        return getattr(importlib.import_module(_HOMES[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
