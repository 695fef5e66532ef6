"""multi_give_way: four robots at the ends of a cross-shaped corridor each turn into the next arm.

Description
    Two 5 m corridors, 0.4 m wide, cross at the origin and are closed at all
    four ends. Agent 0 (green) starts in the west arm, agent 1 (blue) in the
    north, agent 2 (red) in the east and agent 3 (gray) in the south, 2 m from
    the centre. Each must reach a goal near the far end of the next arm
    counter-clockwise: agent 0 the south arm, agent 1 the west, agent 2 the
    north and agent 3 the east. The agents (discs of radius 0.16, or
    0.32 x 0.24 boxes) cannot pass each other in an arm, and every goal arm is
    occupied by the agent that must leave it, so the four form a cycle that
    only a detour through another arm can break. Actions are desired
    velocities tracked by a PID ``VelocityController`` (gains shared with
    ``give_way``).
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus its goal's (2), the
    distance to its goal (1): 7 values. With ``obs_noise > 0`` every entry gets
    uniform noise in [-obs_noise, obs_noise].
Reward
    Position: the decrease of the agent's distance to its goal since the last
    step (x ``pos_shaping_factor``), summed over all agents when ``shared_rew``
    (a factor of 0 gives instead -1e-4 x the distance). Plus ``final_reward``
    in every step all four agents are on their goals (closer than the goal
    radius, 0.08), and ``agent_collision_penalty`` for every other agent whose
    surface is within 0.005 of the agent's. ``info`` reports each term
    (``pos_rew``, ``final_rew``, ``agent_collision_rew``).
Starting state
    Deterministic: agents at rest 2 m from the centre on their arm's axis,
    goals 2.29 m from the centre (0.21 from the end wall); the same in every env.
Episode termination
    Never (set ``max_steps``); ``reached_goal`` records, per env, whether all
    agents have been on their goals at once since the last reset.
Kwargs
    ``u_range`` (0.5, the speed limit of the commands), ``a_range`` (1),
    ``obs_noise`` (0), ``box_agents`` (False), ``linear_friction`` (0.1),
    ``min_input_norm`` (0.08), ``comms_range`` (5, only drawn: agents closer
    than this are joined by a line), ``shared_rew`` (True), ``n_agents`` (4),
    ``pos_shaping_factor`` (1), ``final_reward`` (0.01),
    ``agent_collision_penalty`` (-0.1).
    Deviation from VMAS 1.5: VMAS accepts any ``n_agents`` and silently uses 4
    (the map has four arms); here any other value raises ``ValueError``.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_number, configure, heuristic_kwargs, range_links
from vmas_ros.scenarios.give_way import PID_PARAMS, VelocityController, Wall, track_velocity
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color, TorchUtils

#: name -> default of every kwarg (the heuristic reads the ones it needs too)
DEFAULTS = {
    "u_range": 0.5, "a_range": 1.0, "obs_noise": 0.0, "box_agents": False, "linear_friction": 0.1,
    "min_input_norm": 0.08, "comms_range": 5.0, "shared_rew": True, "n_agents": 4,
    "pos_shaping_factor": 1.0, "final_reward": 0.01, "agent_collision_penalty": -0.1,
}
N_AGENTS = 4
AGENT_RADIUS = 0.16
BOX_LENGTH, BOX_WIDTH = 0.32, 0.24  # box agents: extent along x, along y
LENGTH = 5.0  # each corridor spans [-2.5, 2.5] along its axis
CORRIDOR = 0.4  # corridor width
START_DIST = LENGTH / 2 - 0.5  # agents start this far from the centre
GOAL_DIST = LENGTH / 2 - (AGENT_RADIUS + 0.05)
GOAL_RADIUS = AGENT_RADIUS / 2
TOUCH_DISTANCE = 0.005  # surfaces closer than this count as a collision in the reward
COLORS = (Color.GREEN, Color.BLUE, Color.RED, Color.GRAY)
#: unit vector of each agent's start arm, by agent index: west, north, east, south.
#: Agent i's goal lies in the arm of agent i - 1 (mod 4).
ARMS = ((-1.0, 0.0), (0.0, 1.0), (1.0, 0.0), (0.0, -1.0))


def map_layout() -> list[Wall]:
    """The walls, in world order (VMAS 1.5's names and order).

    First the eight long side walls, each running from an end of the map to
    the crossing (west arm's lower and upper, east arm's lower and upper,
    then south arm's left and right, north arm's left and right); then the
    four short end caps (west, east, south, north).
    """
    side = LENGTH / 2 - CORRIDOR / 2
    centre = side / 2 - LENGTH / 2  # centre of a side wall along its arm, on the negative side
    half = CORRIDOR / 2
    walls = [
        Wall(f"wall {i}", side, -centre * arm, lateral * half, False)
        for i, (arm, lateral) in enumerate(((-1, -1), (-1, 1), (1, -1), (1, 1)))
    ]
    walls += [
        Wall(f"wall {i + 4}", side, lateral * half, -centre * arm, True)
        for i, (arm, lateral) in enumerate(((-1, -1), (-1, 1), (1, -1), (1, 1)))
    ]
    ends = ((-LENGTH / 2, 0.0, True), (LENGTH / 2, 0.0, True), (0.0, -LENGTH / 2, False), (0.0, LENGTH / 2, False))
    walls += [Wall(f"short wall {i}", CORRIDOR, x, y, vertical) for i, (x, y, vertical) in enumerate(ends)]
    return walls


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    for name in ("u_range", "a_range"):
        check_number("multi_give_way", name, config[name], strict=True)
    for name in ("obs_noise", "linear_friction", "min_input_norm", "comms_range"):
        check_number("multi_give_way", name, config[name])
    if config["n_agents"] != N_AGENTS:
        raise ValueError(f"multi_give_way: n_agents must be 4 (one per arm), got {config['n_agents']!r}")


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        self.viewer_zoom = 1.7
        self.f_range = self.a_range + self.linear_friction

        world = World(
            batch_dim, device, dt=0.1, drag=0.0, linear_friction=self.linear_friction,
            substeps=16 if self.box_agents else 5, collision_force=10000 if self.box_agents else 500,
        )
        for i, color in enumerate(COLORS):
            agent = Agent(
                name=f"agent_{i}", color=color, rotatable=False, linear_friction=self.linear_friction,
                shape=Box(length=BOX_LENGTH, width=BOX_WIDTH) if self.box_agents else Sphere(radius=AGENT_RADIUS),
                u_range=self.u_range, f_range=self.f_range, render_action=True,
            )
            agent.controller = VelocityController(agent, world, PID_PARAMS, "standard")
            agent.goal = Landmark(name=f"goal {i}", collide=False, shape=Sphere(radius=GOAL_RADIUS), color=color)
            world.add_agent(agent)
            world.add_landmark(agent.goal)

        layout = map_layout()
        self.walls = [Landmark(name=w.name, collide=True, shape=Line(length=w.length), color=Color.BLACK) for w in layout]
        for wall in self.walls:
            world.add_landmark(wall)
        self._wall_pos = torch.tensor([[w.x, w.y] for w in layout], device=world.device)
        self._wall_rot = torch.tensor([[math.pi / 2 if w.vertical else 0.0] for w in layout], device=world.device)
        arms = torch.tensor(ARMS, device=world.device)
        self._start = arms * START_DIST  # [4 agents, 2]
        self._goal = arms.roll(1, dims=0) * GOAL_DIST  # agent i's goal is in arm i - 1

        #: per env [B, 4 agents]: distance to goal x pos_shaping_factor, as of the last reward
        self.shaping = torch.zeros(batch_dim, N_AGENTS, device=world.device)
        #: per env [B]: all agents on their goals now / at some step since the last reset
        self.all_goal_reached = torch.zeros(batch_dim, dtype=torch.bool, device=world.device)
        self.reached_goal = self.all_goal_reached.clone()
        self.pos_rew = torch.zeros(batch_dim, N_AGENTS, device=world.device)  # per agent, before sharing
        self.final_rew = torch.zeros(batch_dim, device=world.device)
        self.agent_collision_rew = self.pos_rew.clone()
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index=None) -> None:
        for i, agent in enumerate(self.world.agents):
            agent.set_pos(self._start[i], batch_index=env_index)
            agent.goal.set_pos(self._goal[i], batch_index=env_index)
            agent.controller.reset(env_index)
        for k, wall in enumerate(self.walls):
            wall.set_pos(self._wall_pos[k], batch_index=env_index)
            wall.set_rot(self._wall_rot[k], batch_index=env_index)
        start_shaping = torch.linalg.vector_norm(self._start - self._goal, dim=-1) * self.pos_shaping_factor
        if env_index is None:
            self.shaping = start_shaping.expand_as(self.shaping).clone()
            self.reached_goal = torch.zeros_like(self.reached_goal)
        else:
            self.shaping[env_index] = start_shaping
            self.reached_goal[env_index] = False

    # ----------------------------------------------------------------- actions
    def process_action(self, agent: Agent) -> None:
        """The action is a desired velocity: clip it to a disc, zero tiny ones, run the PID."""
        track_velocity(agent, agent.action.u, self.u_range, self.min_input_norm)

    # ------------------------------------------------------------------ reward
    def _update_rewards(self) -> None:
        """Every reward term for all agents at once ([B, 4] / [B]); run once per step."""
        world = self.world
        pos = torch.stack([a.state.pos for a in world.agents], dim=1)  # [B, 4, 2]
        goals = torch.stack([a.goal.state.pos for a in world.agents], dim=1)
        distance = torch.linalg.vector_norm(pos - goals, dim=-1)  # [B, 4]
        shaping = distance * self.pos_shaping_factor
        if self.pos_shaping_factor != 0:
            self.pos_rew = self.shaping - shaping
        else:  # no shaping: a faint pull towards the goal instead
            self.pos_rew = -distance * 0.0001
        self.shaping = shaping
        self.all_goal_reached = (distance < GOAL_RADIUS).all(dim=1)
        self.reached_goal = self.reached_goal | self.all_goal_reached
        self.final_rew = torch.where(self.all_goal_reached, self.final_reward, 0.0)

        touching = torch.zeros(world.batch_dim, N_AGENTS, N_AGENTS, device=world.device)
        agents = world.agents
        for i in range(N_AGENTS):
            for j in range(i + 1, N_AGENTS):
                close = (world.get_distance(agents[i], agents[j]) <= TOUCH_DISTANCE).float()
                touching[:, i, j] = close
                touching[:, j, i] = close
        self.agent_collision_rew = touching.sum(dim=-1) * self.agent_collision_penalty

    def _position_reward(self, i: int) -> Tensor:
        return self.pos_rew.sum(dim=1) if self.shared_rew else self.pos_rew[:, i]

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:
            self._update_rewards()
        i = self._index[agent.name]
        return self._position_reward(i) + self.agent_collision_rew[:, i] + self.final_rew

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> Tensor:
        to_goal = agent.state.pos - agent.goal.state.pos
        distance = torch.linalg.vector_norm(to_goal, dim=-1, keepdim=True)
        obs = torch.cat([agent.state.pos, agent.state.vel, to_goal, distance], dim=-1)
        if self.obs_noise > 0:
            obs = obs + torch.empty_like(obs).uniform_(-self.obs_noise, self.obs_noise)
        return obs

    def info(self, agent: Agent) -> dict:
        i = self._index[agent.name]
        return {
            "pos_rew": self._position_reward(i),
            "final_rew": self.final_rew,
            "agent_collision_rew": self.agent_collision_rew[:, i],
        }

    def extra_render(self, env_index: int = 0) -> list:
        """A black line between every two agents closer than ``comms_range``."""
        return range_links(self.world.agents, env_index, self.comms_range)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Three agents reach their goals in turn; the fourth breaks the cycle by parking.

    Decentralised and memoryless: an agent reads who it is from where its goal
    lies (its start arm is the next one clockwise), and agents never see each
    other, so the order comes from timing alone (the start is deterministic).
    Each agent drives along its start arm to the centre, turns, and drives out
    along its goal arm, holding the arm's axis with a lateral correction.

    * Agent 3 (south) goes first, at full speed, and parks ``park`` m into
      its goal arm (the east), clear of the crossing.
    * Agent 0 (west) approaches at ``approach_speed[0]`` until ``mouth`` m from
      the centre, which brings it there after agent 3 has left the south arm
      and the crossing; then it drives to its goal in the south arm.
    * Agent 1 (north) approaches slower still, so it crosses after agent 0,
      and drives to its goal in the west arm.
    * Agent 2 (east) moves up to ``hold`` m from the centre, behind the
      parked agent 3, and stays.

    Freeing agent 2 would need agent 3 to leave the east arm again and come
    back, which a memoryless policy cannot tell apart from its first visit;
    so two agents of four stay short of their goals and ``final_reward`` is
    never paid. Actions are desired velocities (this scenario's only mode).
    """

    gain = 2.0  # velocity per metre of distance to a target along an arm
    lateral_gain = 3.0  # velocity per metre off the arm's axis
    turn = 0.05  # closer than this to the centre (along its start arm) an agent turns into its goal arm
    mouth = 0.4
    park = 0.45
    hold = 0.9
    #: by start arm (agent index): speed along the start arm while farther than ``mouth`` from the centre
    approach_speed = (0.25, 0.17, 0.5, 0.5)

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        if not continuous_action:
            raise ValueError("multi_give_way HeuristicPolicy needs continuous actions")
        config = heuristic_kwargs("multi_give_way", DEFAULTS, scenario_kwargs)
        self.u_range = config["u_range"]
        self._arms = torch.tensor(ARMS)
        self._speed = torch.tensor(self.approach_speed)
        self._stop = torch.tensor([0.0, 0.0, self.hold, 0.0])  # where along its start arm an agent stops
        self._target = torch.tensor([GOAL_DIST, GOAL_DIST, GOAL_DIST, self.park])  # along its goal arm

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        if observation.shape[-1] != 7:
            raise ValueError(f"multi_give_way heuristic: expected observation width 7, got {observation.shape[-1]}")
        device = observation.device
        arms, speed = self._arms.to(device), self._speed.to(device)
        pos = observation[:, 0:2]
        goal = pos - observation[:, 4:6]
        goal_arm = (goal @ arms.T).argmax(dim=-1)  # [B]
        me = (goal_arm + 1) % N_AGENTS  # the agent's index, which is its start arm
        start_dir, goal_dir = arms[me], arms[goal_arm]
        limit = min(u_range, self.u_range)

        along_start = (pos * start_dir).sum(-1)  # distance from the centre along the start arm
        cap = torch.where(along_start > self.mouth, speed[me], limit)
        inward = torch.minimum(self.gain * (along_start - self._stop.to(device)[me]), cap).clamp_min(-limit)
        off_start = pos - along_start.unsqueeze(-1) * start_dir
        approach = -inward.unsqueeze(-1) * start_dir - self.lateral_gain * off_start

        along_goal = (pos * goal_dir).sum(-1)
        outward = (self.gain * (self._target.to(device)[me] - along_goal)).clamp(-limit, limit)
        off_goal = pos - along_goal.unsqueeze(-1) * goal_dir
        leave = outward.unsqueeze(-1) * goal_dir - self.lateral_gain * off_goal

        velocity = torch.where((along_start > self.turn).unsqueeze(-1), approach, leave)
        return TorchUtils.clamp_with_norm(velocity, limit)
