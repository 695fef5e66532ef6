"""The scripted football team: one decentralised policy, run in the simulator or from observations.

Every decision is taken in the *team frame*, where the team attacks towards
+x (for red, world x is mirrored; this is also the frame of red's
observations). An agent needs only its own state, the ball's and its
teammates' positions, all of which its observation holds, so the same
``plan`` drives

* ``TeamAI``: the in-simulator controller (an ``action_script``) behind
  ``ai_red_agents=True`` / ``ai_blue_agents=True``, which plans the whole team
  in one batched call per step from the world state; and
* ``HeuristicPolicy``: the same player computed from one agent's observation,
  for policy-controlled agents of either team.

How a team plays (``plan``)
    Each agent ranks its team by how cheaply each player can reach where the
    ball will be (distance, plus a penalty for standing upfield of it, which
    means a detour). Everyone ranks with the same data, so roles agree
    without communication:

    * rank 0, the *chaser*, dribbles: it lines up behind the ball on the line
      from the ball to the opponents' goal (going round the ball if it is on
      the wrong side) and, once inside a narrow cone behind it, drives
      through the ball towards the goal, steering out any sideways offset
      (an off-centre hit deflects the ball). Coming from the goal side also
      makes it the first defender when the opponents have the ball. With the
      shooting actions it turns to face the goal and kicks when the ball is
      in its kicking sector.
    * rank 1 (teams of three or more), the *escort*, presses right behind
      the chaser while it pushes (a second body in every shoving match) and
      otherwise waits a little behind the ball.
    * the last rank (teams of two or more), the *keeper*, stands on the line
      from its own goal to the ball, close to the goal mouth.
    * any others *support*: a little behind the ball, spread to either side,
      to pick up rebounds and cut counter-attacks. Supporters and the keeper
      keep some room from their teammates.

    A desired velocity becomes an action by a one-step (dead-beat) velocity
    controller that knows the world's drag and the agent's force multiplier.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import Tensor

from vmas_ros.scenarios.common import heuristic_kwargs
from vmas_ros.scenarios.football_field import DEFAULTS
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy

#: the world's drag and time step (football's world constants; the controller inverts them)
DRAG, DT = 0.05, 0.1
#: seconds of ball motion to anticipate per second of the agent's trip to the ball, and the cap
BALL_LEAD, MAX_LEAD = 0.6, 1.5
#: extra ranking cost per metre an agent stands upfield of the ball
UPFIELD_PENALTY = 0.5
#: the chaser pushes when its lateral offset from the ball-goal line is below this fraction of
#: (its distance behind the ball + contact distance): a cone of about 14 degrees
ALIGN_CONE = 0.25
#: 1/s: while pushing, how fast the chaser removes its sideways offset from the ball-goal line
LATERAL_GAIN = 5.0
#: gaps (m) kept to the ball when lining up behind it and when going round it
STAGING_GAP, SIDE_GAP = 0.04, 0.05
#: the point aimed at, this far behind the goal line (m), and at most this fraction of the
#: goal's half-width off centre (on the ball's side, which flattens the approach from wide)
AIM_DEPTH, AIM_SPREAD = 0.1, 0.6
#: keeper's distance from its goal centre (m); supporters' offset behind and beside the ball (m)
KEEPER_RADIUS, SUPPORT_BACK, SUPPORT_SIDE = 0.3, 0.3, 0.35
#: the escort's target overlaps the chaser by this fraction of a diameter (so it pushes)
ESCORT_OVERLAP = 0.9
#: teammates closer than this (m) push each other apart (not the chaser and its escort)
SPACING = 0.25
#: 1/s: how fast a player closes on a static target before it slows down
APPROACH_GAIN = 3.0
#: shooting: heading gain, cone (rad) within which the ball must lie ahead, range from the goal (m)
TURN_GAIN, KICK_CONE, SHOT_RANGE = 3.0, math.pi / 6, 1.2


class TeamView(NamedTuple):
    """What one agent knows, in its team frame; rows are (env, agent) pairs."""

    pos: Tensor  # [R, 2] own position
    vel: Tensor  # [R, 2] own velocity
    ball: Tensor  # [R, 2] ball position
    ball_vel: Tensor  # [R, 2] ball velocity
    mates: Tensor  # [R, T, 2] teammates' positions (T may be 0)


class Plan(NamedTuple):
    """What the agent wants to do this step, in its team frame."""

    velocity: Tensor  # [R, 2] desired velocity
    target: Tensor  # [R, 2] the point it is heading for
    heading: Tensor  # [R] angle it wants to face (towards the goal it attacks)
    kick: Tensor  # [R] bool: kick now (only used with the shooting actions)


class PitchSpec(NamedTuple):
    """The sizes the AI reasons with (from the scenario's kwargs)."""

    half_length: float
    half_width: float
    goal_half: float
    agent_size: float
    ball_size: float
    max_speed: float
    shooting_radius: float

    @classmethod
    def from_kwargs(cls, cfg: dict) -> PitchSpec:
        return cls(
            cfg["pitch_length"] / 2, cfg["pitch_width"] / 2, cfg["goal_size"] / 2, cfg["agent_size"],
            cfg["ball_size"], cfg["max_speed"], cfg["shooting_radius"],
        )


def _unit(v: Tensor) -> Tensor:
    return v / torch.linalg.vector_norm(v, dim=-1, keepdim=True).clamp_min(1e-9)


def _inside(point: Tensor, spec: PitchSpec, margin: float) -> Tensor:
    """``point`` clamped to the pitch shrunk by ``margin``."""
    limit = torch.tensor([spec.half_length - margin, spec.half_width - margin], device=point.device)
    return torch.maximum(torch.minimum(point, limit), -limit)


def _toward(target: Tensor, pos: Tensor, speed_cap: float) -> Tensor:
    """Velocity towards ``target``, at ``speed_cap`` far away and slowing down near it."""
    gap = target - pos
    dist = torch.linalg.vector_norm(gap, dim=-1, keepdim=True)
    return _unit(gap) * torch.clamp(dist * APPROACH_GAIN, max=speed_cap)


class _Chase(NamedTuple):
    """The chaser's geometry for one ball position (all [R, ...])."""

    line: Tensor  # [R, 2] unit direction from the ball to the aim point in the goal
    aligned: Tensor  # [R, 1] bool: inside the cone behind the ball, ready to push
    target: Tensor  # [R, 2] where to go next
    velocity: Tensor  # [R, 2] desired velocity


def _chase(pos: Tensor, ball: Tensor, spec: PitchSpec) -> _Chase:
    """Line up behind ``ball`` on its line to the goal (round it if needed), then drive through it."""
    vmax, contact = spec.max_speed, spec.agent_size + spec.ball_size
    aim = torch.stack([
        torch.full_like(ball[:, 0], spec.half_length + AIM_DEPTH),
        ball[:, 1].clamp(-spec.goal_half * AIM_SPREAD, spec.goal_half * AIM_SPREAD),
    ], dim=-1)
    line = _unit(aim - ball)
    rel = pos - ball
    along = (rel * line).sum(dim=-1, keepdim=True)  # < 0: behind the ball
    off_line = rel - along * line
    lateral = torch.linalg.vector_norm(off_line, dim=-1, keepdim=True)
    normal = torch.stack([-line[:, 1], line[:, 0]], dim=-1)
    side = torch.where(lateral > 1e-6, off_line / lateral.clamp_min(1e-9), normal)
    aligned = (along < -0.5 * contact) & (lateral < ALIGN_CONE * (contact - along))
    in_front = along > -0.7 * contact
    behind_point = ball - line * (contact + STAGING_GAP)
    round_point = ball + side * (contact + SIDE_GAP) - line * contact
    target = torch.where(aligned, ball + line * contact, torch.where(in_front, round_point, behind_point))
    target = _inside(target, spec, spec.agent_size)
    # pushing: full speed along the line while closing the sideways offset (an off-centre hit
    # deflects the ball); otherwise full speed to the next waypoint (the chaser never slows down)
    push = _unit(line * vmax - off_line * LATERAL_GAIN) * vmax
    velocity = torch.where(aligned, push, _unit(target - pos) * vmax)
    return _Chase(line, aligned, target, velocity)


def plan(view: TeamView, spec: PitchSpec, cost_noise: Tensor | None = None, target_noise: Tensor | None = None) -> Plan:
    """Every row's role and desired motion (see the module docstring); all rows at once.

    ``cost_noise`` [R] blurs the agent's own ranking cost (poor decisions) and
    ``target_noise`` [R, 2] its target (poor precision); both default to none.
    """
    vmax, size = spec.max_speed, spec.agent_size
    to_ball = torch.linalg.vector_norm(view.ball - view.pos, dim=-1, keepdim=True)
    lead = torch.clamp(to_ball / vmax * BALL_LEAD, max=MAX_LEAD)
    ball = _inside(view.ball + view.ball_vel * lead, spec, spec.ball_size)

    # ---- roles: rank the team (self first, then mates) by the cost of reaching the ball
    team = torch.cat([view.pos.unsqueeze(1), view.mates], dim=1)  # [R, T + 1, 2]
    cost = torch.linalg.vector_norm(team - ball.unsqueeze(1), dim=-1) + UPFIELD_PENALTY * torch.relu(
        team[..., 0] - ball[:, :1]
    )
    if cost_noise is not None:
        cost = torch.cat([cost[:, :1] + cost_noise.unsqueeze(-1), cost[:, 1:]], dim=1)
    n_mates = view.mates.shape[1]
    rank = (cost[:, 1:] < cost[:, :1]).sum(dim=-1)
    chaser, escort = rank == 0, (rank == 1) & (n_mates > 1)
    keeper = (rank == n_mates) & (n_mates > 0)
    mine = _chase(view.pos, ball, spec)

    # ---- escort: right behind the chaser while it pushes (a second body in every shoving match)
    leader = team[torch.arange(team.shape[0], device=team.device), cost.argmin(dim=1)]
    leading = _chase(leader, ball, spec)
    behind_leader = leader - leading.line * (2 * size * ESCORT_OVERLAP)
    hang_back = ball - leading.line * SUPPORT_BACK
    escort_target = torch.where(leading.aligned, behind_leader, hang_back)
    close = torch.linalg.vector_norm(escort_target - view.pos, dim=-1, keepdim=True) < 2 * size
    escort_velocity = torch.where(leading.aligned & close, leading.line * vmax, _unit(escort_target - view.pos) * vmax)

    # ---- keeper: between the ball and its own goal
    own_goal = torch.tensor([-spec.half_length, 0.0], device=ball.device)
    from_goal = ball - own_goal
    reach = torch.clamp(0.5 * torch.linalg.vector_norm(from_goal, dim=-1, keepdim=True), max=KEEPER_RADIUS)
    keeper_target = own_goal + _unit(from_goal) * reach
    keeper_target = torch.stack([keeper_target[:, 0].clamp_min(-spec.half_length + 2 * size), keeper_target[:, 1]], -1)

    # ---- supporters: behind the ball, even ranks towards the middle, odd ranks wide
    towards_middle = -torch.where(ball[:, 1:2] >= 0, 1.0, -1.0)
    side_sign = torch.where((rank % 2 == 0).unsqueeze(-1), towards_middle, -towards_middle)
    support_target = ball + torch.cat([torch.full_like(side_sign, -SUPPORT_BACK), side_sign * SUPPORT_SIDE], dim=-1)
    support_target = _inside(support_target, spec, 3 * size)

    def by_role(for_chaser: Tensor, for_escort: Tensor, for_keeper: Tensor, for_support: Tensor) -> Tensor:
        pick = torch.where(keeper.unsqueeze(-1), for_keeper, for_support)
        return torch.where(chaser.unsqueeze(-1), for_chaser, torch.where(escort.unsqueeze(-1), for_escort, pick))

    target = by_role(mine.target, escort_target, keeper_target, support_target)
    if target_noise is not None:
        target = target + target_noise
    settle = _toward(target, view.pos, vmax)
    velocity = by_role(mine.velocity, escort_velocity, settle, settle)
    if n_mates:  # the keeper and supporters keep room from their teammates
        gap = view.pos.unsqueeze(1) - view.mates  # [R, T, 2]
        dist = torch.linalg.vector_norm(gap, dim=-1, keepdim=True)
        room = (_unit(gap) * torch.relu(SPACING - dist) / SPACING).sum(dim=1) * vmax
        velocity = velocity + torch.where((chaser | escort).unsqueeze(-1), 0.0, room)

    heading = torch.atan2(mine.line[:, 1], mine.line[:, 0])
    bearing = torch.atan2(ball[:, 1] - view.pos[:, 1], ball[:, 0] - view.pos[:, 0])
    kick = (
        chaser
        & (to_ball.squeeze(-1) <= spec.shooting_radius)
        & (_wrap(bearing - heading).abs() < KICK_CONE)
        & (spec.half_length - ball[:, 0] < SHOT_RANGE)
    )
    return Plan(velocity, target, heading, kick)


def _wrap(angle: Tensor) -> Tensor:
    return torch.remainder(angle + math.pi, 2 * math.pi) - math.pi


def velocity_action(velocity: Tensor, current: Tensor, u_multiplier: Tensor | float, strength: float = 1.0) -> Tensor:
    """The movement action [R, 2] (in [-1, 1]) that best reaches ``velocity`` in one step.

    Inverts one step of the world (drag, then the force times ``DT``; mass
    1): ``u = (v_wanted - (1 - drag) v) / (u_multiplier * dt)``, scaled down
    as a whole (keeping its direction) until every component fits in
    [-1, 1], then times ``strength``.
    """
    u = (velocity - (1 - DRAG) * current) / (u_multiplier * DT)
    biggest = u.abs().amax(dim=-1, keepdim=True).clamp_min(1.0)
    return u / biggest * strength


def shooting_action(heading: Tensor, rot: Tensor, kick: Tensor) -> Tensor:
    """The rotation and kick columns [R, 2]: turn towards ``heading``, kick at full power when asked."""
    turn = torch.clamp(TURN_GAIN * _wrap(heading - rot), -1.0, 1.0)
    return torch.stack([turn, kick.float()], dim=-1)


class TeamAI:
    """The in-simulator controller of one team: the ``action_script`` of each of its agents.

    On the team's first agent of a step it plans the whole team in one
    batched call from the world state (mirrored for red) and stores every
    agent's action; each agent's script then takes its own row. Actions are
    in [-1, 1] times ``ai_strength``, then times the agent's ``u_multiplier``
    (as the environment does for policy agents). With the shooting actions
    the rotation column turns the agent towards the goal; AI kicks are not
    applied (only policy agents shoot, as upstream). ``ai_decision_strength``
    and ``ai_precision_strength`` below 1 add Gaussian noise to the role
    ranking and the targets.
    """

    def __init__(self, spec: PitchSpec, mirrored: bool, strength: float = 1.0, decision: float = 1.0,
                 precision: float = 1.0, disabled: bool = False) -> None:
        self.spec, self.mirrored, self.disabled = spec, mirrored, disabled
        self.strength, self.decision, self.precision = strength, decision, precision
        self.team: list = []
        self._actions: list = []

    def bind(self, team: list, ball, traj_points: list | None = None) -> None:
        """Attach the team's agents (in world order), the ball and optional trajectory markers per agent."""
        n = len(team)
        self.team, self.ball = team, ball
        self.index = {agent.name: i for i, agent in enumerate(team)}
        self.traj_points = traj_points or [[] for _ in team]
        device = team[0].device
        others = [[j for j in range(n) if j != i] for i in range(n)]
        self.others = torch.tensor(others, dtype=torch.long, device=device).reshape(n, n - 1)
        self.flip = torch.tensor([-1.0 if self.mirrored else 1.0, 1.0], device=device)

    def __call__(self, agent, world) -> None:
        i = self.index[agent.name]
        if i == 0:
            self._actions = self._team_actions(world)
        agent.action.u = self._actions[i]

    def _team_actions(self, world) -> list:
        team, n = self.team, len(self.team)
        if self.disabled:
            return [torch.zeros(world.batch_dim, a.action_size, device=world.device) for a in team]
        flip = self.flip = self.flip.to(world.device)
        self.others = self.others.to(world.device)
        pos = torch.stack([a.state.pos for a in team], dim=1) * flip  # [B, n, 2]
        vel = torch.stack([a.state.vel for a in team], dim=1) * flip
        batch = pos.shape[0]
        ball = (self.ball.state.pos * flip).unsqueeze(1).expand(batch, n, 2)
        ball_vel = (self.ball.state.vel * flip).unsqueeze(1).expand(batch, n, 2)
        view = TeamView(
            pos.reshape(-1, 2), vel.reshape(-1, 2), ball.reshape(-1, 2), ball_vel.reshape(-1, 2),
            pos[:, self.others].reshape(batch * n, n - 1, 2),
        )
        cost_noise = target_noise = None
        if self.decision < 1:
            cost_noise = torch.randn(batch * n, device=pos.device) * 0.5 * (1 - self.decision)
        if self.precision < 1:
            target_noise = torch.randn(batch * n, 2, device=pos.device) * 0.2 * (1 - self.precision)
        wish = plan(view, self.spec, cost_noise, target_noise)
        multipliers = torch.stack([a.action.u_multiplier_tensor[:2] for a in team]).repeat(batch, 1)
        move = velocity_action(wish.velocity, view.vel, multipliers, self.strength).reshape(batch, n, 2) * flip
        self._plot(wish.target.reshape(batch, n, 2) * flip, pos * flip)
        actions = []
        for i, agent in enumerate(team):
            u = move[:, i]
            if agent.action_size == 4:
                rot = agent.state.rot[:, 0]
                heading = wish.heading.reshape(batch, n)[:, i]
                # mirroring x maps an angle a to pi - a, so plan in the mirrored angle and turn the other way
                extra = shooting_action(heading, math.pi - rot if self.mirrored else rot, torch.zeros_like(rot, dtype=torch.bool))
                extra[:, 0] = -extra[:, 0] if self.mirrored else extra[:, 0]
                u = torch.cat([u, extra * self.strength], dim=-1)
            actions.append(u * agent.action.u_multiplier_tensor)
        return actions

    def _plot(self, target: Tensor, pos: Tensor) -> None:
        """Put each agent's trajectory markers on the segment from it to its target."""
        for i, markers in enumerate(self.traj_points):
            for k, marker in enumerate(markers):
                u = k / max(len(markers) - 1, 1)
                marker.set_pos(pos[:, i] + (target[:, i] - pos[:, i]) * u, batch_index=None)


class HeuristicPolicy(BaseHeuristicPolicy):
    """The scripted player (``plan``) computed from one agent's own observation.

    The observation layout depends on the scenario's kwargs, so the policy
    takes them (defaults are the scenario's): team sizes, what is observed,
    ``enable_shooting`` and the pitch sizes. ``team`` ("blue", the default, or
    "red") says which team's agents it will play: the layouts differ when the
    teams differ in size, and red's observed heading is offset by pi. Accepts
    a flat observation or, with ``dict_obs=True``, the dict one. Returns
    [batch, 2] (or [batch, 4] with shooting) clamped to ``u_range``.
    """

    def __init__(self, continuous_action: bool = True, team: str = "blue", **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        heuristic_kwargs("football", DEFAULTS, scenario_kwargs)  # refuses unknown kwargs
        if team not in ("blue", "red"):
            raise ValueError(f"football HeuristicPolicy: team must be 'blue' or 'red', got {team!r}")
        cfg = {**DEFAULTS, **scenario_kwargs}
        self.team, self.spec = team, PitchSpec.from_kwargs(cfg)
        self.shooting, self.u_multiplier = cfg["enable_shooting"], cfg["u_multiplier"]
        own, other = ("n_blue_agents", "n_red_agents") if team == "blue" else ("n_red_agents", "n_blue_agents")
        self.n_adversaries = cfg[other] if cfg["observe_adversaries"] else 0
        self.n_mates = cfg[own] - 1 if cfg["observe_teammates"] else 0
        self.goal = torch.tensor([self.spec.half_length + cfg["ball_size"] / 2, 0.0])
        self.head = 12 + int(self.shooting)  # the "obs" block: force, ball, [rot]
        self.width = self.head + 4 + 8 * (self.n_adversaries + self.n_mates)

    def compute_action(self, observation, u_range: float) -> Tensor:
        obs = self._flat(observation)
        if obs.shape[1] != self.width:
            raise ValueError(
                f"football heuristic: observation width {obs.shape[1]} does not match the expected {self.width} "
                f"(team={self.team!r}, {self.n_adversaries} adversaries, {self.n_mates} teammates observed)"
            )
        goal = self.goal.to(obs.device)
        pos = obs[:, self.head:self.head + 2] + goal
        vel = obs[:, self.head + 2:self.head + 4]
        ball = obs[:, 6:8] + goal
        mates_start = self.head + 4 + 8 * self.n_adversaries
        mates = pos.unsqueeze(1) - obs[:, mates_start:].reshape(obs.shape[0], self.n_mates, 8)[..., :2]
        wish = plan(TeamView(pos, vel, ball, obs[:, 8:10], mates), self.spec)
        action = velocity_action(wish.velocity, vel, self.u_multiplier)
        if self.shooting:
            rot = obs[:, 12] if self.team == "blue" else -obs[:, 12]  # red sees rot - pi; mirrored is pi - rot
            action = torch.cat([action, shooting_action(wish.heading, rot, wish.kick)], dim=-1)
        return (action * u_range).clamp(-u_range, u_range)

    @staticmethod
    def _flat(observation) -> Tensor:
        if isinstance(observation, dict):
            parts = [observation[k].flatten(1) for k in ("obs", "pos", "vel", "adversaries", "teammates") if k in observation]
            return torch.cat(parts, dim=-1)
        return observation
