"""VMAS 1.5.2's public names against vmas_ros's, module by module (see docs/vmas_compat.md).

Every line of VMAS's surface (names, class attributes, signatures) must exist in
vmas_ros's module at the same path, unless ALLOWED lists it with a reason. The
same list is the table in docs/vmas_compat.md; a test keeps the two in step.
"""
import importlib
import re
from pathlib import Path

import pytest

from test.compat.vmas_names import VMAS_MODULES, missing, missing_module_names, ours, vmas_scenario_modules

DOC = Path(__file__).resolve().parents[2] / "docs" / "vmas_compat.md"

_IMPORTED = "names VMAS's module imports for its own use; import them from their home modules"
_ENGINE = "engine internals: our world is struct-of-arrays, entities are views into batched tensors"
_INTEGRATORS = "the dynamics integrate in their own private helpers, not these public methods"
#: VMAS's road_traffic module's own classes and helpers
_ROAD_TRAFFIC_INTERNALS = " ".join([
    "Parameters Normalizers Rewards Penalties Thresholds ReferencePathsMapRelated ReferencePathsAgentRelated",
    "Distances Timer Collisions Constants CircularBuffer StateBuffer InitialStateBuffer Observations",
    "parse_point parse_bound get_center_length_yaw_polyline parse_lanelet parse_intersections get_map_data",
    "get_rectangle_vertices get_perpendicular_distances get_short_term_reference_path exponential_decreasing_fcn",
    "get_distances_between_agents interX transform_from_global_to_local_coordinate angle_eliminate_two_pi",
    "get_reference_lanelet_index calculate_reference_path get_reference_paths",
])
_ROWS = [  # (VMAS module, top-level names, reason): deliberate differences; "*" covers a whole module
    ("vmas.interactive_rendering", "*", "keyboard player is ours (pygame, not pyglet); render_interactively adds steps/fps"),
    ("vmas.make_env", "make_env", "ours adds compile_physics (by default eager, then compiled once a run is "
                                  "long; False for bit parity) and gives num_envs a default of 32"),
    ("vmas.make_env", "BaseScenario Environment Wrapper", _IMPORTED),
    ("vmas.simulator.core", "Action AgentState EntityState",
     "state and action objects are views into the world's batched tensors; the world moves them (World.to)"),
    ("vmas.simulator.core", "Box Line Sphere", "shape sizes are plain attributes, read the same way"),
    ("vmas.simulator.core", "TorchVectorizedObject", _ENGINE),
    ("vmas.simulator.core", "World",
     "no update_env_forces: contact forces are summed inside the batched step, not per entity pair"),
    ("vmas.simulator.physics", "TorchUtils", _IMPORTED),
    ("vmas.simulator.rendering", "*", "our renderer draws with Pillow, headless; pyglet's Viewer classes differ"),
    ("vmas.simulator.heuristic_policy", "BaseHeuristicPolicy RandomPolicy", "continuous_action keeps a default (True)"),
    ("vmas.simulator.joints", "JointConstraint", "joints are drawn by the renderer, not by a render method"),
    ("vmas.simulator.joints", "TYPE_CHECKING UNCOLLIDABLE_JOINT_RENDERING_WIDTH", _IMPORTED),
    ("vmas.simulator.scenario", "Agent World", _IMPORTED),
    ("vmas.simulator.utils", "ScenarioUtils x_to_rgb_colormap",
     "heat-map and agent-index drawing belong to pyglet's renderer (see render's plot_position_function)"),
    ("vmas.simulator.dynamics.diff_drive", "DiffDrive", _INTEGRATORS),
    ("vmas.simulator.dynamics.diff_drive", "Dynamics", _IMPORTED),
    ("vmas.simulator.dynamics.drone", "Drone", _INTEGRATORS),
    ("vmas.simulator.dynamics.drone", "Dynamics", _IMPORTED),
    ("vmas.simulator.dynamics.forward", "TorchUtils X", _IMPORTED),
    ("vmas.simulator.dynamics.kinematic_bicycle", "KinematicBicycle", _INTEGRATORS),
    ("vmas.simulator.dynamics.kinematic_bicycle", "Dynamics", _IMPORTED),
    ("vmas.simulator.environment.environment", "Environment",
     "render draws headless (default mode rgb_array) and has no plot_function/plot_boundary heat maps; "
     "randomness is per env (seed), not the class-wide vmas_random_state"),
    ("vmas.simulator.environment.environment",
     "ALPHABET Agent BaseScenario TorchUtils TorchVectorizedObject X Y local_seed override", _IMPORTED),
    ("vmas.simulator.environment.rllib", "Environment TorchUtils", _IMPORTED),
    ("vmas.simulator.environment.gym.base", "BaseGymWrapper",
     "each wrapper defines reset, step and render with its own library's signature"),
    ("vmas.simulator.environment.gym.base", "EnvData", "VMAS-internal record of one step; not used by our wrappers"),
    ("vmas.simulator.environment.gym.base", "Environment TorchUtils extract_nested_with_index", _IMPORTED),
    ("vmas.simulator.environment.gym.gym", "GymWrapper", "render forwards env_index too (None: env 0)"),
    ("vmas.simulator.environment.gym.gym", "BaseGymWrapper Environment", _IMPORTED),
    ("vmas.examples.use_vmas_env", "Agent", _IMPORTED),
    ("vmas.examples.rllib", "*", "VMAS's script needs ray and wandb; ours points at vmas_ros/envs/rllib_env.py"),
    ("vmas.scenarios.football", "AgentPolicy Splines ball_action_script",
     "football's AI is ours (vmas_ros/scenarios/football_ai.py), with classes and a ball script of its own"),
    ("vmas.scenarios.road_traffic", _ROAD_TRAFFIC_INTERNALS,
     "road_traffic's internals: ours reads the same map and gives the same observations and rewards, built "
     "from modules of its own (vmas_ros/scenarios/road_traffic/)"),
]
#: (VMAS module, top-level name) -> reason
ALLOWED = {(module, name): reason for module, names, reason in _ROWS for name in names.split()}


