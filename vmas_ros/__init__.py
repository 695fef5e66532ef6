"""vmas_ros: a vectorized 2D multi-robot simulator in PyTorch, compatible with VMAS 1.5, for ROS 2."""
from vmas_ros.envs.make_env import make_env
from vmas_ros.scenarios import list_scenarios
from vmas_ros.viz.interactive import render_interactively

__version__ = "0.1.0"

#: scenario names, as VMAS exposes them
scenarios = list_scenarios()
mpe_scenarios = [name for name in scenarios if name.startswith("simple")]

__all__ = ["make_env", "render_interactively", "list_scenarios", "scenarios", "mpe_scenarios", "__version__"]
