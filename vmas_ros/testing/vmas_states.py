"""VMAS's per-env draw, written into our shipped scenarios: ``check_scenario``'s default ``scenario_state`` hooks.

``check_scenario``'s ``vmas_parity`` check starts ours where VMAS's reset
left it. Entity states are copied by name; the rest of what a reset draws
(goals, shaping baselines, masses, routes) many shipped scenarios keep in
another form than VMAS does: one [B, n] tensor where VMAS keeps a [B] tensor
on each of n agents, a landmark index per env where VMAS keeps one landmark
for the whole batch. Each hook here reads VMAS's attributes by name and writes
their values into ours, so a user who checks a shipped scenario needs no hook
of their own. The project's parity tests import the same hooks.

``SCENARIO_STATES`` maps a registered name to ``hook(vmas_env, our_env)``;
``check_scenario`` uses it when the scenario under check is that registered
scenario and the caller passes no ``scenario_state``. The scenarios missing
from it keep that state under VMAS's names and shapes, so the copy by name
does the job, or start it at values no draw decides (zeros, nothing eaten).
"""
from __future__ import annotations

from typing import Callable, Dict

import torch

__all__ = ["SCENARIO_STATES", "JOINT_PASSAGE_SHAPING"]

#: our ``joint_passage`` shaping keys -> the attributes of VMAS's ``scenario.joint`` that hold them, [B] each
JOINT_PASSAGE_SHAPING = {
    "pos_pre": "pos_shaping_pre", "pos_post": "pos_shaping_post",
    "rot_pre": "rot_shaping_pre", "rot_post": "rot_shaping_post",
}
#: the passage layout joint_passage_size draws per env, under the same names on both sides
_PASSAGE_SIZE_LAYOUT = ("big_passage_pos", "small_passage_pos", "pass_center", "middle_angle")


def _per_agent(entities, name: str) -> torch.Tensor:
    """VMAS's [B] attribute ``name`` of each entity, stacked as ours keeps it: [B, len(entities)]."""
    return torch.stack([getattr(entity, name) for entity in entities], dim=1).clone()


def _goal_index(up, landmark) -> int:
    """Which of VMAS's landmarks ``landmark`` is: VMAS draws one goal landmark for the whole batch."""
    return up.world.landmarks.index(landmark)


# ------------------------------------------------------------------ MPE
def simple_adversary(up, ours) -> None:
    """VMAS's goal landmark (one for the batch, on every agent as ``goal``) as our [B] index."""
    ours.scenario.goal[:] = _goal_index(up, up.world.agents[0].goal)


def simple_crypto(up, ours) -> None:
    """VMAS's secret (a long tensor shared by every agent) and key (on the speaker, agent 2), as our [B, dim_c]."""
    ours.scenario.secret[:] = up.world.agents[0].secret.float()
    ours.scenario.key[:] = up.world.agents[2].key.float()


def simple_push(up, ours) -> None:
    """VMAS's goal landmark (one for the batch, on the good agent as ``goal``); ``set_goal`` recolours too."""
    ours.scenario.set_goal(torch.tensor(_goal_index(up, up.world.agents[1].goal), device=ours.device))


def simple_reference(up, ours) -> None:
    """Each agent's target (VMAS: one landmark per agent, ``goal_b``) as our [B, 2] indices."""
    for i, agent in enumerate(up.world.agents):
        ours.scenario.goal[:, i] = _goal_index(up, agent.goal_b)


def simple_speaker_listener(up, ours) -> None:
    """VMAS's goal landmark (one for the batch, the speaker's ``goal_b``) as our [B] index."""
    ours.scenario.goal[:] = _goal_index(up, up.world.agents[0].goal_b)


# ------------------------------------------------------------------ main scenarios
def balance(up, ours) -> None:
    """The package's last shaped distance to its goal, [B]."""
    ours.scenario.shaping = up.scenario.global_shaping.clone()


def ball_passage(up, ours) -> None:
    """The ball's last shaped distances to the nearest gap and to the goal (VMAS keeps them on the ball), [B] each."""
    ours.scenario.pre_shaping = up.scenario.ball.pos_shaping_pre.clone()
    ours.scenario.post_shaping = up.scenario.ball.pos_shaping_post.clone()


def ball_trajectory(up, ours) -> None:
    """The three shaping terms' last values, [B] each (VMAS keeps them as separate attributes)."""
    theirs = up.scenario
    ours.scenario.shaping = {
        "pos": theirs.pos_shaping.clone(), "speed": theirs.speed_shaping.clone(), "dist": theirs.dist_shaping.clone(),
    }


def buzz_wire(up, ours) -> None:
    """The ball's last shaped distance to the goal, [B]."""
    ours.scenario.pos_shaping = up.scenario.pos_shaping.clone()


def flocking(up, ours) -> None:
    """The target's clock (its heading), [B], and each agent's last distance shaping, agent-major [n, B]."""
    ours.scenario.t = up.scenario.t.clone()
    ours.scenario.distance_shaping = _per_agent(up.world.policy_agents, "distance_shaping").T.contiguous()