def _allowed(line: str) -> bool:
    module, rest = line.split(": ", 1)
    name = re.split(r"[.(:]", rest)[0]
    return (module, name) in ALLOWED or (module, "*") in ALLOWED


@pytest.mark.parametrize("vmas_path", VMAS_MODULES)
def test_every_vmas_name_exists_at_the_same_path(vmas_path):
    unexplained = sorted(line for line in missing(vmas_path) if not _allowed(line))
    assert not unexplained, f"{ours(vmas_path)} lacks VMAS's:\n" + "\n".join(unexplained)


@pytest.mark.parametrize("vmas_path", vmas_scenario_modules())
def test_every_scenario_modules_own_names_exist_at_the_same_path(vmas_path):
    """Module-level constants and helpers of VMAS's scenario modules (``DEFAULT_ENERGY_COEFF``, the angle
    helpers): VMAS code imports them from the scenario's module."""
    unexplained = sorted(line for line in missing_module_names(vmas_path) if not _allowed(line))
    assert not unexplained, f"{ours(vmas_path)} lacks VMAS's:\n" + "\n".join(unexplained)


def test_the_scenario_modules_are_all_compared():
    assert len(vmas_scenario_modules()) >= 40


def test_allowlist_is_the_one_in_the_docs():
    rows = re.findall(r"^\| `([\w.]+)` \| ((?:`[\w*]+`(?:, )?)+) \| (.+?) \|$", DOC.read_text(), re.M)
    documented = [(m, " ".join(re.findall(r"`([\w*]+)`", names)), r) for m, names, r in rows]
    assert documented == _ROWS


@pytest.mark.parametrize("module, name", [key for key in ALLOWED if key[1] != "*"])
def test_every_allowed_name_is_still_a_difference(module, name):
    """An entry that no longer hides a difference is stale: remove it from the list and the docs."""
    assert any(_allowed(line) and re.split(r"[.(:]", line.split(": ", 1)[1])[0] == name
               for line in missing(module)), f"{module}.{name} matches VMAS now"


@pytest.mark.parametrize("vmas_path", VMAS_MODULES)
def test_module_path_table_imports(vmas_path):
    """Every VMAS path in docs/vmas_compat.md's table imports as vmas_ros at the same relative path."""
    assert f"| `{vmas_path}` | `{ours(vmas_path)}` |" in DOC.read_text()
    importlib.import_module(ours(vmas_path))


def test_make_env_stays_the_function_after_importing_its_module():
    import vmas_ros
    import vmas_ros.make_env  # noqa: F401 - binds the submodule, which must not shadow the function

    assert callable(vmas_ros.make_env) and vmas_ros.make_env.__name__ == "make_env"
    from vmas_ros.make_env import make_env
    assert make_env is vmas_ros.make_env


def test_examples_run():
    from vmas_ros.examples.run_heuristic import run_heuristic
    from vmas_ros.examples.use_vmas_env import use_vmas_env
    from vmas_ros.scenarios.navigation import HeuristicPolicy

    assert use_vmas_env(num_envs=2, n_steps=3, random_action=True) == 3
    assert use_vmas_env(num_envs=2, n_steps=3, dict_spaces=False, scenario_name="navigation") == 3
    assert isinstance(run_heuristic("navigation", heuristic=HeuristicPolicy, n_envs=2, n_steps=3), float)
