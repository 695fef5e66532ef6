"""vmas_ros: a vectorized 2D multi-robot simulator in PyTorch, compatible with VMAS 1.5, for ROS 2.

``import vmas_ros`` stays light (the scenario registry only): ``make_env`` and
the engine, which pull in torch, load on first use. A node's entry point
(``python -m vmas_ros.ros.sim_node``) imports this package before anything
else, and must be able to install its signal handlers before torch's second of
imports (see vmas_ros/ros/signal_guard.py).
"""
import importlib
import sys
import types

from vmas_ros.compat.version import __version__
from vmas_ros.scenarios import DEBUG_SCENARIOS, MAIN_SCENARIOS, MPE_SCENARIOS, list_scenarios  # no scenario imported

# gymnasium.make("vmas_ros/<scenario>-v0"): registered once gymnasium is loaded, never importing it here
from vmas_ros.compat.gymnasium_ids import register_when_gymnasium_loads  # noqa: E402

register_when_gymnasium_loads()

#: scenario names in VMAS's three lists (``list_scenarios()`` gives all of them)
scenarios = list(MAIN_SCENARIOS)
debug_scenarios = list(DEBUG_SCENARIOS)
mpe_scenarios = list(MPE_SCENARIOS)

#: subpackages reachable as attributes (``vmas_ros.envs.wrap``) without importing them first
_SUBPACKAGES = ("bench", "envs", "policy", "record", "ros", "simulator", "testing", "train", "viz")


def __getattr__(name: str):
    # imported on first use: torch for make_env; Pillow for the viewer, which a headless run never needs
    if name == "make_env":
        from vmas_ros.envs.make_env import make_env

        globals()["make_env"] = make_env
        return make_env
    if name == "render_interactively":
        from vmas_ros.interactive_rendering import render_interactively

        return render_interactively
    if name == "Wrapper":  # VMAS's top level offers the enum of wrapper names
        from vmas_ros.simulator.environment import Wrapper

        return Wrapper
    if name == "install_as_vmas":  # vmas_ros/compat/install.py: ``import vmas`` resolves to vmas_ros
        from vmas_ros.compat.install import install_as_vmas

        return install_as_vmas
    if name in _SUBPACKAGES:
        return importlib.import_module(f"vmas_ros.{name}")
    raise AttributeError(f"module 'vmas_ros' has no attribute {name!r}")


__all__ = [
    "make_env", "render_interactively", "list_scenarios", "scenarios", "debug_scenarios", "mpe_scenarios",
    "install_as_vmas", "__version__",
]


class _Package(types.ModuleType):
    """This package's module type: keeps ``vmas_ros.make_env`` the function.

    Importing the submodule ``vmas_ros.make_env`` (VMAS's module path) would
    otherwise bind the module to that name on this package, shadowing the function.
    """

    def __setattr__(self, name: str, value) -> None:
        if name == "make_env" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
