"""football: two teams of discs play football on a walled pitch with goals.

Description
    ``n_blue_agents`` blue players attack the right goal, ``n_red_agents`` red
    players the left one (paper, "Multi-robot scenarios"). The ball is a light
    agent ("Ball") moved only by contacts, plus a small scripted nudge that
    keeps a slow ball off the pitch's edges. Goal-line walls run from each goal
    post to the corners; the side lines are the world's y limits. Red can be
    the scripted team of ``football_ai`` (``ai_red_agents``, default) and so
    can blue (``ai_blue_agents``); scripted agents are not policy agents. With
    ``enable_shooting`` policy agents also steer their heading and kick: the
    ball is kicked along the heading when it lies within ``shooting_radius``
    and ``shooting_angle`` of the kicker and the kicker is the player closest
    to it. Red policy agents act in their own mirrored frame: the x components
    of their move (and their rotation) are negated.
Observation (per agent, in its team's frame: x mirrored for red)
    ``obs``: own force (2), own position - ball (2), own velocity - ball's (2),
    ball - attacked goal (2), ball velocity (2), ball force (2), [own heading
    (1) with shooting; red's is offset by -pi]; ``pos``: own position - goal
    (2); ``vel``: own velocity (2); ``adversaries`` (if observed): per
    opponent own position - theirs, own velocity - theirs, their velocity,
    their force (8); ``teammates`` (if observed and any): the same per
    teammate. Flat concatenation in this order, or a dict of these blocks with
    ``dict_obs`` (adversaries and teammates then [n, 8]).
Reward (shared by a team)
    ``scoring_reward`` for a goal scored, minus it for one conceded. With
    ``dense_reward`` (non-scripted teams only): ``pos_shaping_factor_ball_goal``
    times the decrease of the ball's distance to the attacked goal, plus
    ``pos_shaping_factor_agent_ball`` times the decrease of the team's closest
    distance to the ball while that is at least ``distance_to_ball_trigger``
    and the ball is at rest.
Starting state
    Ball at rest at the centre. Blue uniform in its half, red in the other
    half facing left (or in columns with ``spawn_in_formation``).
Episode termination
    When the whole ball is past a goal line inside the goal mouth.
Kwargs
    See ``football_field.DEFAULTS`` (VMAS 1.5.2's names and defaults). Both
    team sizes must be >= 1; ``physically_different`` needs 5 blue agents.
Differences from VMAS 1.5.2 (on purpose)
    Rewards and done are computed once per step after the physics, so they
    stay right when blue is scripted (upstream then never refreshes them). With
    one-player teams the empty teammates block is left out (upstream fails).
    Red faces left after a formation spawn too. Blue's index labels are not drawn.
    The scripted team is our own ``football_ai``, written from the task's
    description, not VMAS's AI: scripted players move differently from VMAS's.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.scenarios.football_ai import HeuristicPolicy, PitchSpec, TeamAI
from vmas_ros.scenarios.football_field import (
    BLUE_COLOR,
    DEFAULTS,
    RED_COLOR,
    Pitch,
    ball_wall_push,
    pitch_geoms,
    shooting_geoms,
)
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.dynamics.holonomic import Holonomic
from vmas_ros.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color, TorchUtils, as_index_tensor

__all__ = ["HeuristicPolicy", "Scenario"]

#: physically different blue roles (5 agents): change of radius, move multiplier, top speed,
#: rotation multiplier and shot multiplier (upstream's goalkeeper bonus lands on rotation)
ROLES = ("attacker", "attacker", "defender", "defender", "goalkeeper")
ROLE_CHANGES = {
    "attacker": (-0.005, 0.1, 0.05, 0.0, -0.2),
    "defender": (0.0, 0.0, 0.0, 0.0, 0.0),
    "goalkeeper": (0.01, -0.05, -0.1, 0.2, 0.0),
}
#: a kick's force is the kick action (already times u_shoot_multiplier) times this and u_shoot_multiplier
KICK_GAIN = 2.67
#: closest-player distance counted as touching the ball, beyond contact (info only)
TOUCH_MARGIN = 1e-2
BLUE, RED = 0, 1


def _strengths(value, name: str) -> tuple[float, float]:
    """An AI strength: one number for both teams or a (blue, red) pair, each in [0, 1]."""
    pair = tuple(value) if isinstance(value, (tuple, list)) else (value, value)
    if len(pair) != 2 or not all(isinstance(v, (int, float)) and 0 <= v <= 1 for v in pair):
        raise ValueError(f"football: {name} must be a number in [0, 1] or a (blue, red) pair of them, got {value!r}")
    return float(pair[0]), float(pair[1])


class Scenario(BaseScenario):
    supports_batched_reset = True

    # ------------------------------------------------------------------ build
    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        if kwargs.pop("dense_reward_ratio", None) is not None:
            raise ValueError("football: dense_reward_ratio is deprecated, use dense_reward (a bool) instead")
        cfg = read_kwargs(kwargs, DEFAULTS)
        self._validate(cfg)
        self.cfg = cfg
        for name, value in cfg.items():
            setattr(self, name, value)
        self.viewer_size = tuple(cfg["viewer_size"])
        self.visualize_semidims = False  # extra_render paints the pitch
        self.pitch = Pitch(
            cfg["pitch_length"], cfg["pitch_width"], cfg["goal_size"], cfg["goal_depth"], cfg["agent_size"], cfg["ball_size"]
        )
        world = World(
            batch_dim, device, dt=0.1, drag=0.05, substeps=2,
            x_semidim=self.pitch.x_semidim, y_semidim=self.pitch.y_semidim,
        )
        spec = PitchSpec.from_kwargs(cfg)
        speed, decision, precision = (_strengths(cfg[k], k) for k in ("ai_strength", "ai_decision_strength", "ai_precision_strength"))
        self.blue_controller = TeamAI(spec, False, speed[0], decision[0], precision[0]) if cfg["ai_blue_agents"] else None
        self.red_controller = (
            TeamAI(spec, True, speed[1], decision[1], precision[1], disabled=cfg["disable_ai_red"])
            if cfg["ai_red_agents"] else None
        )
        roles = ROLES if cfg["physically_different"] else ("defender",) * cfg["n_blue_agents"]
        self.blue_agents = [
            self._player(f"agent_blue_{i}", BLUE_COLOR, self.blue_controller, cfg["enable_shooting"], ROLE_CHANGES[role])
            for i, role in enumerate(roles)
        ]
        red_shoots = cfg["enable_shooting"] and not cfg["ai_red_agents"]
        self.red_agents = [
            self._player(f"agent_red_{i}", RED_COLOR, self.red_controller, red_shoots, ROLE_CHANGES["defender"])
            for i in range(cfg["n_red_agents"])
        ]
        self.players = self.blue_agents + self.red_agents
        for agent in self.players:
            world.add_agent(agent)
        self.ball = Agent(
            name="Ball", shape=Sphere(radius=cfg["ball_size"]), action_script=self._ball_script,
            max_speed=cfg["ball_max_speed"], mass=cfg["ball_mass"], alpha=1, color=Color.BLACK,
        )
        world.add_agent(self.ball)
        self.fixtures = [self.pitch.make_fixture(name, kind) for name, kind, *_ in self.pitch.fixtures()]
        for landmark in self.fixtures:
            world.add_landmark(landmark)
        self.walls = self.fixtures[:4]
        self.blue_net, self.red_net = self.fixtures[-2:]
        traj = {}
        for team, controller, agents in (("Red", self.red_controller, self.red_agents), ("Blue", self.blue_controller, self.blue_agents)):
            if controller is None:
                continue
            traj[team] = [[self._marker(f"{team} {i} Trajectory {j}", world) for j in range(cfg["n_traj_points"])] for i in range(len(agents))]
            controller.bind(agents, self.ball, traj[team])
        self._init_state(world)
        return world

    @staticmethod
    def _validate(cfg: dict) -> None:
        def need(ok: bool, name: str, expected: str) -> None:
            if not ok:
                raise ValueError(f"football: {name} must be {expected}, got {cfg[name]!r}")

        for name in ("n_blue_agents", "n_red_agents", "formation_agents_per_column"):
            need(isinstance(cfg[name], int) and not isinstance(cfg[name], bool) and cfg[name] >= 1, name, "an int >= 1")
        need(isinstance(cfg["n_traj_points"], int) and cfg["n_traj_points"] >= 0, "n_traj_points", "an int >= 0")
        for name in ("agent_size", "goal_size", "goal_depth", "pitch_length", "pitch_width", "ball_mass", "ball_size",
                     "u_multiplier", "max_speed", "ball_max_speed", "shooting_radius"):
            need(isinstance(cfg[name], (int, float)) and cfg[name] > 0, name, "a number > 0")
        need(cfg["goal_size"] < cfg["pitch_width"] - 2 * cfg["agent_size"], "goal_size", "narrower than the pitch")
        need(0 < cfg["shooting_angle"] <= 2 * math.pi, "shooting_angle", "in (0, 2 pi]")
        need(cfg["formation_noise"] >= 0, "formation_noise", ">= 0")
        need(not cfg["physically_different"] or cfg["n_blue_agents"] == 5, "n_blue_agents",
             "5 with physically_different=True")
        need(len(cfg["viewer_size"]) == 2, "viewer_size", "a (width, height) pair")

    def _player(self, name: str, color, controller, shoots: bool, change: tuple) -> Agent:
        radius, move, speed, rot, shot = change
        move = self.u_multiplier + move
        return Agent(
            name=name, shape=Sphere(radius=self.agent_size + radius),
            action_script=controller,
            u_multiplier=[move, move, self.u_rot_multiplier + rot, self.u_shoot_multiplier + shot] if shoots else [move, move],
            max_speed=self.max_speed + speed,
            dynamics=HolonomicWithRotation() if shoots else Holonomic(),
            action_size=4 if shoots else 2, color=color, alpha=1,
        )

    @staticmethod
    def _marker(name: str, world: World) -> Landmark:
        marker = Landmark(name=name, collide=False, movable=False, shape=Sphere(radius=0.01), color=Color.GRAY)
        world.add_landmark(marker)
        return marker

    def _init_state(self, world: World) -> None:
        """Per-env scenario state; team columns are [blue, red]."""
        batch, device, n = world.batch_dim, world.device, len(self.players)
        zeros = lambda *shape: torch.zeros(batch, *shape, device=device)
        goal = self.pitch.goal_line
        self._goals = torch.tensor([[goal, 0.0], [-goal, 0.0]], device=device)  # attacked goal per team
        self._team_flip = torch.tensor([[1.0, 1.0], [-1.0, 1.0]], device=device)  # team frame per team
        self._red_flip = torch.tensor([-1.0, 1.0, -1.0, 1.0], device=device)  # red's move x and rotation
        self._frame_goal = torch.tensor([goal, 0.0], device=device)  # the attacked goal in every team frame
        self._in_team = [torch.arange(len(self.blue_agents), device=device),
                         torch.arange(len(self.blue_agents), n, device=device)]
        n_blue = len(self.blue_agents)
        self._mates = [  # each player's teammates, as index tensors built once (no masking per step)
            torch.tensor([j for j in (range(n_blue) if p < n_blue else range(n_blue, n)) if j != p],
                         dtype=torch.long, device=device)
            for p in range(n)
        ]
        self._where = {a.name: (BLUE, i, i) for i, a in enumerate(self.blue_agents)}
        self._where.update({a.name: (RED, i, len(self.blue_agents) + i) for i, a in enumerate(self.red_agents)})
        self._dense = torch.tensor([
            self.dense_reward and not self.ai_blue_agents, self.dense_reward and not self.ai_red_agents,
        ], device=device)
        self._done = torch.zeros(batch, dtype=torch.bool, device=device)
        self._sparse, self._rewards = zeros(2), zeros(2)
        self._ball_goal_dist, self._ball_shaping, self._ball_rew = zeros(2), zeros(2), zeros(2)
        self._min_dist, self._agent_shaping, self._agent_rew = zeros(2), zeros(2), zeros(2)
        self._kick = zeros(2)  # kicks collected this step, applied by the ball's script
        self.kick_ready = torch.zeros(batch, n, dtype=torch.bool, device=device)  # ball in range and sector
        self.kick_force = zeros(n, 2)  # each player's last kick force (before the closest-player test)
        self._kick_geometry: tuple | None = None
        self._render_field = True

    # ------------------------------------------------------------------ reset
    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        index = None if env_index is None else as_index_tensor(env_index, world.batch_dim, world.device)
        rows = world.batch_dim if index is None else len(index)
        self._spawn_players(index, rows)
        self.ball.set_pos(torch.zeros(rows, 2, device=world.device), batch_index=index)
        pos, rot = self.pitch.fixture_poses(world.device)
        for k, landmark in enumerate(self.fixtures):
            landmark.set_pos(pos[k], batch_index=index)
            landmark.set_rot(rot[k], batch_index=index)
        selected = slice(None) if index is None else index
        self._done[selected] = False
        self._sparse[selected] = 0.0
        self._rewards[selected] = 0.0
        self._ball_rew[selected] = 0.0
        self._agent_rew[selected] = 0.0
        self._kick[selected] = 0.0
        self.reset_shaping(index)

    def _spawn_players(self, index, rows: int) -> None:
        device, l2, w = self.world.device, self.pitch_length / 2, self.pitch_width
        if self.spawn_in_formation:
            self._spawn_formation(self.blue_agents, True, index, rows)
            if not self.only_blue_formation:
                self._spawn_formation(self.red_agents, False, index, rows)
        if not self.spawn_in_formation:
            extent = torch.tensor([l2, w], device=device)
            for agent in self.blue_agents:
                start = torch.tensor([-l2 + self.agent_size, -w / 2], device=device)
                agent.set_pos(torch.rand(rows, 2, device=device) * extent + start, batch_index=index)
        if not self.spawn_in_formation or self.only_blue_formation:
            extent = torch.tensor([l2, w], device=device)
            for agent in self.red_agents:
                start = torch.tensor([-self.agent_size, -w / 2], device=device)
                agent.set_pos(torch.rand(rows, 2, device=device) * extent + start, batch_index=index)
        facing_left = torch.tensor([math.pi], device=device)
        for agent in self.red_agents:
            agent.set_rot(facing_left, batch_index=index)

    def _spawn_formation(self, agents: list, blue: bool, index, rows: int) -> None:
        """Columns of ``formation_agents_per_column`` agents between the half-way line and the goal."""
        if self.randomise_formation_indices:
            agents = [agents[i] for i in torch.randperm(len(agents)).tolist()]
        end = -(self.pitch_length / 2 + self.goal_depth) * (1 if blue else -1)
        columns = torch.linspace(0, end, len(agents) // self.formation_agents_per_column + 3)[1:-1].tolist()
        per_column = self.formation_agents_per_column
        slots = []
        for c, x in enumerate(columns):
            n_here = len(agents[c * per_column:(c + 1) * per_column])
            ys = torch.linspace(self.pitch_width / 2, -self.pitch_width / 2, n_here + 2)[1:-1].tolist()
            slots += [(x, y) for y in ys]
        for agent, (x, y) in zip(agents, slots):
            spot = torch.tensor([x, y], device=self.world.device)
            noise = (torch.rand(rows, 2, device=self.world.device) - 0.5) * self.formation_noise
            agent.set_pos(spot + noise, batch_index=index)

    def reset_shaping(self, env_index=None) -> None:
        """Restart the dense-reward baselines from the current positions (all envs or the selected ones).

        Reset calls it; call it yourself after moving the ball or the players
        by hand, so the next step's shaping measures progress from there.
        """
        selected = slice(None) if env_index is None else env_index
        dist, min_dist = self._distances()
        self._ball_goal_dist[selected] = dist[selected]
        self._ball_shaping[selected] = (dist * self.pos_shaping_factor_ball_goal)[selected]
        self._min_dist[selected] = min_dist[selected]
        self._agent_shaping[selected] = (min_dist * self.pos_shaping_factor_agent_ball)[selected]

    def _distances(self) -> tuple[Tensor, Tensor]:
        """The ball's distance to each team's attacked goal and each team's closest distance to it, [B, 2] each."""
        ball = self.ball.state.pos
        to_goal = torch.linalg.vector_norm(ball.unsqueeze(1) - self._goals, dim=-1)
        players = torch.stack([a.state.pos for a in self.players], dim=1)
        to_ball = torch.linalg.vector_norm(players - ball.unsqueeze(1), dim=-1)
        closest = torch.stack([to_ball[:, team].amin(dim=1) for team in self._in_team], dim=-1)
        return to_goal, closest

    # ---------------------------------------------------------------- actions
    def process_action(self, agent: Agent) -> None:
        if agent.action_script is not None:  # the ball and the scripted teams
            return
        team, _, player = self._where[agent.name]
        u = agent.action.u
        if team == RED:  # red acts in its mirrored frame: flip x (and the rotation)
            u = u * self._red_flip[:u.shape[1]]
        if self.enable_shooting:
            u = self._shoot(player, u, agent.state.rot)
        agent.action.u = u

    def _shoot(self, player: int, u: Tensor, rot: Tensor) -> Tensor:
        """Collect the kick in the last action column (applied to the ball by its script); returns the rest."""
        if self._kick_geometry is None:  # once per step, for every player
            players = torch.stack([a.state.pos for a in self.players], dim=1)
            to_ball = self.ball.state.pos.unsqueeze(1) - players
            dist = torch.linalg.vector_norm(to_ball, dim=-1)
            closest = dist == dist.min(dim=-1, keepdim=True)[0]
            self._kick_geometry = (to_ball, dist, closest)
        to_ball, dist, closest = self._kick_geometry
        bearing = torch.atan2(to_ball[:, player, 1], to_ball[:, player, 0])
        offset = (rot[:, 0] - bearing + math.pi) % (2 * math.pi) - math.pi
        in_sector = (offset >= -self.shooting_angle / 2) & (offset <= self.shooting_angle / 2)
        ready = in_sector & (dist[:, player] <= self.shooting_radius)
        power = u[:, -1] * KICK_GAIN * self.u_shoot_multiplier
        force = TorchUtils.rotate_vector(torch.stack([power, torch.zeros_like(power)], dim=-1), rot)
        self.kick_ready[:, player] = ready
        self.kick_force[:, player] = force
        self._kick = self._kick + torch.where((ready & closest[:, player]).unsqueeze(-1), force, 0.0)
        return u[:, :-1]

    def _ball_script(self, ball: Agent, world: World) -> None:
        """The ball's action: the anti-stick nudge plus this step's kicks."""
        u = ball_wall_push(ball.state.pos, ball.state.vel, self.pitch)
        if self.enable_shooting:
            u = u + self._kick
            self._kick = torch.zeros_like(self._kick)
        ball.action.u = u

    def pre_step(self) -> None:
        self._kick_geometry = None  # positions change in this step

    # ---------------------------------------------------------------- rewards
    def post_step(self) -> None:
        """Goals, done and every team's reward for the step just taken, once for all agents."""
        ball = self.ball.state.pos
        in_mouth = (ball[:, 1] <= self.goal_size / 2) & (ball[:, 1] >= -self.goal_size / 2)
        blue_scores = (ball[:, 0] > self.pitch.goal_line) & in_mouth
        red_scores = (ball[:, 0] < -self.pitch.goal_line) & in_mouth
        sparse_blue = self.scoring_reward * blue_scores - self.scoring_reward * red_scores
        self._sparse = torch.stack([sparse_blue, -sparse_blue], dim=-1)
        self._done = blue_scores | red_scores

        dist, min_dist = self._distances()
        shaping = dist * self.pos_shaping_factor_ball_goal
        ball_rew = self._ball_shaping - shaping
        self._ball_goal_dist, self._ball_shaping = dist, shaping
        agent_shaping = min_dist * self.pos_shaping_factor_agent_ball
        moving = torch.linalg.vector_norm(self.ball.state.vel, dim=-1) > 1e-6
        paused = (min_dist < self.distance_to_ball_trigger) | moving.unsqueeze(-1)
        agent_rew = torch.where(paused, 0.0, self._agent_shaping - agent_shaping)
        self._min_dist, self._agent_shaping = min_dist, agent_shaping
        self._ball_rew = torch.where(self._dense, ball_rew, 0.0)
        self._agent_rew = torch.where(self._dense, agent_rew, 0.0)
        self._rewards = self._sparse + torch.where(self._dense, ball_rew + agent_rew, 0.0)

    def reward(self, agent: Agent) -> Tensor:
        return self._rewards[:, self._where[agent.name][0]]

    def done(self) -> Tensor:
        return self._done

    def info(self, agent: Agent) -> dict:
        team = self._where[agent.name][0]
        return {
            "sparse_reward": self._sparse[:, team],
            "ball_goal_pos_rew": self._ball_rew[:, team],
            "all_agent_ball_pos_rew": self._agent_rew[:, team],
            "ball_pos": self.ball.state.pos,
            "dist_ball_to_goal": self._ball_goal_dist[:, team],
            "min_agent_dist_to_ball": self._min_dist[:, team],
            "touching_ball": self._min_dist[:, team] <= self.agent_size + self.ball_size + TOUCH_MARGIN,
        }

    # ------------------------------------------------------------ observation
    def observation(self, agent: Agent):
        team, _, me = self._where[agent.name]
        flip = self._team_flip[team]
        pos, vel, force = (torch.stack([getattr(a.state, f) for a in self.players], dim=1) * flip
                           for f in ("pos", "vel", "force"))
        ball = self.ball.state
        ball_pos, ball_vel, ball_force = ball.pos * flip, ball.vel * flip, ball.force * flip
        own = [force[:, me], pos[:, me] - ball_pos, vel[:, me] - ball_vel, ball_pos - self._frame_goal, ball_vel, ball_force]
        if self.enable_shooting:
            own.append(agent.state.rot if team == BLUE else agent.state.rot - math.pi)
        obs = {"obs": torch.cat(own, dim=-1), "pos": pos[:, me] - self._frame_goal, "vel": vel[:, me]}
        mates = self._mates[me]
        for key, rows, wanted in (("adversaries", self._in_team[1 - team], self.observe_adversaries),
                                  ("teammates", mates, self.observe_teammates)):
            if wanted and len(rows):
                block = torch.cat([pos[:, me:me + 1] - pos[:, rows], vel[:, me:me + 1] - vel[:, rows],
                                   vel[:, rows], force[:, rows]], dim=-1)  # [B, n, 8]
                obs[key] = block if self.dict_obs else block.flatten(1)
        return obs if self.dict_obs else torch.cat(list(obs.values()), dim=-1)

    # -------------------------------------------------------------- rendering
    def render_field(self, render: bool) -> None:
        """Show or hide the painted pitch and the goal-line walls (to plot something else on the field)."""
        self._render_field = render
        for wall in self.walls:
            wall.is_rendering[:] = render

    def extra_render(self, env_index: int = 0) -> list:
        geoms = pitch_geoms(self.pitch, with_grass=self._render_field)
        if self.enable_shooting:
            for agent in self.blue_agents:
                player = self._where[agent.name][2]
                ready = bool(self.kick_ready[env_index, player])
                color = Color.PINK.value if ready else agent.color
                intensity = float(torch.linalg.vector_norm(self.kick_force[env_index, player])) / (self.u_shoot_multiplier * 2)
                geoms += shooting_geoms(
                    agent.state.pos[env_index].tolist(), float(agent.state.rot[env_index]), color,
                    self.shooting_radius, self.shooting_angle, intensity, self.agent_size,
                )
        return geoms
