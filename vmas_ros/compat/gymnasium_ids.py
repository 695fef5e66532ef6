"""Register vmas_ros's gymnasium ids without importing gymnasium: at once if it is loaded, else when it is.

``import vmas_ros`` must not import gymnasium (it costs time and memory a
ROS node or a training script may never need). So the ids
(``vmas_ros/<scenario>-v0``, :mod:`vmas_ros.envs.gymnasium_registry`) are
registered when both packages are loaded, in whichever order: immediately if
gymnasium was imported first, otherwise by an import hook that registers them
right after gymnasium's own import finishes. ``gymnasium.make("vmas_ros:vmas_ros/navigation-v0")``,
gymnasium's module-prefixed form, also works, as it imports vmas_ros first.
"""
from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
from typing import List, Optional

__all__ = ["NAMESPACE", "VERSION", "env_id", "register_envs", "register_when_gymnasium_loads"]


NAMESPACE = "vmas_ros"
VERSION = 0
#: where the ids' entry points live; gymnasium imports it when an env is made, not when ids are registered
_ENTRY_MODULE = "vmas_ros.envs.gymnasium_registry"


def env_id(scenario: str) -> str:
    """The registered id of ``scenario``: ``vmas_ros/<scenario>-v0``."""
    return f"{NAMESPACE}/{scenario}-v{VERSION}"


def register_envs() -> List[str]:
    """Register ``vmas_ros/<scenario>-v0`` for every scenario (again: nothing); returns the ids.

    Only gymnasium and the scenario names are needed: this may run in the middle of gymnasium's import,
    itself in the middle of vmas_ros's (the Environment imports gymnasium's spaces), so the entry points
    are named as strings, which gymnasium imports when an env is made."""
    import gymnasium

    from vmas_ros.scenarios import list_scenarios

    ids = []
    for scenario in list_scenarios():
        name = env_id(scenario)
        if name not in gymnasium.registry:
            gymnasium.register(id=name, entry_point=f"{_ENTRY_MODULE}:make_single",
                               vector_entry_point=f"{_ENTRY_MODULE}:make_vector", kwargs={"scenario": scenario})
        ids.append(name)
    return ids


def _register() -> None:
    register_envs()


class _RegisterAfterImport(importlib.abc.MetaPathFinder):
    """Finds nothing itself: when ``gymnasium`` is imported, it wraps the real loader so that the ids are
    registered once gymnasium's module has run, then steps out of the import system."""

    def __init__(self) -> None:
        self._used = False

    def find_spec(self, name: str, path=None, target=None) -> Optional[importlib.machinery.ModuleSpec]:
        if name != "gymnasium" or self._used:
            return None
        self._used = True
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        run = spec.loader.exec_module

        def exec_module(module) -> None:
            run(module)
            # (the import system iterates sys.meta_path while it finds a spec: leave only once it is done)
            if self in sys.meta_path:
                sys.meta_path.remove(self)
            _register()

        spec.loader.exec_module = exec_module  # this loader instance serves this one import only
        return spec


def register_when_gymnasium_loads() -> None:
    """Register now if gymnasium is loaded, else as soon as it is (idempotent)."""
    if "gymnasium" in sys.modules:
        _register()
    elif not any(isinstance(finder, _RegisterAfterImport) for finder in sys.meta_path):
        sys.meta_path.insert(0, _RegisterAfterImport())
