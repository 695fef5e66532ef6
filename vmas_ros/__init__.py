"""vmas_ros: a vectorized 2D multi-robot simulator in PyTorch, compatible with VMAS 1.5, for ROS 2."""
from vmas_ros.envs.make_env import make_env
from vmas_ros.scenarios import list_scenarios

__version__ = "0.1.0"

#: scenario names, as VMAS exposes them
scenarios = list_scenarios()
mpe_scenarios = [name for name in scenarios if name.startswith("simple")]


def __getattr__(name: str):
    # imported on first use: the viewer pulls in Pillow, which a headless training run never needs
    if name == "render_interactively":
        from vmas_ros.viz.interactive import render_interactively

        return render_interactively
    raise AttributeError(f"module 'vmas_ros' has no attribute {name!r}")


__all__ = ["make_env", "render_interactively", "list_scenarios", "scenarios", "mpe_scenarios", "__version__"]