def football(up, ours) -> None:
    """The dense reward's baselines: VMAS takes them from the reset state, so ours restarts them from the copy."""
    ours.scenario.reset_shaping()


def give_way(up, ours) -> None:
    """Each agent's last shaped distance to its goal, [B, 2]."""
    ours.scenario.shaping = _per_agent(up.world.agents, "shaping")


def joint_passage(up, ours) -> None:
    """The rod's four shaping baselines (VMAS keeps them on ``scenario.joint``) and ``passed``, [B] each."""
    for name in ours.scenario.shaping:
        ours.scenario.shaping[name] = getattr(up.scenario.joint, JOINT_PASSAGE_SHAPING[name]).clone()
    ours.scenario.passed = up.scenario.passed.clone()


def joint_passage_size(up, ours) -> None:
    """joint_passage's state, and the passage layout drawn per env (same names on both sides)."""
    joint_passage(up, ours)
    for name in _PASSAGE_SIZE_LAYOUT:
        setattr(ours.scenario, name, getattr(up.scenario, name).clone())


def multi_give_way(up, ours) -> None:
    """Each agent's last shaped distance to its goal, [B, 4]."""
    ours.scenario.shaping = _per_agent(up.world.agents, "shaping")


def navigation(up, ours) -> None:
    """Each agent's last shaped distance to its goal, [B, n]."""
    ours.scenario.pos_shaping = _per_agent(up.world.agents, "pos_shaping")


def passage(up, ours) -> None:
    """Each agent's last shaped distance to its goal, [B, 5]."""
    ours.scenario.global_shaping = _per_agent(up.world.agents, "global_shaping")


def reverse_transport(up, ours) -> None:
    """The package's last shaped distance to its goal and its on-goal flag, [B] each."""
    ours.scenario.potential = up.scenario.package.global_shaping.clone()
    ours.scenario.on_goal = up.scenario.package.on_goal.clone()


def road_traffic(up, ours) -> None:
    """Each car's route and start point (VMAS: ``ref_paths_agent_related``), with what follows from them."""
    paths = up.scenario.ref_paths_agent_related
    rows = torch.arange(up.num_envs, device=ours.device)
    pos, rot, vel = (torch.stack([getattr(a.state, name) for a in up.agents], dim=1) for name in ("pos", "rot", "vel"))
    ours.scenario.set_starts(rows, paths.path_id.long(), paths.point_id.long(), pos, rot[..., 0], vel)


def sampling(up, ours) -> None:
    """The Gaussian centres, their normaliser, the spent cells and each agent's sample at its start."""
    ours.scenario.samples = _per_agent(up.world.agents, "sample")
    ours.scenario.locs = torch.stack(up.scenario.locs, dim=1).clone()
    ours.scenario.max_pdf = up.scenario.max_pdf.clone()
    ours.scenario.sampled = up.scenario.sampled.clone()


def transport(up, ours) -> None:
    """Each package's last shaped distance to the goal and its on-goal flag, [B, n_packages]."""
    ours.scenario.potential = _per_agent(up.scenario.packages, "global_shaping")
    ours.scenario.on_goal = _per_agent(up.scenario.packages, "on_goal")


def wind_flocking(up, ours) -> None:
    """The step count, the shaping baselines (VMAS keeps three of them on each agent) and the big agent's wind."""
    mine, theirs = ours.scenario, up.scenario
    mine.t = theirs.t.clone()
    for name in ("distance_shaping", "rot_shaping", "pos_shaping"):
        setattr(mine, name, getattr(theirs, name).clone())
    for name in ("vel_shaping", "energy_shaping", "wind_shaping"):
        setattr(mine, name, _per_agent(up.world.agents, name))
    mine.big_agent.gravity = theirs.big_agent.gravity.clone()


# ------------------------------------------------------------------ debug worlds
def asym_joint(up, ours) -> None:
    """The rod's last shaped angle to upright (VMAS keeps it on ``scenario.joint``), [B]."""
    ours.scenario.shaping = up.scenario.joint.rot_shaping_pre.clone()


def goal(up, ours) -> None:
    """The last shaped distance to the goal (VMAS keeps it on the goal landmark), [B]."""
    ours.scenario.shaping = up.scenario.goal.pos_shaping.clone()


def het_mass(up, ours) -> None:
    """The agents' masses, drawn at reset (VMAS from NumPy's stream, so ours cannot draw the same)."""
    for theirs, mine in zip(up.agents, ours.agents, strict=True):
        mine.mass = theirs.mass


#: registered scenario name -> ``hook(vmas_env, our_env)`` writing VMAS's per-env draw into ours
SCENARIO_STATES: Dict[str, Callable[[object, object], None]] = {
    hook.__name__: hook for hook in (
        simple_adversary, simple_crypto, simple_push, simple_reference, simple_speaker_listener,
        balance, ball_passage, ball_trajectory, buzz_wire, flocking, football, give_way, joint_passage, joint_passage_size,
        multi_give_way, navigation, passage, reverse_transport, road_traffic, sampling, transport, wind_flocking,
        asym_joint, goal, het_mass,
    )
}
