"""What sim_node adds to a scenario and takes from it at start: its own lidars, the agents' goals, and
the scenario a policy was trained on.

* **Lidars.** ``add_lidar`` gives an agent without a lidar one; ``robot_lidar``
  gives every agent one, after the sensors the scenario made (a scenario's
  observation reads the lidars it made, which stay where they were). Either way
  the node's lidar has the configured geometry (``lidar_rays``,
  ``lidar_angle_min``/``max``, ``lidar_range``) and is published first, as
  ``<agent>/scan``; the scenario's follow as ``scan_1``, ... Its
  ``lidar_range_min`` goes into its :class:`~vmas_ros.simulator.env_snapshot.ScanGeometry`.
* **Goals.** An agent whose ``goal`` attribute is an entity of the world
  (navigation, give_way, passage) has that goal published as
  ``<agent>/goal``; a scenario with one agent and a ``goal`` entity that no
  other entity claims as its own goal (debug ``goal``; not transport, whose
  goal is the package's) gives that agent the scenario's goal.
* **The policy's scenario.** With ``control: policy``, ``scenario`` and
  ``scenario_kwargs`` come from the policy's metadata unless they were given
  (in code, on the command line or in a parameter file).
"""
from __future__ import annotations

import json
from typing import Any, Dict, List, Mapping

from vmas_ros.simulator import env_snapshot
from vmas_ros.ros.lifecycle import ConfigError
from vmas_ros.ros.params import SIM_PARAMS, validate
from vmas_ros.simulator.sensors import CollidesWith, Lidar

__all__ = ["add_node_lidars", "goal_rows", "parameters_from_policy", "published_lidars", "scan_geometry"]


# ------------------------------------------------------------------ lidars
def add_node_lidars(world, params) -> Dict[int, Lidar]:
    """Agent index -> the lidar the node gave it, as ``robot_lidar`` and ``add_lidar`` say."""
    added: Dict[int, Lidar] = {}
    if not (params.robot_lidar or params.add_lidar):
        return added
    for i, agent in enumerate(world.agents):
        if params.robot_lidar or not any(isinstance(s, Lidar) for s in agent.sensors):
            lidar = Lidar(world, angle_start=params.lidar_angle_min, angle_end=params.lidar_angle_max,
                          n_rays=params.lidar_rays, max_range=params.lidar_range,
                          entity_filter=CollidesWith(agent))
            agent.add_sensor(lidar)  # after the scenario's own: their indices in agent.sensors stay
            added[i] = lidar
    return added


def published_lidars(world, own: Mapping[int, Lidar]) -> Dict[int, List[Lidar]]:
    """Agent index -> its lidars in publishing order: the node's own first (``<agent>/scan``), then the
    scenario's (``scan_1``, ...)."""
    lidars = env_snapshot.agent_lidars(world)
    for i, lidar in own.items():
        lidars[i] = [lidar] + [s for s in lidars[i] if s is not lidar]
    return lidars


def scan_geometry(lidars: Mapping[int, List[Lidar]], own: Mapping[int, Lidar],
                  range_min: float) -> Dict[int, List[env_snapshot.ScanGeometry]]:
    """The LaserScan geometry of every published lidar; ``range_min`` is the node's own lidars' only."""
    return {i: [env_snapshot.ScanGeometry.of(s, range_min if own.get(i) is s else 0.0) for s in sensors]
            for i, sensors in lidars.items()}


# ------------------------------------------------------------------- goals
def goal_rows(world, scenario=None) -> Dict[int, int]:
    """Agent index -> the row in ``world.entities`` of that agent's goal, for the agents that have one."""
    rows = {id(e): k for k, e in enumerate(world.entities)}
    goals = {}
    for i, agent in enumerate(world.agents):
        goal = getattr(agent, "goal", None)
        if id(goal) in rows:
            goals[i] = rows[id(goal)]
    shared = getattr(scenario, "goal", None)
    if not goals and len(world.agents) == 1 and id(shared) in rows:
        claimed = any(getattr(e, "goal", None) is shared for e in world.entities)
        if not claimed:
            goals[0] = rows[id(shared)]
    return goals


# --------------------------------------------------------- policy scenario
def parameters_from_policy(overrides: Mapping[str, Any], given: Mapping[str, Any], logger) -> Dict[str, Any]:
    """``scenario`` and ``scenario_kwargs`` from the policy's metadata, for those of the two that were not
    given, when ``control`` is ``policy`` and a ``policy_path`` is given; said in one log line.

    ``overrides``: the values given in code; ``given``: those of the command
    line and parameter files (rclpy's parameter overrides of the node), which
    count as given whatever their value, the default included.

    The kwargs are taken only for the policy's own scenario: a scenario given
    explicitly that differs from the policy's keeps its own kwargs (and the
    policy check then refuses or warns, as for any policy that does not fit).
    """
    values = {**given, **overrides}
    control = values.get("control", SIM_PARAMS.params["control"].default)
    path = values.get("policy_path", "")
    if control != "policy" or not path or validate("policy_path", path) is not None:
        return {}  # no policy to read: the parameters' own checks say why, if they are wrong
    if "scenario" in values and "scenario_kwargs" in values:
        return {}
    from vmas_ros.policy.onnx_policy import read_metadata

    try:
        json_path, meta = read_metadata(path)
    except ValueError as error:
        raise ConfigError(f"policy_path: {error}") from None
    scenario, kwargs = meta["scenario"], meta["scenario_kwargs"]
    taken, found = [], {}
    if "scenario" not in values:
        if reason := validate("scenario", scenario):
            raise ConfigError(f"policy_path: the policy's metadata {json_path} names scenario {scenario!r}, "
                              f"which this node cannot run: {reason}")
        values["scenario"] = found["scenario"] = scenario
        taken.append(f"scenario {scenario}")
    same = str(values["scenario"]).removesuffix(".py") == scenario.removesuffix(".py")
    if "scenario_kwargs" not in values and same:
        found["scenario_kwargs"] = json.dumps(kwargs)
        taken.append(f"scenario_kwargs {found['scenario_kwargs']}")
    if taken:
        logger.info(f"{' and '.join(taken)} from the policy's metadata {json_path}")
    return found
